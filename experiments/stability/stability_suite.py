"""Stability suite: extreme cases x strain models x float32/float64.

Every case is solved with ``pj.solve_equilibrium`` (continuation, no diffrax fallback, so the
numbers are those of the default solver) inside one compiled ``jax.value_and_grad`` that also
differentiates a tip coordinate with respect to the controls (implicit function theorem). For
each case the suite records convergence, the reason, the scaled residual, the steps, stability,
the compile and run times, whether ``q``, the energy and the gradient are finite, and what the
case is about (tip height, total bending per segment, shortest segment).

Float32 runs use ``tol = 1e-4`` (as ``tests/test_gradients.py``: 1e-5 still converges on a
two-segment scene, 1e-6 is below float32's round-off floor); float64 the default ``1e-10``.

Each (model, dtype) runs in its own interpreter, so that a crash of XLA takes one row group, not
the suite. Run from the repository root:

    nice -n 10 python experiments/stability/stability_suite.py          # all, ~ tens of minutes
    python experiments/stability/stability_suite.py --models PCC --dtypes float64 \
        --cases straight_free

Writes ``experiments/stability/stability.json`` and ``stability.md``.
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import time

import numpy as np

HERE = pathlib.Path(__file__).parent
MODELS = ("PCC", "PAC", "Poly3")
DTYPES = {"float64": 1e-10, "float32": 1e-4}

# The base robot: two segments (0.1 m, EI 0.01 N m^2, k_a 1000 N/m, 0.1 kg/m), four tendons at
# 90 degree spacing, 1 cm from the backbone, anchored at the tip and running through both
# segments, guide rings at s = 0, 1/4, ..., 1.
SEG_LENGTH = 0.1
EI = 0.01
AXIAL = 1000.0
DENSITY = 0.1
OFFSET = 0.01
GAIN = 1e4  # N/m: gain * offset^2 = 1 N m against k_b = EI / L = 0.1 N m
ANGLES = (0.0, 0.5 * np.pi, np.pi, 1.5 * np.pi)
GUIDES = (0.0, 0.25, 0.5, 0.75, 1.0)
UPRIGHT = np.eye(3)
HANGING = np.diag([1.0, -1.0, -1.0])
HORIZONTAL = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
TIP_WEIGHTS = np.array([1.0, -2.0, 0.5])


def _critical_load(n_segments, seg_length, ei):
    """Euler load (N) of the clamped-free column: pi^2 EI / (4 L^2)."""
    return np.pi**2 * ei / (4 * (n_segments * seg_length) ** 2)


P_CR = _critical_load(2, SEG_LENGTH, EI)
K_BEND = EI / SEG_LENGTH  # bending stiffness scale k_b (N m per unit curvature per s)
STIFF_GAIN = 1e5 * K_BEND / OFFSET**2  # tendon stiffness gain r^2 = 1e5 k_b

# name: (what it tests, values put into the base structure, controls (4,), n_segments)
CASES = {
    "straight_free": (
        "exactly straight, no load, tendons at rest length (zero tension: on the kink of "
        "max(stretch, 0))",
        dict(g=0.0),
        [0.0, 0.0, 0.0, 0.0],
        2,
    ),
    "straight_hanging_payload": (
        "exactly straight, hanging, 0.5 kg tip payload (tension)",
        dict(rotation=HANGING, mass=0.5),
        [0.0, 0.0, 0.0, 0.0],
        2,
    ),
    "straight_upright_half_critical": (
        "exactly straight, upright, tip load 0.5 P_cr (compression below buckling)",
        dict(rotation=UPRIGHT, mass=0.5 * P_CR / 9.81, density=0.0),
        [0.0, 0.0, 0.0, 0.0],
        2,
    ),
    "upright_twice_critical": (
        "upright, tip load 2 P_cr: the straight state is a saddle; the default solver escapes "
        "it to a bent minimum",
        dict(rotation=UPRIGHT, mass=2.0 * P_CR / 9.81, density=0.0),
        [0.0, 0.0, 0.0, 0.0],
        2,
    ),
    "stiff_tendon_1e5": (
        f"tendon gain {STIFF_GAIN:.0e} N/m: gain r^2 = 1e5 k_b (gain / EI = "
        f"{STIFF_GAIN / EI:.0e} m^-3), hanging, 5 mm pull",
        dict(rotation=HANGING, gain=STIFF_GAIN),
        [0.005, 0.0, 0.0, 0.0],
        2,
    ),
    "soft_heavy_payload": (
        "EI 1e-4 N m^2 (100x softer), upright, 0.2 kg tip payload (~300 P_cr), one tendon "
        "pulled 3 cm: tip falls below the base, bending beyond 180 degrees",
        dict(rotation=UPRIGHT, ei=1e-4, mass=0.2),
        [0.03, 0.0, 0.0, 0.0],
        2,
    ),
    "contract_half_range": (
        "all four tendons pulled 0.1 m (half the 0.2 m length): axial contraction",
        dict(rotation=HANGING),
        [0.1, 0.1, 0.1, 0.1],
        2,
    ),
    "contract_past_end": (
        "all four tendons pulled 0.25 m (more than the 0.2 m length), EI 0.1 N m^2: each "
        "segment rests on its contraction stop (default limit 0.09 m), see min L+dL",
        dict(rotation=HANGING, ei=10 * EI),
        [0.25, 0.25, 0.25, 0.25],
        2,
    ),
    "contract_past_end_soft": (
        "as contract_past_end with EI 0.01 N m^2: ~700 N per tendon against the stop makes the "
        "straight state unstable (chords between rings shorten as the body bends); the body "
        "folds up with no equilibrium short of self-contact, which the model does not have",
        dict(rotation=HANGING),
        [0.25, 0.25, 0.25, 0.25],
        2,
    ),
    "all_slack": (
        "horizontal mount, gravity, every tendon paid out 1 cm (all slack)",
        dict(rotation=HORIZONTAL),
        [-0.01, -0.01, -0.01, -0.01],
        2,
    ),
    "antagonistic_hard": (
        "upright, opposite tendons (0 and 180 degrees) both pulled 2 cm at 10x gain",
        dict(rotation=UPRIGHT, gain=10 * GAIN),
        [0.02, 0.0, 0.02, 0.0],
        2,
    ),
    "many_segments_24": (
        "24 segments of 2 cm, horizontal, gravity, one tendon pulled 1 cm",
        dict(rotation=HORIZONTAL, seg_length=0.02),
        [0.01, 0.0, 0.0, 0.0],
        24,
    ),
}


# ------------------------------------------------------------------------------------ worker
def _model(name):
    import pacjax as pj

    return {"PCC": pj.PCC(), "PAC": pj.PAC(), "Poly3": pj.PolynomialCurvature(3)}[name]


def _structure(model, n_segments, seg_length):
    """The scene structure shared by all cases with ``n_segments`` (values are set later)."""
    import pacjax as pj

    seg = pj.Segment(seg_length, EI, AXIAL, linear_density=DENSITY, radius=0.015)
    guides = GUIDES if n_segments <= 4 else (0.0, 0.5, 1.0)
    tendons = [pj.Tendon(n_segments - 1, a, OFFSET, gain=GAIN, guides=guides) for a in ANGLES]
    loads = (pj.Gravity(), pj.PointMass(0.0, n_segments - 1, 1.0))
    return pj.Scene(pj.Robot([seg] * n_segments), model, tendons=tendons, loads=loads)


def _with_values(
    scene,
    dtype,
    ei=EI,
    gain=GAIN,
    mass=0.0,
    g=9.81,
    rotation=HANGING,
    density=DENSITY,
    seg_length=None,
):
    """Put values into the structure (no recompilation: only array leaves change)."""
    import equinox as eqx
    import jax.numpy as jnp

    import pacjax as pj

    n = scene.n_segments
    f = lambda x: jnp.asarray(x, dtype)  # noqa: E731
    segs = scene.robot.segments
    scene = eqx.tree_at(
        lambda s: (
            [x.bending_stiffness for x in s.robot.segments]
            + [x.torsion_stiffness for x in s.robot.segments]
            + [x.linear_density for x in s.robot.segments]
            + [t.gain for t in s.tendons]
            + [s.loads[0].g, s.loads[1].mass, s.robot.base_rotation]
        ),
        pj.astype(scene, dtype),
        [f(ei)] * n
        + [f(ei / 1.5)] * n
        + [f(density)] * n
        + [f(gain)] * len(scene.tendons)
        + [f(g), f(mass), f(rotation)],
    )
    del segs
    return scene


def _metrics(scene, q):
    """Tip height above the base (m, world z), total turning per segment (deg), L + dL (m)."""
    import jax.numpy as jnp

    import pacjax as pj

    q = jnp.asarray(q)
    n = scene.n_segments
    per = 24
    pos, rot = pj.backbone(scene, q, n * per + 1)
    z = np.asarray(rot)[:, :, 2]
    cosines = np.clip(np.sum(z[1:] * z[:-1], axis=1), -1.0, 1.0)
    turning = np.degrees(np.arccos(cosines)).reshape(n, per).sum(axis=1)
    d = scene.dofs_per_segment
    lengths = np.asarray([float(s.length) for s in scene.robot.segments])
    elong = np.asarray(q, float).reshape(n, d)[:, d - 1]
    base = np.asarray(scene.robot.base_position, float)
    return {
        "tip_height_m": float(np.asarray(pos)[-1, 2] - base[2]),
        "max_turning_deg": float(turning.max()),
        "total_turning_deg": float(turning.sum()),
        "min_length_m": float((lengths + elong).min()),
    }


def run_worker(model_name, dtype_name, case_names):
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    import pacjax as pj
    from pacjax._results import code_of

    # Compile times below are those of a cold cache: the persistent cache stays off.

    dtype = {"float64": jnp.float64, "float32": jnp.float32}[dtype_name]
    tol = DTYPES[dtype_name]
    model = _model(model_name)
    weights = jnp.asarray(TIP_WEIGHTS, dtype)

    @eqx.filter_jit
    def solve_and_grad(scene, controls):
        def tip_loss(u):
            eq = pj.solve_equilibrium(scene, u, tol=tol, fallback=False)
            _, pos = scene.frames(eq.q, np.array([scene.n_segments - 1]), jnp.ones(1, dtype))
            return pos[0] @ weights, eq

        (loss, eq), grad = jax.value_and_grad(tip_loss, has_aux=True)(controls)
        return eq, loss, grad

    structures = {}
    for name in case_names:
        what, values, controls, n_segments = CASES[name]
        values = dict(values)
        seg_length = values.get("seg_length", SEG_LENGTH)
        key = (n_segments, seg_length)
        compiles = key not in structures
        if compiles:
            structures[key] = _structure(model, n_segments, seg_length)
        scene = _with_values(structures[key], dtype, **values)
        u = jnp.asarray(controls, dtype)
        t0 = time.perf_counter()
        eq, loss, grad = jax.block_until_ready(solve_and_grad(scene, u))
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        eq, loss, grad = jax.block_until_ready(solve_and_grad(scene, u))
        run = time.perf_counter() - t0
        q = np.asarray(eq.q, float)
        record = {
            "case": name,
            "model": model_name,
            "dtype": dtype_name,
            "what": what,
            "tol": tol,
            "converged": bool(eq.converged),
            "result": int(code_of(eq.result)),
            "reason": eq.reason,
            "residual_norm": float(eq.residual_norm),
            "steps": int(eq.steps),
            "stable": bool(eq.stable),
            "min_hessian_eigenvalue": float(eq.min_hessian_eigenvalue),
            "energy": float(eq.energy),
            "q_finite": bool(np.all(np.isfinite(q))),
            "grad_finite": bool(np.all(np.isfinite(np.asarray(grad)))),
            "grad": np.asarray(grad, float).tolist(),
            # Only the first case of a scene structure compiles; later ones reuse it.
            "compile_s": first - run if compiles else None,
            "run_s": run,
            "n_dofs": scene.n_dofs,
        }
        if record["q_finite"]:
            record.update(_metrics(scene, eq.q))
        print(json.dumps(record), flush=True)


# ------------------------------------------------------------------------------------ report
def _fmt(x, spec):
    return "—" if x is None else format(x, spec)


def write_report(records, crashes, path_md, path_json, argv):
    with open(path_json, "w") as f:
        json.dump({"records": records, "crashes": crashes, "command": argv}, f, indent=1)
    lines = [
        "# Stability suite",
        "",
        "Generated by `experiments/stability/stability_suite.py` (see its docstring). Each row "
        "is one `pj.solve_equilibrium` (continuation solver, no diffrax fallback) inside a "
        "compiled `jax.value_and_grad` of a tip coordinate with respect to the controls. "
        "`res` is the scaled residual (tolerance 1e-10 in float64, 1e-4 in float32); `flag` is "
        "`ok` when converged with finite q and gradient, otherwise the explicit failure. "
        "`compile` is the first call minus the second (XLA compile; only the first case of "
        "each scene structure compiles, the others reuse it), `run` the second call (solve + "
        "gradient). `tip z` is the tip's height above the base (world z), `max turn` the "
        "largest total turning of the tangent within one segment, `min L+dL` the shortest "
        "segment. Times on a 2-core CPU shared with other jobs (load 6-9), so only indicative.",
        "",
        "## Cases",
        "",
    ]
    for name, (what, _, controls, n) in CASES.items():
        lines.append(f"- `{name}` ({n} segments, controls {controls} m): {what}")
    lines += [
        "",
        "## Results",
        "",
        "| case | model | dtype | flag | res | steps | stable | min eig | grad finite | "
        "tip z (m) | max turn (deg) | min L+dL (m) | compile (s) | run (ms) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    seen = set()
    short = {1: "max steps", 2: "non-finite", 3: "stalled"}
    for r in records:
        structure = (r["model"], r["dtype"], r["n_dofs"])
        if structure in seen:
            r = dict(r, compile_s=None)  # reused the compiled solver
        seen.add(structure)
        if r["converged"] and r["q_finite"] and r["grad_finite"]:
            flag = "ok"
        elif r["converged"]:
            flag = "CONVERGED BUT NON-FINITE"
        else:
            flag = f"FAILED: {short.get(r['result'], r['reason'])}"
        lines.append(
            f"| {r['case']} | {r['model']} | {r['dtype']} | {flag} | {r['residual_norm']:.1e} | "
            f"{r['steps']} | {r['stable']} | {r['min_hessian_eigenvalue']:.2e} | "
            f"{r['grad_finite']} | {_fmt(r.get('tip_height_m'), '.3f')} | "
            f"{_fmt(r.get('max_turning_deg'), '.0f')} | {_fmt(r.get('min_length_m'), '.4f')} | "
            f"{_fmt(r['compile_s'], '.0f')} | {1e3 * r['run_s']:.0f} |"
        )
    if crashes:
        lines += ["", "## Crashed runs", ""]
        for c in crashes:
            lines.append(
                f"- {c['model']} {c['dtype']}: return code {c['returncode']}: "
                f"`{c['stderr_tail'][-300:]}`"
            )
    n_ok = sum(r["converged"] and r["q_finite"] and r["grad_finite"] for r in records)
    silent = [r for r in records if r["converged"] and not (r["q_finite"] and r["grad_finite"])]
    lines += [
        "",
        f"{n_ok} of {len(records)} runs converged with finite gradients; "
        f"{len(records) - n_ok} returned an explicit failure flag; {len(silent)} silent "
        f"non-finite results; {len(crashes)} crashed interpreter(s).",
        "",
    ]
    with open(path_md, "w") as f:
        f.write("\n".join(lines))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=list(MODELS), choices=MODELS)
    parser.add_argument("--dtypes", nargs="+", default=list(DTYPES), choices=list(DTYPES))
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--out", default=str(HERE / "stability"))
    parser.add_argument("--worker", nargs=2, metavar=("MODEL", "DTYPE"), help=argparse.SUPPRESS)
    parser.add_argument(
        "--report-only", action="store_true", help="rewrite the .md from the existing .json"
    )
    args = parser.parse_args()
    if args.worker:
        run_worker(*args.worker, args.cases)
        return
    if args.report_only:
        with open(args.out + ".json") as f:
            data = json.load(f)
        write_report(
            data["records"], data["crashes"], args.out + ".md", args.out + ".json", data["command"]
        )
        return

    records, crashes = [], []
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    for model in args.models:
        for dtype in args.dtypes:
            cmd = [sys.executable, __file__, "--worker", model, dtype, "--cases", *args.cases]
            t0 = time.perf_counter()
            proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
            got = [json.loads(x) for x in proc.stdout.splitlines() if x.startswith("{")]
            records += got
            print(
                f"{model} {dtype}: {len(got)} cases in {time.perf_counter() - t0:.0f} s "
                f"(rc {proc.returncode})",
                flush=True,
            )
            for r in got:
                print(
                    f"  {r['case']:<32} conv={r['converged']!s:<5} res={r['residual_norm']:.1e} "
                    f"steps={r['steps']:<4} stable={r['stable']!s:<5} "
                    f"grad_finite={r['grad_finite']} {r['reason'][:40]}",
                    flush=True,
                )
            if proc.returncode != 0:
                done = {r["case"] for r in got}
                crashes.append(
                    {
                        "model": model,
                        "dtype": dtype,
                        "returncode": proc.returncode,
                        "missing_cases": [c for c in args.cases if c not in done],
                        "stderr_tail": proc.stderr[-2000:],
                    }
                )
                print(proc.stderr[-2000:], flush=True)
    write_report(records, crashes, args.out + ".md", args.out + ".json", sys.argv)


if __name__ == "__main__":
    main()
