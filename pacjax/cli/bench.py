"""Equilibria per second for the paper's robot: the engine of ``pacjax bench``.

For every strain model x batch size x dtype, :func:`bench_batch` times :func:`pacjax.solve_batch`
on the paper's robot (``pj.presets.stella2023(model, tip_mass=0.2)``) under random commands
(0-20 mm pull-ins): a first call (compilation, or a load from JAX's persistent cache, plus one
run) and warm calls; compile time = first call minus the median warm call. In the same run:

- :func:`bench_flow_baseline`: the paper's plain damped flow ``D qdot = -F(q)`` (constant
  ``D`` = the scene's ``elastic_stiffness_diagonal``, no preconditioning, no Newton polish)
  integrated by ``diffrax`` (Kvaerno5, PID step-size control) from the straight state until the
  scaled residual is below the same tolerance (a steady-state event), ``vmap``-ped over a small
  batch; the ratios of the batch solver's rate to it;
- :func:`bench_gradient`: ``jax.grad`` of a loss (the sum of the tips' x coordinates) through a
  ``vmap``-ped :func:`pacjax.solve_equilibrium` w.r.t. the commands, against the same batch
  solved without the gradient;
- float32 against float64: the largest tip-position difference on the same commands.

Nothing here is asserted; timings are wall-clock on the machine recorded by
:func:`machine_info`.
"""

from __future__ import annotations

import os
import platform
import time
from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import pacjax as pj

MODELS = {
    "PCC": pj.PCC,
    "PAC": pj.PAC,
    "Poly3": lambda: pj.PolynomialCurvature(3),
}
DTYPES = {"float64": jnp.float64, "float32": jnp.float32}
#: Solver tolerance on the scaled residual per dtype (float32's floor is near 1e-5 here).
TOLERANCES = {"float64": 1e-10, "float32": 1e-4}
#: Random commands: uniform pull-ins in [0, MAX_PULL_IN] m, as benchmarks/bench_solve.py.
MAX_PULL_IN = 0.02
TIP_MASS = 0.2


def machine_info() -> dict:
    """Platform, Python, JAX and the devices, for the benchmark record."""
    devices = jax.devices()
    info = {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jaxlib": _version("jaxlib"),
        "pacjax": pj.__version__,
        "cpu_count": os.cpu_count(),
        "backend": jax.default_backend(),
        "devices": [d.device_kind for d in devices],
        "x64": bool(jax.config.jax_enable_x64),
        "compilation_cache": jax.config.jax_compilation_cache_dir,
    }
    if hasattr(os, "getloadavg"):
        info["load_average_1min"] = os.getloadavg()[0]
    return info


def _version(package: str) -> str | None:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(package)
    except PackageNotFoundError:
        return None


def paper_scene(model: str, dtype: str = "float64") -> pj.Scene:
    """``pj.presets.stella2023(model, tip_mass=0.2)`` in ``dtype``."""
    if model not in MODELS:
        raise ValueError(f"model must be one of {', '.join(MODELS)}; got {model!r}")
    if dtype not in DTYPES:
        raise ValueError(f"dtype must be one of {', '.join(DTYPES)}; got {dtype!r}")
    scene = pj.presets.stella2023(MODELS[model](), tip_mass=TIP_MASS)
    return scene if dtype == "float64" else pj.astype(scene, DTYPES[dtype])


def random_commands(n: int, n_tendons: int = 9, seed: int = 0) -> np.ndarray:
    """``n`` rows of uniform pull-ins in ``[0, MAX_PULL_IN]`` m."""
    return np.random.default_rng(seed).uniform(0.0, MAX_PULL_IN, (n, n_tendons))


def timed(fn):
    """``(seconds, result)`` of ``fn()``, waiting for every array of the result."""
    start = time.perf_counter()
    out = fn()
    jax.block_until_ready(out)
    return time.perf_counter() - start, out


def _first_and_warm(fn, repeats: int):
    first, out = timed(fn)
    warm = [timed(fn)[0] for _ in range(repeats)]
    return first, float(np.median(warm)), out


def _repeats(batch: int) -> int:
    return 5 if batch <= 10 else 3 if batch <= 100 else 1


