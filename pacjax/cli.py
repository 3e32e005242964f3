"""The ``pacjax`` command line.

- ``pacjax demo [--out DIR]``: the paper's robot with a 200 g payload under a few tendon
  commands, PCC and PAC; prints a table (tip positions, PAC-PCC differences, convergence,
  timings) and writes ``demo.png``.
- ``pacjax solve SCENE.toml [--controls u1,u2,...] [--out DIR]``: solves a scene file (see
  :mod:`pacjax.scenefile`) and writes ``<name>.json`` and ``<name>.png``.
- ``pacjax inverse SCENE.toml TARGETS.csv [--out DIR]``: tendon commands that put the tip on
  each ``x,y,z`` row (m) of the CSV (a path, warm-started row to row, or ``--independent``);
  writes ``<name>_commands.csv`` and ``<name>_inverse.png``; exit status 3 when a target was
  not reached.
- ``pacjax batch SCENE.toml --n N [--sampler lhs|uniform|grid] [--out DIR]``: samples N commands,
  solves them chunk by chunk and writes ``<name>_batch.h5``, ``<name>_batch.json`` and
  ``<name>_workspace.png`` (see :mod:`pacjax.batchrun`).
- ``pacjax bench [--batch 1,100] [--models PAC] [--dtypes float64,float32] [--json F] [--md F]``:
  equilibria per second of the paper's robot (see :mod:`pacjax.bench`).

Compiling a solver dominates a first run (tens of seconds); JAX's persistent compilation cache
(``~/.cache/pacjax-jax``, or ``$PACJAX_CACHE_DIR``; ``PACJAX_CACHE_DIR=off`` disables it) keeps
compiled solvers between runs. User errors (missing or malformed files, wrong number of
controls) print one line and exit with status 1 (2 for usage errors), without a traceback;
``solve`` exits with status 3 when the solver did not converge (after writing its results).
"""

from __future__ import annotations

import json
import math
import os
import sys
import time

import click
import equinox as eqx
import jax
import numpy as np

import pacjax as pj