# ------------------------------------------------------------------------------ batch solver
def bench_batch(scene: pj.Scene, commands: np.ndarray, tol: float, repeats: int | None = None):
    """Time :func:`pacjax.solve_batch` over ``commands`` in one chunk (no flow fallback, so the
    rate is the solver's own; rows it leaves unconverged are counted)."""
    n = len(commands)
    repeats = _repeats(n) if repeats is None else repeats

    def solve():
        return pj.solve_batch(
            scene, commands, chunk_size=n, tol=tol, fallback=False, progress=False
        )

    first, warm, eq = _first_and_warm(solve, repeats)
    converged = np.asarray(eq.converged)
    residual = np.asarray(eq.residual_norm)
    return {
        "batch": n,
        "tol": tol,
        "first_call_s": first,
        "compile_s": max(first - warm, 0.0),
        "run_s": warm,
        "warm_repeats": repeats,
        "equilibria_per_s": n / warm,
        "converged": float(converged.mean()),
        "stable": float(np.asarray(eq.stable)[converged].mean()) if converged.any() else 0.0,
        "max_residual_converged": float(residual[converged].max()) if converged.any() else None,
        "steps_median": float(np.median(np.asarray(eq.steps))),
    }, eq


@eqx.filter_jit
def _tips(scene, q):
    return jax.vmap(lambda qi: pj.tip_pose(scene, qi)[0])(q)


# ------------------------------------------------------------------------------ flow baseline
def _flow_one(scene: pj.Scene, controls, tol: float, max_steps: int):
    """The plain damped flow ``D qdot = -F(q)`` from the straight state to a steady state."""
    dtype = controls.dtype
    d = scene.elastic_stiffness_diagonal(dtype)
    scale = d * scene.coordinate_scale(dtype)

    def scaled_residual(q):
        return jnp.max(jnp.abs(scene.residual(q, controls) / scale))

    term = diffrax.ODETerm(lambda t, q, args: -scene.residual(q, controls) / d)
    event = diffrax.Event(lambda t, q, args, **kwargs: scaled_residual(q) <= tol)
    sol = diffrax.diffeqsolve(
        term,
        diffrax.Kvaerno5(),
        t0=0.0,
        t1=jnp.inf,
        dt0=None,
        y0=scene.zeros(dtype),
        stepsize_controller=diffrax.PIDController(rtol=1e-6, atol=1e-9),
        event=event,
        max_steps=max_steps,
        throw=False,
    )
    q = sol.ys[-1]
    residual = scaled_residual(q)
    return q, residual, residual <= tol, sol.stats["num_steps"]


@eqx.filter_jit
def _flow_batch(scene, controls, tol, max_steps):
    return jax.vmap(lambda u: _flow_one(scene, u, tol, max_steps))(controls)


def bench_flow_baseline(scene: pj.Scene, commands: np.ndarray, tol: float, max_steps: int = 20_000):
    """Time the plain-flow baseline (see the module doc) on ``commands`` (one vmapped call)."""
    dtype = jnp.asarray(scene.robot.segments[0].length).dtype
    controls = jnp.asarray(commands, dtype)

    def solve():
        return _flow_batch(scene, controls, tol, max_steps)

    first, warm, (q, residual, converged, steps) = _first_and_warm(solve, 1)
    converged = np.asarray(converged)
    return {
        "method": "diffrax Kvaerno5 + PIDController(rtol=1e-6, atol=1e-9) on D qdot = -F, "
        "D = elastic_stiffness_diagonal, steady-state event on the scaled residual",
        "batch": len(commands),
        "tol": tol,
        "first_call_s": first,
        "compile_s": max(first - warm, 0.0),
        "run_s": warm,
        "equilibria_per_s": len(commands) / warm,
        "converged": float(converged.mean()),
        "max_residual": float(np.max(np.asarray(residual))),
        "steps_median": float(np.median(np.asarray(steps))),
    }, np.asarray(q)


# ------------------------------------------------------------------------------ gradient
def bench_gradient(scene: pj.Scene, commands: np.ndarray, tol: float, repeats: int = 3):
    """``jax.grad`` of the sum of the tips' x through a vmapped solve w.r.t. the commands,
    against the same loss without the gradient (both jitted, warm)."""
    dtype = jnp.asarray(scene.robot.segments[0].length).dtype
    controls = jnp.asarray(commands, dtype)

    def loss(u):
        eqs = jax.vmap(lambda ui: pj.solve_equilibrium(scene, ui, tol=tol, fallback=False))(u)
        return jnp.sum(jax.vmap(lambda q: pj.tip_pose(scene, q)[0][0])(eqs.q))

    forward = jax.jit(loss)
    gradient = jax.jit(jax.grad(loss))
    f_first, f_warm, value = _first_and_warm(lambda: forward(controls), repeats)
    g_first, g_warm, grad = _first_and_warm(lambda: gradient(controls), repeats)
    grad = np.asarray(grad)
    return {
        "loss": "sum of tip x over the batch; gradient w.r.t. the (batch, 9) commands",
        "batch": len(commands),
        "forward_run_s": f_warm,
        "forward_compile_s": max(f_first - f_warm, 0.0),
        "gradient_run_s": g_warm,
        "gradient_compile_s": max(g_first - g_warm, 0.0),
        "gradient_over_forward": g_warm / f_warm,
        "extra_cost_over_forward": g_warm / f_warm - 1.0,
        "loss_value": float(value),
        "gradient_finite": bool(np.all(np.isfinite(grad))),
    }


# ------------------------------------------------------------------------------ the whole run
class _Subjects(NamedTuple):
    """What a run measures: scene makers per model (dtype name -> scene), the float64 scenes of
    the baseline, the commands (rows enough for every stage) and how the record names them."""

    scenes: dict
    base_scenes: dict
    commands: np.ndarray
    models: tuple
    description: str
    command_text: str


def run(
    batches=(1, 100),
    models=("PAC",),
    dtypes=("float64", "float32"),
    baseline_models=("PAC",),
    baseline_batch: int = 8,
    grad_batch: int = 16,
    seed: int = 0,
    scene: pj.Scene | None = None,
    scene_label: str | None = None,
    log=print,
    save=None,
) -> dict:
    """The full benchmark; returns the JSON-ready record (see :func:`to_markdown`).

    ``save(record)``, when given, is called after every measurement with the record so far, so a
    long run that is stopped (a time limit, a crash in a later stage) keeps what it measured.

    By default the paper's robot with each of ``models``; with ``scene`` (float64) that scene
    alone, labelled ``scene_label`` (``models`` and ``baseline_models`` are then ignored and the
    baseline runs on it), under uniform commands in its :func:`pacjax.cli.batchrun.default_ranges`.
    """
    batches = _check_sizes(batches, dtypes, baseline_batch, grad_batch)
    n_rows = max(batches + [baseline_batch, grad_batch])
    if scene is None:
        subjects = _paper_subjects(models, baseline_models, baseline_batch, n_rows, seed)
    else:
        subjects = _scene_subjects(scene, scene_label, baseline_batch, n_rows, seed)
    record = _new_record(subjects, batches, dtypes, baseline_batch, grad_batch)

    def checkpoint():
        # The ratios first, so that every saved record is complete as far as it goes.
        _ratios(record)
        if save is not None:
            save(record)

    commands = subjects.commands
    for model, make in subjects.scenes.items():
        tips = _measure_model(record, model, make, dtypes, batches, commands, log, checkpoint)
        if "float64" in tips and "float32" in tips:
            record["float32_vs_float64"][model] = _compare_dtypes(make, tips, max(batches))
            checkpoint()
    for model, sc in subjects.base_scenes.items():
        _measure_baseline(record, model, sc, commands[:baseline_batch], log, checkpoint)
    if grad_batch:
        for model, make in subjects.scenes.items():
            scene64 = make("float64")
            _measure_gradient(record, model, scene64, commands[:grad_batch], log, checkpoint)
    return record


def _check_sizes(batches, dtypes, baseline_batch: int, grad_batch: int) -> list[int]:
    """The batch sizes as ints, after checking them, the dtypes and the stage sizes (before
    anything is built or compiled)."""
    batches = [int(b) for b in batches]
    if not batches or min(batches) < 1:
        raise ValueError(f"batch sizes must be >= 1, got {batches}")
    for d in dtypes:
        if d not in DTYPES:
            raise ValueError(f"dtype must be one of {', '.join(DTYPES)}; got {d!r}")
    if not dtypes:
        raise ValueError("dtypes is empty")
    if baseline_batch < 0 or grad_batch < 0:
        raise ValueError("baseline_batch and grad_batch must be >= 0 (0: skip)")
    return batches


def _paper_subjects(models, baseline_models, baseline_batch: int, n_rows: int, seed: int):
    """The paper's robot with each model, under :func:`random_commands`."""
    if not models:
        raise ValueError("models is empty")
    for m in (*models, *baseline_models):
        if m not in MODELS:
            raise ValueError(f"model must be one of {', '.join(MODELS)}; got {m!r}")
    return _Subjects(
        scenes={m: (lambda d, m=m: paper_scene(m, d)) for m in models},
        base_scenes={m: paper_scene(m) for m in baseline_models} if baseline_batch else {},
        commands=random_commands(n_rows, seed=seed),
        models=models,
        description=f"pj.presets.stella2023(model, tip_mass={TIP_MASS})",
        command_text=f"uniform pull-ins in [0, {MAX_PULL_IN}] m, seed {seed}",
    )