#: The demo's tendon commands: pull-ins (m) of the nine tendons, three per section at 90, 210
#: and 330 degrees around the cross-section (section 1 free, sections 2 and 3 in Bowden cables).
DEMO_COMMANDS = {
    "section 1 bend": (0.04, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    "S-shape": (0.0, 0.04, 0.0, 0.05, 0.0, 0.05, 0.0, 0.0, 0.0),
    "all contracted": (0.03,) * 9,
    "combined": (0.045, 0.01, 0.01, 0.0, 0.035, 0.0, 0.01, 0.01, 0.04),
}
DEMO_MODELS = {"PCC": pj.PCC, "PAC": pj.PAC}


def _enable_compilation_cache() -> None:
    cache = os.environ.get("PACJAX_CACHE_DIR", os.path.join("~", ".cache", "pacjax-jax"))
    if cache.lower() in ("", "off", "none", "0"):
        return
    jax.config.update("jax_compilation_cache_dir", os.path.expanduser(cache))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(pj.__version__, prog_name="pacjax")
def cli():
    """Statics of tendon-driven continuum robots: PCC, PAC and polynomial curvature."""
    _enable_compilation_cache()


def main() -> None:
    """Console-script entry point."""
    cli(prog_name="pacjax")


# ------------------------------------------------------------------------------ helpers
def _timed_solve(scene, controls, **options):
    start = time.perf_counter()
    eq = pj.solve_equilibrium(scene, controls, **options)
    jax.block_until_ready(eq)
    return eq, time.perf_counter() - start


@eqx.filter_jit
def _summary(scene, q, controls):
    """Tip pose, marker positions and tendon tensions at ``q``, in one compiled call (op by
    op, these kinematics take seconds)."""
    tip = pj.tip_pose(scene, q)
    marker_positions = pj.markers(scene, q) if scene.markers else None
    tensions = pj.tendon_tensions(scene, q, controls) if scene.n_tendons else None
    return tip, marker_positions, tensions


def _progress(total: int, desc: str):
    from tqdm import tqdm

    # disable=None: no bar when stderr is not a terminal (logs, pipes, tests).
    return tqdm(
        total=total, desc=desc, unit="solve", file=sys.stderr, leave=False, ncols=88, disable=None
    )


def _float(x) -> float | None:
    """A JSON-safe float (NaN and infinities become null)."""
    value = float(np.asarray(x))
    return value if math.isfinite(value) else None


def _output_dir(out: str) -> str:
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as err:
        raise click.ClickException(f"cannot create output directory {out!r}: {err}") from None
    return out


# ------------------------------------------------------------------------------ demo
@cli.command()
@click.option(
    "--out",
    default=".",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Directory for demo.png.",
)
@click.option(
    "--tip-mass", default=0.2, show_default=True, type=click.FloatRange(min=0), help="Payload, kg."
)
def demo(out: str, tip_mass: float):
    """Solve the paper's robot (PCC and PAC) under a few tendon commands."""
    from . import plots

    out = _output_dir(out)
    rows = []
    compile_s = {}
    groups: dict[str, dict] = {name: {} for name in DEMO_COMMANDS}
    bar = _progress(2 * len(DEMO_COMMANDS) * len(DEMO_MODELS), "demo")
    with bar:
        for model_name, model in DEMO_MODELS.items():
            scene = pj.presets.stella2023(model(), tip_mass=tip_mass)
            for i, (command, controls) in enumerate(DEMO_COMMANDS.items()):
                bar.set_postfix_str(
                    f"{model_name}: {'compiling' if i == 0 else command}", refresh=True
                )
                eq, first = _timed_solve(scene, np.asarray(controls))
                bar.update()
                _, warm = _timed_solve(scene, np.asarray(controls))  # same work, compiled
                bar.update()
                if i == 0:
                    compile_s[model_name] = max(first - warm, 0.0)
                (tip, _), _, _ = _summary(scene, eq.q, np.asarray(controls))
                rows.append((command, model_name, np.asarray(tip), eq, warm))
                groups[command][model_name] = (scene, eq.q)

    tips = {(c, m): tip for c, m, tip, _, _ in rows}
    head = (
        f"{'command':<16} {'model':<5} {'tip x':>8} {'tip y':>8} {'tip z':>8} "
        f"{'PAC-PCC':>8} {'conv':>5} {'stable':>6} {'residual':>9} {'steps':>5} {'ms':>7}"
    )
    units = f"{'':<16} {'':<5} {'mm':>8} {'mm':>8} {'mm':>8} {'mm':>8}"
    click.echo(f"stella2023 preset, hanging, {1e3 * tip_mass:.0f} g payload; controls in metres")
    click.echo(head)
    click.echo(units)
    click.echo("-" * len(head))
    for command, model_name, tip, eq, warm in rows:
        diff = ""
        if model_name != "PCC" and (command, "PCC") in tips:
            diff = f"{1e3 * np.linalg.norm(tip - tips[command, 'PCC']):8.2f}"
        click.echo(
            f"{command:<16} {model_name:<5} {1e3 * tip[0]:8.1f} {1e3 * tip[1]:8.1f} "
            f"{1e3 * tip[2]:8.1f} {diff:>8} {'yes' if bool(eq.converged) else 'NO':>5} "
            f"{'yes' if bool(eq.stable) else 'NO':>6} {float(eq.residual_norm):9.1e} "
            f"{int(eq.steps):5d} {1e3 * warm:7.1f}"
        )
    click.echo("-" * len(head))
    click.echo("ms: warm solve (already compiled), timed by re-running the same command.")
    click.echo(
        "First solve's compilation (or load from the disk cache): "
        + ", ".join(f"{m} {s:.1f} s" for m, s in compile_s.items())
    )
    click.echo("Commands (pull-ins, m; tendons at 90/210/330 deg, sections 1-3):")
    for command, controls in DEMO_COMMANDS.items():
        sections = ["  ".join(f"{u:5.3f}" for u in controls[k : k + 3]) for k in (0, 3, 6)]
        click.echo(f"  {command:<16} " + "  |  ".join(sections))

    titled = {}
    for command, cases in groups.items():
        diff = 1e3 * np.linalg.norm(tips[command, "PAC"] - tips[command, "PCC"])
        titled[f"{command}\n|tip PAC - PCC| = {diff:.1f} mm"] = cases
    path = os.path.join(out, "demo.png")
    plots.plot_equilibrium_grid(
        titled,
        path,
        title=(
            f"Stella et al. 2023 robot, {1e3 * tip_mass:.0f} g payload: "
            "PCC vs PAC under four tendon commands"
        ),
    )
    click.echo(f"wrote {path}")


# ------------------------------------------------------------------------------ solve
def _parse_controls(text: str, n_tendons: int) -> np.ndarray:
    try:
        values = [float(v) for v in text.replace(" ", "").split(",") if v != ""]
    except ValueError:
        raise click.ClickException(
            f"--controls must be comma-separated numbers, got {text!r}"
        ) from None
    if len(values) != n_tendons:
        raise click.ClickException(
            f"--controls has {len(values)} value(s) but the scene has {n_tendons} tendon(s)"
        )
    return np.asarray(values)


@cli.command()
@click.argument("scene_file", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "--controls",
    help="Comma-separated controls, one per tendon (m pull-in, or N tension); "
    "default: the file's `controls`, else zeros.",
)
@click.option(
    "--out",
    default=".",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Directory for <name>.json and <name>.png.",
)
@click.option("--no-plot", is_flag=True, help="Skip the figure.")
def solve(scene_file: str, controls: str | None, out: str, no_plot: bool):
    """Solve the equilibrium of a TOML scene file."""
    from .scenefile import load_scene

    try:
        scene, file_controls, extra = load_scene(scene_file)
    except (ValueError, OSError) as err:
        raise click.ClickException(str(err)) from None
    if controls is not None:
        u = _parse_controls(controls, scene.n_tendons)
    elif file_controls is not None:
        u = file_controls
    else:
        u = np.zeros(scene.n_tendons)
    out = _output_dir(out)
    name = extra["name"]
    try:
        eq, seconds = _timed_solve(scene, u, **extra["solver"])
    except ValueError as err:
        raise click.ClickException(f"{scene_file}: {err}") from None

    (tip, rotation), marker_positions, tensions = _summary(scene, eq.q, u)
    result = {
        "scene": os.path.abspath(scene_file),
        "name": name,
        "model": type(scene.model).__name__,
        "controls": [float(v) for v in u],
        "q": [float(v) for v in np.asarray(eq.q)],
        "coordinate_names": list(scene.coordinate_names()),
        "converged": bool(eq.converged),
        "residual_norm": _float(eq.residual_norm),
        "stable": bool(eq.stable),
        "min_hessian_eigenvalue": _float(eq.min_hessian_eigenvalue),
        "steps": int(eq.steps),
        "reason": eq.reason,
        "energy": _float(eq.energy),
        "tip": {
            "position": [float(v) for v in np.asarray(tip)],
            "rotation": np.asarray(rotation).tolist(),
        },
        "markers": None,
        "tendon_tensions": None,
        "solve_time_s": seconds,
        "units": "SI: m, rad, N, J; controls m (length mode) or N (tension mode)",
    }
    if scene.markers:
        result["markers"] = {
            "sites": [[seg, s, list(offset)] for seg, s, offset in scene.markers],
            "positions": np.asarray(marker_positions).tolist(),
        }
    if tensions is not None:
        result["tendon_tensions"] = [float(v) for v in np.asarray(tensions)]

    json_path = os.path.join(out, f"{name}.json")
    with open(json_path, "w", encoding="utf-8") as f:
        json.dump(result, f, indent=2)
        f.write("\n")

    status = "converged" if result["converged"] else f"NOT converged ({eq.reason})"
    stability = "stable" if result["stable"] else "UNSTABLE (saddle)"
    t = 1e3 * np.asarray(tip)
    click.echo(
        f"{name}: {status}, {stability}, residual {float(eq.residual_norm):.1e}, "
        f"{result['steps']} steps, {seconds:.2f} s"
    )
    click.echo(f"tip position: x {t[0]:.1f} mm, y {t[1]:.1f} mm, z {t[2]:.1f} mm")
    if result["tendon_tensions"] is not None:
        tensions = ", ".join(f"{v:.3g}" for v in result["tendon_tensions"])
        click.echo(f"tendon tensions (N): {tensions}")
    click.echo(f"wrote {json_path}")
    if not no_plot:
        from . import plots

        png_path = os.path.join(out, f"{name}.png")
        label = f"{result['model']} ({'converged' if result['converged'] else 'not converged'})"
        plots.plot_equilibria(
            scene,
            {label: eq.q},
            png_path,
            title=f"{name}: " + (extra["description"] or os.path.basename(scene_file)),
        )
        click.echo(f"wrote {png_path}")
    if not result["converged"]:
        sys.exit(3)


# ------------------------------------------------------------------------------ fit
def _names(text: str) -> tuple[str, ...]:
    return tuple(x.strip() for x in text.split(",") if x.strip())


@cli.command()
@click.argument("scene_file", type=click.Path(exists=True, dir_okay=False))
@click.argument("data_file", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "--params",
    default="bending_stiffness,mocap_transform",
    show_default=True,
    help="Comma-separated parameters to fit (see pacjax.identify).",
)
@click.option("--per-segment", default="", help="Parameters fitted per segment / tendon.")
@click.option(
    "--holdout",
    default=0.2,
    show_default=True,
    type=click.FloatRange(0.0, 0.9),
    help="Fraction of frames held out for validation (0: none).",
)
@click.option("--loss", type=click.Choice(["l2", "huber"]), default="l2", show_default=True)
@click.option("--noise", default=1e-3, show_default=True, help="Marker noise scale, m.")
@click.option("--max-iterations", default=50, show_default=True, type=click.IntRange(min=0))
@click.option("--seed", default=0, show_default=True, help="Seed of the held-out split.")
@click.option(
    "--out",
    default=".",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Directory for the fitted scene, the report and the plots.",
)
@click.option("--no-plot", is_flag=True, help="Skip the figures.")
def fit(
    scene_file,
    data_file,
    params,
    per_segment,
    holdout,
    loss,
    noise,
    max_iterations,
    seed,
    out,
    no_plot,
):
    """Fit a scene's parameters to static motion-capture frames (pacjax mocap CSV).

    Writes <name>_fitted.toml, <name>_fit.json, <name>_fit.md and, unless --no-plot, the loss
    curve, predicted vs measured backbones and an error histogram (PNG).
    """
    from .mocapfile import load_mocap
    from .scenefile import load_scene, save_scene

    try:
        scene, _, extra = load_scene(scene_file)
    except (ValueError, OSError) as err:
        raise click.ClickException(str(err)) from None
    with open(data_file, encoding="utf-8-sig") as f:
        if f.readline().startswith("Format Version"):
            raise click.ClickException(
                f"{data_file} is a Motive export: attach the robot's commands and pick static "
                "frames with pacjax.mocapfile.motive_dataset, then save_mocap it"
            )
    try:
        data = load_mocap(data_file)
        fitted, report = pj.identify(
            scene,
            data,
            _names(params),
            per_segment=_names(per_segment),
            holdout=holdout,
            seed=seed,
            loss=loss,
            noise=noise,
            max_iterations=max_iterations,
            solver_options=extra["solver"],
        )
    except (ValueError, TypeError) as err:
        raise click.ClickException(str(err)) from None
    out = _output_dir(out)
    name = extra["name"]
    paths = {
        "scene": os.path.join(out, f"{name}_fitted.toml"),
        "json": os.path.join(out, f"{name}_fit.json"),
        "md": os.path.join(out, f"{name}_fit.md"),
    }
    save_scene(paths["scene"], fitted, name=f"{name} (fitted)")
    report.to_json(paths["json"])
    with open(paths["md"], "w", encoding="utf-8") as f:
        f.write(report.to_markdown())
    if not no_plot:
        from . import fitplots

        paths["loss"] = os.path.join(out, f"{name}_fit_loss.png")
        paths["backbones"] = os.path.join(out, f"{name}_fit_backbones.png")
        paths["errors"] = os.path.join(out, f"{name}_fit_errors.png")
        fitplots.plot_loss(report, paths["loss"])
        fitplots.plot_backbones(fitted, report, paths["backbones"])
        fitplots.plot_error_histogram(report, paths["errors"])
    click.echo(f"{name}: {report.message}; {report.iterations} iterations, {report.time_s:.1f} s")
    for pname, p in report.parameters.items():
        for label, value, std in zip(p["labels"], p["value"], p["std"], strict=True):
            sd = "" if std is None else f" +- {std:.3g}"
            click.echo(f"  {pname}{label} = {value:.6g}{sd} {p['unit']}")
    click.echo(f"train RMSE {report.train.rmse_mm:.3f} mm ({len(report.train.q)} frames)")
    if report.validation is not None:
        click.echo(
            f"held-out RMSE {report.validation.rmse_mm:.3f} mm ({len(report.validation.q)} frames)"
        )
    for path in paths.values():
        click.echo(f"wrote {path}")


# ------------------------------------------------------------------------------ inverse
def _read_targets(path: str) -> np.ndarray:
    """Target tip positions (m) from a CSV file: one ``x,y,z`` row per target, an optional
    header line (any non-numeric first line), ``#`` comments."""
    rows = []
    with open(path, encoding="utf-8") as f:
        lines = [ln.strip() for ln in f if ln.strip() and not ln.lstrip().startswith("#")]
    for i, line in enumerate(lines):
        cells = [c.strip() for c in line.split(",")]
        try:
            values = [float(c) for c in cells]
        except ValueError:
            if i == 0:
                continue  # header
            raise click.ClickException(f"{path}: row {i + 1} is not numbers: {line!r}") from None
        if len(values) != 3:
            raise click.ClickException(
                f"{path}: row {i + 1} has {len(values)} value(s); expected x,y,z in metres"
            )
        rows.append(values)
    if not rows:
        raise click.ClickException(f"{path}: no targets (expected rows of x,y,z in metres)")
    targets = np.asarray(rows)
    if not np.all(np.isfinite(targets)):
        raise click.ClickException(f"{path}: targets must be finite numbers")
    return targets


@cli.command()
@click.argument("scene_file", type=click.Path(exists=True, dir_okay=False))
@click.argument("targets_file", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "--out",
    default=".",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Directory for <name>_commands.csv and <name>_inverse.png.",
)
@click.option(
    "--independent",
    is_flag=True,
    help="Solve every target from fresh starts (default: the rows are a path, each warm-started "
    "from the previous one).",
)
@click.option(
    "--tol",
    default=1e-4,
    show_default=True,
    type=click.FloatRange(min=0, min_open=True),
    help="Reached threshold on the tip position error, m.",
)
@click.option("--upper", type=click.FloatRange(min=0, min_open=True), help="Largest command (m).")
@click.option(
    "--max-tension", type=click.FloatRange(min=0, min_open=True), help="Tension limit, N."
)
@click.option("--no-plot", is_flag=True, help="Skip the figure.")
def inverse(
    scene_file: str,
    targets_file: str,
    out: str,
    independent: bool,
    tol: float,
    upper: float | None,
    max_tension: float | None,
    no_plot: bool,
):
    """Tendon commands that put the tip of a TOML scene on the targets of a CSV file (x,y,z in
    metres per row). Exits with status 3 when a target was not reached."""
    from .scenefile import load_scene

    try:
        scene, _, extra = load_scene(scene_file)
    except (ValueError, OSError) as err:
        raise click.ClickException(str(err)) from None
    targets = _read_targets(targets_file)
    out = _output_dir(out)
    name = extra["name"]
    options = dict(reached_tol=tol, upper=upper, max_tension=max_tension)
    options["solver_options"] = extra["solver"] or None
    start = time.perf_counter()
    try:
        if independent:
            results = [pj.inverse_statics(scene, t, **options) for t in targets]
            result = jax.tree_util.tree_map(lambda *xs: np.stack(xs), *results)
        else:
            result = pj.track(scene, targets, **options).result
    except ValueError as err:
        raise click.ClickException(f"{scene_file}: {err}") from None
    seconds = time.perf_counter() - start

    controls = np.asarray(result.controls)
    reached = np.asarray(result.reached)
    csv_path = os.path.join(out, f"{name}_commands.csv")
    header = (
        ["target_x", "target_y", "target_z", "reached", "error_m", "tip_x", "tip_y", "tip_z"]
        + [f"u{i}" for i in range(scene.n_tendons)]
        + [f"tension{i}" for i in range(scene.n_tendons)]
        + ["iterations"]
    )
    with open(csv_path, "w", encoding="utf-8") as f:
        f.write("# pacjax inverse: commands u (m pull-in, or N tension), tensions N, lengths m\n")
        f.write(",".join(header) + "\n")
        for i in range(len(targets)):
            row = list(targets[i]) + [int(reached[i]), float(result.error[i])]
            row += list(np.asarray(result.position[i])) + list(controls[i])
            row += list(np.asarray(result.tensions[i])) + [int(result.iterations[i])]
            f.write(",".join(f"{v:.9g}" if isinstance(v, float) else str(v) for v in row) + "\n")
    jumps = np.abs(np.diff(controls, axis=0)).max() if len(controls) > 1 else 0.0
    click.echo(
        f"{name}: {int(reached.sum())}/{len(targets)} targets reached within {1e3 * tol:g} mm, "
        f"largest error {1e3 * float(np.max(result.error)):.3g} mm, {seconds:.1f} s"
    )
    click.echo(f"largest command change between neighbouring rows: {1e3 * jumps:.2f} mm")
    click.echo(f"wrote {csv_path}")
    if not no_plot:
        from . import plots

        png_path = os.path.join(out, f"{name}_inverse.png")
        shown = np.unique(np.linspace(0, len(targets) - 1, min(len(targets), 6)).astype(int))
        cases = {f"target {i + 1}": np.asarray(result.q[i]) for i in shown}
        plots.plot_equilibria(
            scene,
            cases,
            png_path,
            title=f"{name}: reached backbones ({int(reached.sum())}/{len(targets)} reached)",
            markers=False,
            targets={"target": targets, "reached tip": np.asarray(result.position)},
        )
        click.echo(f"wrote {png_path}")
    if not reached.all():
        sys.exit(3)


# ------------------------------------------------------------------------------ simulate
@cli.command()
@click.argument("scene_file", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "--controls",
    help="Comma-separated controls stepped to at t = 0, one per tendon (m pull-in, or N "
    "tension); default: the file's `controls`, else zeros.",
)
@click.option(
    "--duration",
    default=2.0,
    show_default=True,
    type=click.FloatRange(min=0, min_open=True),
    help="Simulated time, s.",
)
@click.option(
    "--start",
    type=click.Choice(["equilibrium", "straight"]),
    default="equilibrium",
    show_default=True,
    help="Initial state: at rest in the equilibrium under zero controls (a step in commands), "
    "or straight and at rest.",
)
@click.option(
    "--damping-ratio",
    default=0.05,
    show_default=True,
    type=click.FloatRange(min=0),
    help="Damping ratio of the lowest mode (stiffness-proportional damping).",
)
@click.option("--fps", default=20, show_default=True, type=click.IntRange(min=1))
@click.option(
    "--out",
    default=".",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Directory for <name>_sim.gif, <name>_tip.png and <name>_sim.json.",
)
def simulate(
    scene_file: str,
    controls: str | None,
    duration: float,
    start: str,
    damping_ratio: float,
    fps: int,
    out: str,
):
    """Simulate the dynamics of a TOML scene file after a step in commands."""
    from . import animation
    from .scenefile import load_scene

    try:
        scene, file_controls, extra = load_scene(scene_file)
    except (ValueError, OSError) as err:
        raise click.ClickException(str(err)) from None
    if controls is not None:
        u = _parse_controls(controls, scene.n_tendons)
    elif file_controls is not None:
        u = file_controls
    else:
        u = np.zeros(scene.n_tendons)
    out = _output_dir(out)
    name = extra["name"]
    q0 = None
    if start == "equilibrium":
        eq, _ = _timed_solve(scene, np.zeros(scene.n_tendons), **extra["solver"])
        if not bool(eq.converged):
            raise click.ClickException(f"{scene_file}: the initial equilibrium did not converge")
        q0 = eq.q
    n_frames = max(2, int(round(duration * fps)) + 1)
    try:
        damping = pj.Damping.modal(scene, damping_ratio)
        begin = time.perf_counter()
        trajectory = pj.simulate(
            scene,
            (0.0, duration),
            u,
            q0=q0,
            saveat=np.linspace(0.0, duration, n_frames),
            damping=damping,
        )
        jax.block_until_ready(trajectory)
        seconds = time.perf_counter() - begin
    except ValueError as err:
        raise click.ClickException(f"{scene_file}: {err}") from None
    ok = bool(trajectory.success)
    tips = animation.tip_positions(scene, trajectory)
    result = {
        "scene": os.path.abspath(scene_file),
        "name": name,
        "model": type(scene.model).__name__,
        "controls": [float(v) for v in u],
        "start": start,
        "damping_ratio": damping_ratio,
        "success": ok,
        "steps": int(trajectory.num_steps),
        "wall_time_s": seconds,
        "t": [float(v) for v in np.asarray(trajectory.ts)],
        "q": np.asarray(trajectory.q).tolist(),
        "tip_position": tips.tolist(),
        "units": "SI: s, m, rad; wall time includes compilation",
    }
    json_path = os.path.join(out, f"{name}_sim.json")
    with open(json_path, "w", encoding="utf-8") as f:
        json.dump(result, f)
        f.write("\n")
    status = "reached the end" if ok else "FAILED before the end (step limit or solver failure)"
    click.echo(
        f"{name}: {duration:g} s simulated, {status}, {result['steps']} steps, "
        f"{seconds:.1f} s wall (compilation included)"
    )
    t = 1e3 * tips[-1]
    click.echo(f"final tip position: x {t[0]:.1f} mm, y {t[1]:.1f} mm, z {t[2]:.1f} mm")
    click.echo(f"wrote {json_path}")
    title = f"{name}: " + (extra["description"] or os.path.basename(scene_file))
    png_path = os.path.join(out, f"{name}_tip.png")
    animation.plot_tip_trajectory(scene, trajectory, png_path, title=title)
    click.echo(f"wrote {png_path}")
    if ok:
        gif_path = os.path.join(out, f"{name}_sim.gif")
        animation.animate_trajectory(scene, trajectory, gif_path, fps=fps, title=name)
        click.echo(f"wrote {gif_path}")
    else:
        sys.exit(3)


# ------------------------------------------------------------------------------ batch
def _per_tendon(text: str | None, option: str):
    """``--low``/``--high``: one number, or comma-separated numbers (one per tendon)."""
    if text is None:
        return None
    try:
        values = [float(v) for v in text.replace(" ", "").split(",") if v != ""]
    except ValueError:
        raise click.ClickException(
            f"{option} must be comma-separated numbers, got {text!r}"
        ) from None
    if not values:
        raise click.ClickException(f"{option} is empty")
    return values[0] if len(values) == 1 else values


@cli.command()
@click.argument("scene_file", type=click.Path(exists=True, dir_okay=False))
@click.option("--n", "n", required=True, type=click.IntRange(min=1), help="Number of commands.")
@click.option(
    "--sampler",
    type=click.Choice(["uniform", "lhs", "grid"]),
    default="lhs",
    show_default=True,
    help="Uniform random, Latin hypercube, or the full grid with at most N rows.",
)
@click.option("--seed", default=0, show_default=True, type=int, help="Sampling seed.")
@click.option("--low", help="Lowest command: one number or one per tendon (default: 0).")
@click.option(
    "--high",
    help="Highest command: one number or one per tendon (default: from the tendons, see "
    "pacjax.batchrun.default_ranges).",
)
@click.option(
    "--chunk-size",
    default=1024,
    show_default=True,
    type=click.IntRange(min=1),
    help="Rows per compiled call and per write (memory is bounded by it).",
)
@click.option("--tol", type=click.FloatRange(min=0, min_open=True), help="Solver tolerance.")
@click.option(
    "--float32",
    "use_float32",
    is_flag=True,
    help="Solve in float32 (tolerance 1e-4 unless --tol or the file's [solver] sets one).",
)
@click.option(
    "--out",
    default=".",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Directory for <name>_batch.h5, <name>_batch.json and <name>_workspace.png.",
)
@click.option("--no-plot", is_flag=True, help="Skip the workspace figure.")
def batch(scene_file, n, sampler, seed, low, high, chunk_size, tol, use_float32, out, no_plot):
    """Sample N tendon commands of a TOML scene, solve them chunk by chunk and write the
    equilibria (commands, q, markers, tip pose, converged, stable, residual, steps) to an HDF5
    file as they are solved, with a workspace plot and a JSON summary."""
    import jax.numpy as jnp

    from . import batchrun
    from .scenefile import load_scene

    # Everything is checked before anything is compiled.
    try:
        scene, _, extra = load_scene(scene_file)
        default_low, default_high = batchrun.default_ranges(scene)
        lo, hi = batchrun.check_ranges(
            default_low if low is None else _per_tendon(low, "--low"),
            default_high if high is None else _per_tendon(high, "--high"),
            scene.n_tendons,
        )
        commands = batchrun.sample_commands(sampler, n, lo, hi, seed)
        options = dict(extra["solver"])
        if tol is not None:
            options["tol"] = tol
        elif use_float32 and "tol" not in options:
            options["tol"] = 1e-4
        pj.SolverOptions(**{k: v for k, v in options.items() if k != "fallback"})
    except (ValueError, TypeError, OSError) as err:
        raise click.ClickException(f"{scene_file}: {err}") from None
    if use_float32:
        scene = pj.astype(scene, jnp.float32)
    out = _output_dir(out)
    name = extra["name"]
    paths = {
        "h5": os.path.join(out, f"{name}_batch.h5"),
        "json": os.path.join(out, f"{name}_batch.json"),
    }
    with open(scene_file, encoding="utf-8") as f:
        scene_text = f.read()
    attrs = {
        "scene_toml": scene_text,
        "sampler": sampler,
        "seed": seed,
        "low": lo,
        "high": hi,
        "dtype": "float32" if use_float32 else "float64",
        "tol": float(options.get("tol", pj.SolverOptions().tol)),
    }
    if len(commands) != n:
        click.echo(
            f"grid: {round(len(commands) ** (1 / scene.n_tendons))} values per tendon, "
            f"{len(commands)} rows"
        )
    bar = _progress(len(commands), "batch")
    with bar:
        bar.unit = "eq"
        summary = batchrun.run_batch(
            scene,
            commands,
            paths["h5"],
            chunk_size=chunk_size,
            attrs=attrs,
            on_chunk=bar.update,
            **options,
        )
    report = {
        "scene": os.path.abspath(scene_file),
        "name": name,
        "model": type(scene.model).__name__,
        **{k: v for k, v in attrs.items() if k != "scene_toml"},
        "low": lo.tolist(),
        "high": hi.tolist(),
        **summary.as_dict(),
        "file": os.path.abspath(paths["h5"]),
    }
    with open(paths["json"], "w", encoding="utf-8") as f:
        json.dump(report, f, indent=2)
        f.write("\n")
    click.echo(f"{name} ({report['model']}, {report['dtype']}, {sampler} sampling):")
    for line in summary.lines():
        click.echo("  " + line)
    if not no_plot:
        paths["png"] = batchrun.plot_workspace(
            paths["h5"], os.path.join(out, f"{name}_workspace.png"), title=name
        )
    for path in paths.values():
        click.echo(f"wrote {path}")


# ------------------------------------------------------------------------------ bench
@cli.command()
@click.option("--batch", "batches", default="1,100", show_default=True, help="Batch sizes.")
@click.option("--models", default="PAC", show_default=True, help="Strain models: PCC, PAC, Poly3.")
@click.option("--dtypes", default="float64,float32", show_default=True, help="float64, float32.")
@click.option(
    "--baseline-batch",
    default=8,
    show_default=True,
    type=click.IntRange(min=0),
    help="Batch of the plain damped-flow baseline (diffrax Kvaerno5; 0: skip).",
)
@click.option("--baseline-models", default="PAC", show_default=True, help="Models of the baseline.")
@click.option(
    "--grad-batch",
    default=16,
    show_default=True,
    type=click.IntRange(min=0),
    help="Batch of the gradient-cost measurement (0: skip).",
)
@click.option(
    "--scene",
    "scene_file",
    type=click.Path(exists=True, dir_okay=False),
    help="Benchmark this TOML scene instead of the paper's robot (--models is then ignored).",
)
@click.option("--seed", default=0, show_default=True, type=int, help="Commands' seed.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), help="Write the record.")
@click.option("--md", "md_path", type=click.Path(dir_okay=False), help="Write the tables.")
def bench(
    batches,
    models,
    dtypes,
    baseline_batch,
    baseline_models,
    grad_batch,
    scene_file,
    seed,
    json_path,
    md_path,
):
    """Equilibria per second of the paper's robot per model x batch size x dtype, compile time
    apart, against the plain damped flow, and the cost of a gradient through a batch."""
    from . import bench as benchmod

    try:
        batch_sizes = benchmod.parse_list(batches, int)
    except ValueError:
        raise click.ClickException(
            f"--batch must be comma-separated integers, got {batches!r}"
        ) from None
    scene = label = None
    if scene_file is not None:
        from .scenefile import load_scene

        try:
            scene, _, extra = load_scene(scene_file)
        except (ValueError, OSError) as err:
            raise click.ClickException(str(err)) from None
        label = extra["name"]
    options = dict(
        batches=batch_sizes,
        models=benchmod.parse_list(models),
        dtypes=benchmod.parse_list(dtypes),
        baseline_models=benchmod.parse_list(baseline_models),
        baseline_batch=baseline_batch,
        grad_batch=grad_batch,
        seed=seed,
        scene=scene,
        scene_label=label,
        log=lambda text: click.echo(text, err=True),
    )
    try:
        record = benchmod.run(**options)
    except (ValueError, TypeError) as err:
        raise click.ClickException(str(err)) from None
    text = benchmod.to_markdown(record)
    click.echo(text)
    if json_path:
        with open(json_path, "w", encoding="utf-8") as f:
            json.dump(record, f, indent=2)
            f.write("\n")
        click.echo(f"wrote {json_path}")
    if md_path:
        with open(md_path, "w", encoding="utf-8") as f:
            f.write(text)
        click.echo(f"wrote {md_path}")


if __name__ == "__main__":
    main()