def _scene_subjects(scene: pj.Scene, label, baseline_batch: int, n_rows: int, seed: int):
    """One given (float64) scene, under uniform commands in its default ranges."""
    from .batchrun import default_ranges

    label = label or type(scene.model).__name__
    low, high = default_ranges(scene)

    def cast(d, s=scene):
        return s if d == "float64" else pj.astype(s, DTYPES[d])

    return _Subjects(
        scenes={label: cast},
        base_scenes={label: scene} if baseline_batch else {},
        commands=np.random.default_rng(seed).uniform(low, high, (n_rows, scene.n_tendons)),
        models=(label,),
        description=label,
        command_text=f"uniform in pacjax.cli.batchrun.default_ranges, seed {seed}",
    )


def _new_record(subjects: _Subjects, batches, dtypes, baseline_batch: int, grad_batch: int):
    """The record before any measurement: the machine, the configuration, empty results."""
    return {
        "machine": machine_info(),
        "config": {
            "scene": subjects.description,
            "commands": subjects.command_text,
            "batches": batches,
            "models": list(subjects.models),
            "dtypes": list(dtypes),
            "tolerances": {d: TOLERANCES[d] for d in dtypes},
            "baseline_models": list(subjects.base_scenes),
            "baseline_batch": baseline_batch,
            "grad_batch": grad_batch,
            "note": "compile_s = first call - warm call (a load from the persistent compilation "
            "cache when it holds the program); no flow fallback in the batch solver",
        },
        "results": [],
        "baselines": {},
        "gradients": {},
        "float32_vs_float64": {},
    }


def _measure_model(record, model, make, dtypes, batches, commands, log, checkpoint) -> dict:
    """One model's batch-solver rows (every dtype x batch size) into ``record["results"]``;
    returns ``{dtype: (q as float64, converged)}`` of the largest batch, for the dtype
    comparison."""
    tips = {}
    for dtype in dtypes:
        sc = make(dtype)
        for batch in batches:
            log(f"{model} {dtype} batch {batch} ...")
            row, eq = bench_batch(sc, commands[:batch], TOLERANCES[dtype])
            row.update(model=model, dtype=dtype)
            record["results"].append(row)
            log(
                f"  {row['equilibria_per_s']:.1f} eq/s, compile {row['compile_s']:.1f} s, "
                f"converged {row['converged']:.1%}"
            )
            checkpoint()
            if batch == max(batches):
                tips[dtype] = (np.asarray(eq.q, np.float64), np.asarray(eq.converged))
    return tips


def _compare_dtypes(make, tips: dict, batch: int) -> dict:
    """Tip-position differences between the float32 and float64 solutions (both evaluated on the
    float64 scene, so only the solves differ) over the rows converged in both."""
    scene64 = make("float64")
    q64, ok64 = tips["float64"]
    q32, ok32 = tips["float32"]
    both = ok64 & ok32
    diff = np.linalg.norm(
        np.asarray(_tips(scene64, jnp.asarray(q64))) - np.asarray(_tips(scene64, jnp.asarray(q32))),
        axis=1,
    )
    return {
        "batch": batch,
        "rows_both_converged": int(both.sum()),
        "max_tip_difference_m": float(diff[both].max()) if both.any() else None,
        "median_tip_difference_m": float(np.median(diff[both])) if both.any() else None,
    }


def _measure_baseline(record, model, scene, commands, log, checkpoint) -> None:
    """One model's plain-flow baseline into ``record["baselines"]``."""
    log(f"{model} float64 plain-flow baseline, batch {len(commands)} ...")
    base, _ = bench_flow_baseline(scene, commands, TOLERANCES["float64"])
    record["baselines"][model] = base
    checkpoint()
    log(
        f"  {base['equilibria_per_s']:.2f} eq/s, compile {base['compile_s']:.1f} s, "
        f"converged {base['converged']:.1%}"
    )


def _measure_gradient(record, model, scene, commands, log, checkpoint) -> None:
    """One model's gradient cost into ``record["gradients"]``."""
    log(f"{model} float64 gradient through a batch of {len(commands)} ...")
    g = bench_gradient(scene, commands, TOLERANCES["float64"])
    record["gradients"][model] = g
    checkpoint()
    log(f"  gradient / forward = {g['gradient_over_forward']:.2f}")


def _ratios(record: dict) -> None:
    """Each result's rate over its model's plain-flow baseline (None without one)."""
    for row in record["results"]:
        base = record["baselines"].get(row["model"])
        row["vs_flow_baseline"] = (
            row["equilibria_per_s"] / base["equilibria_per_s"] if base else None
        )


def to_markdown(record: dict) -> str:
    """The record as Markdown tables."""
    lines = [
        f"# pacjax bench: equilibria of {record['config']['scene']}",
        "",
        _machine_line(record["machine"]),
        "",
        *_results_table(record["results"]),
    ]
    if record["baselines"]:
        lines += _baselines_table(record["baselines"])
    if record["gradients"]:
        lines += _gradients_table(record["gradients"])
    if record["float32_vs_float64"]:
        lines += _dtype_lines(record["float32_vs_float64"])
    lines += ["", "compile = first call - warm call (or a persistent-cache load).", ""]
    return "\n".join(lines)


def _machine_line(m: dict) -> str:
    """The processor, backend, JAX version and platform (and the load, where known) in one
    line."""
    return (
        f"{m['processor']}, {m['cpu_count']} CPUs, {m['backend']} ({', '.join(m['devices'])}), "
        f"jax {m['jax']}, {m['platform']}"
        + (f", load average {m['load_average_1min']:.1f}" if "load_average_1min" in m else "")
    )


def _results_table(results: list) -> list[str]:
    """The batch solver's rows: one per model x dtype x batch size."""
    lines = [
        "| model | dtype | batch | tol | compile (s) | run (s) | eq/s | vs plain flow | "
        "converged | max residual | steps |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        ratio = f"{r['vs_flow_baseline']:.0f}x" if r.get("vs_flow_baseline") else "-"
        res = r["max_residual_converged"]
        lines.append(
            f"| {r['model']} | {r['dtype']} | {r['batch']} | {r['tol']:.0e} | "
            f"{r['compile_s']:.1f} | {r['run_s']:.3f} | {r['equilibria_per_s']:.1f} | {ratio} | "
            f"{r['converged']:.1%} | {'-' if res is None else f'{res:.1e}'} | "
            f"{r['steps_median']:.0f} |"
        )
    return lines


def _baselines_table(baselines: dict) -> list[str]:
    """The plain-flow baseline per model, under a line saying what it is."""
    lines = [
        "",
        "Plain-flow baseline (`D qdot = -F`, diffrax Kvaerno5, PID control, steady-state "
        "event at the same tolerance, vmapped, float64):",
        "",
        "| model | batch | compile (s) | run (s) | eq/s | converged | steps |",
        "|---|---|---|---|---|---|---|",
    ]
    for model, b in baselines.items():
        lines.append(
            f"| {model} | {b['batch']} | {b['compile_s']:.1f} | {b['run_s']:.2f} | "
            f"{b['equilibria_per_s']:.2f} | {b['converged']:.0%} | {b['steps_median']:.0f} |"
        )
    return lines


def _gradients_table(gradients: dict) -> list[str]:
    """The gradient's cost against the forward solve, per model."""
    lines = [
        "",
        "Gradient of the sum of tip x w.r.t. the commands through a vmapped "
        "`pj.solve_equilibrium` (float64, implicit function theorem):",
        "",
        "| model | batch | forward (s) | gradient (s) | gradient / forward | "
        "compile fwd / grad (s) |",
        "|---|---|---|---|---|---|",
    ]
    for model, g in gradients.items():
        lines.append(
            f"| {model} | {g['batch']} | {g['forward_run_s']:.3f} | "
            f"{g['gradient_run_s']:.3f} | {g['gradient_over_forward']:.2f} | "
            f"{g['forward_compile_s']:.1f} / {g['gradient_compile_s']:.1f} |"
        )
    return lines


def _dtype_lines(comparisons: dict) -> list[str]:
    """float32 against float64: a bullet per model."""
    lines = ["", "float32 against float64 (same commands, rows converged in both):", ""]
    for model, a in comparisons.items():
        mx = a["max_tip_difference_m"]
        lines.append(
            f"- {model}, batch {a['batch']}: max tip difference "
            + ("-" if mx is None else f"{1e3 * mx:.2g} mm")
            + f" over {a['rows_both_converged']} rows"
        )
    return lines


def parse_list(text: str, kind=str) -> list:
    """``"a,b,c"`` -> ``[kind(a), kind(b), kind(c)]``."""
    items = [x.strip() for x in text.split(",") if x.strip()]
    return [kind(x) for x in items]


__all__ = [
    "MODELS",
    "TOLERANCES",
    "bench_batch",
    "bench_flow_baseline",
    "bench_gradient",
    "machine_info",
    "paper_scene",
    "random_commands",
    "run",
    "to_markdown",
]
