"""Error against run time: which model, quadrature, dtype and tolerance for the paper's robot.

Usage: python experiments/error_vs_runtime/study.py [--n 40] [--quick] [--out DIR]

The paper's robot (``pj.presets.stella2023``, hanging, 9 tendons) under random commands (0-20 mm
pull-ins, the same for every configuration) and four loads: 0, 200 and 400 g at the tip (one
compiled scene, the mass set per row), and a 3.41 N follower force along the body at the tip
(local +z, the paper's human-interaction experiment; its own scene). Every configuration is
compared row by row with a reference: ``PolynomialCurvature(6)``, 12 quadrature points, float64,
tolerance 1e-12. The reference's own error is estimated by ``PolynomialCurvature(5)`` against
it; the same family converges to the Kirchhoff elastica (``experiments/convergence``).

Each configuration reports, over the rows where it and the reference converged: tip position
error (mm; mean and max), marker RMSE (mm; the 7 markers: base, midpoints and ends of the
sections), tip orientation error (degrees), and the time per equilibrium in a batch (warm
:func:`pacjax.solve_batch` with its default fallbacks, so the follower rows include the load
continuation some of them need; compile time apart). Output: ``results.json``, ``results.md`` and
``pareto.png`` (tip error against time per equilibrium) in ``--out``. Nothing is asserted;
timings are wall-clock on this machine (recorded with its load average).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import pacjax as pj
from pacjax.bench import machine_info, random_commands, timed

HERE = Path(__file__).parent
TIP_MASSES = (0.0, 0.2, 0.4)  # kg
TIP_FORCE = 3.41  # N, follower, along the body

MODELS = {
    "PCC": pj.PCC,
    "PAC": pj.PAC,
    "Poly2": lambda: pj.PolynomialCurvature(2),
    "Poly3": lambda: pj.PolynomialCurvature(3),
    "Poly4": lambda: pj.PolynomialCurvature(4),
    "Poly5": lambda: pj.PolynomialCurvature(5),
    "Poly6": lambda: pj.PolynomialCurvature(6),
}
REFERENCE = dict(model="Poly6", quadrature=12, dtype="float64", tol=1e-12)


def configurations(quick: bool) -> list[dict]:
    """The configurations compared with the reference (model x quadrature x dtype x tolerance)."""
    configs = []
    for model in ("PCC", "PAC", "Poly2", "Poly3", "Poly4"):
        configs.append(dict(model=model, quadrature=8, dtype="float64", tol=1e-10))
        if not quick:
            configs.append(dict(model=model, quadrature=8, dtype="float32", tol=1e-4))
    if not quick:
        configs += [
            dict(model="PAC", quadrature=4, dtype="float64", tol=1e-10),
            dict(model="Poly3", quadrature=4, dtype="float64", tol=1e-10),
            dict(model="PAC", quadrature=8, dtype="float64", tol=1e-6),
            dict(model="Poly5", quadrature=12, dtype="float64", tol=1e-12),
        ]
    return configs


def scene_for(config: dict, load: str) -> pj.Scene:
    """The paper's robot for one configuration; ``load`` is ``"mass"`` or ``"follower"``."""
    model = MODELS[config["model"]]()
    if load == "mass":
        scene = pj.presets.stella2023(model, tip_mass=0.2, quadrature_points=config["quadrature"])
    else:
        force = pj.PointForce((0.0, 0.0, TIP_FORCE), segment=2, s=1.0, follower=True)
        scene = pj.presets.stella2023(model, loads=(force,), quadrature_points=config["quadrature"])
    if config["dtype"] == "float32":
        scene = pj.astype(scene, jnp.float32)
    return scene


def _set_tip_mass(scene, mass):
    return eqx.tree_at(lambda s: s.loads[-1].mass, scene, mass)


def solve(config: dict, load: str, commands: np.ndarray, masses: np.ndarray | None) -> dict:
    """Solve every row (first call and a warm call timed); markers and tip pose per row."""
    scene = scene_for(config, load)
    kwargs = dict(chunk_size=len(commands), tol=config["tol"], progress=False)
    if masses is not None:
        kwargs.update(params=masses.astype(np.float32 if config["dtype"] == "float32" else float))
        kwargs.update(update=_set_tip_mass)

    def run():
        return pj.solve_batch(scene, commands, **kwargs)

    first, _ = timed(run)
    warm, eq = timed(run)
    q = np.asarray(eq.q, float)
    scene64 = scene_for(dict(config, dtype="float64"), load)
    marks = np.asarray(jax.vmap(lambda x: pj.markers(scene64, x))(jnp.asarray(q)))
    tip, rot = jax.vmap(lambda x: pj.tip_pose(scene64, x))(jnp.asarray(q))
    return {
        "first_call_s": first,
        "run_s": warm,
        "compile_s": max(first - warm, 0.0),
        "per_equilibrium_ms": 1e3 * warm / len(commands),
        "converged": np.asarray(eq.converged),
        "markers": marks,
        "tip": np.asarray(tip),
        "rot": np.asarray(rot),
    }


def errors(result: dict, reference: dict) -> dict:
    """Tip, marker and orientation errors of the rows that both converged."""
    ok = result["converged"] & reference["converged"]
    out = {"converged": float(np.mean(result["converged"])), "compared": int(ok.sum())}
    if not ok.any():
        return out
    tip = 1e3 * np.linalg.norm(result["tip"][ok] - reference["tip"][ok], axis=-1)
    diff = result["markers"][ok] - reference["markers"][ok]
    rmse = 1e3 * np.sqrt(np.mean(np.sum(diff**2, -1), -1))
    rel = np.einsum("bji,bjk->bik", reference["rot"][ok], result["rot"][ok])
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.degrees(np.arccos(cos))
    out.update(
        tip_mm_mean=float(tip.mean()),
        tip_mm_max=float(tip.max()),
        marker_rmse_mm=float(rmse.mean()),
        orientation_deg_mean=float(angle.mean()),
        orientation_deg_max=float(angle.max()),
    )
    return out


def _rows(result: dict, sl: slice) -> dict:
    return {key: v[sl] for key, v in result.items() if isinstance(v, np.ndarray)}


def label(config: dict) -> str:
    return f"{config['model']} q{config['quadrature']} {config['dtype']} tol {config['tol']:g}"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=40, help="random commands per load")
    parser.add_argument("--quick", action="store_true", help="float64 models only")
    parser.add_argument("--out", type=Path, default=HERE)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    commands = random_commands(args.n, seed=1)
    mass_rows = np.repeat(np.asarray(TIP_MASSES), args.n)
    loads = {
        "mass": (np.tile(commands, (len(TIP_MASSES), 1)), mass_rows),
        "follower": (commands, None),
    }
    started = time.time()
    reference = {load: solve(REFERENCE, load, *loads[load]) for load in loads}
    for load, ref in reference.items():
        print(f"reference {load}: {ref['converged'].mean():.0%} converged", flush=True)
    rows = []
    for config in configurations(args.quick):
        for load in loads:
            if config["dtype"] == "float32" and load == "follower":
                continue
            try:
                result = solve(config, load, *loads[load])
            except ValueError as err:  # e.g. too few quadrature points for the model
                print(f"skipped {label(config)}: {err}", flush=True)
                break
            row = dict(config, load=load, **errors(result, reference[load]))
            row.update(
                per_equilibrium_ms=result["per_equilibrium_ms"],
                compile_s=result["compile_s"],
                first_call_s=result["first_call_s"],
            )
            if load == "mass":  # errors per tip mass
                for k, m in enumerate(TIP_MASSES):
                    sl = slice(k * args.n, (k + 1) * args.n)
                    part, refp = _rows(result, sl), _rows(reference[load], sl)
                    row[f"tip_mm_mean_{int(1000 * m)}g"] = errors(part, refp).get("tip_mm_mean")
            rows.append(row)
            print(
                f"{label(config):36s} {load:8s} tip {row.get('tip_mm_mean', float('nan')):9.4f} mm"
                f" (max {row.get('tip_mm_max', float('nan')):.4f}), "
                f"{row['per_equilibrium_ms']:.1f} ms/eq, compile {row['compile_s']:.0f} s, "
                f"converged {row['converged']:.0%}",
                flush=True,
            )
    record = {
        "machine": machine_info(),
        "commands_per_load": args.n,
        "tip_masses_kg": list(TIP_MASSES),
        "follower_force_N": TIP_FORCE,
        "reference": REFERENCE,
        "reference_converged": {k: float(v["converged"].mean()) for k, v in reference.items()},
        "wall_s": time.time() - started,
        "load_average_end": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "rows": rows,
    }
    (args.out / "results.json").write_text(json.dumps(record, indent=2))
    (args.out / "results.md").write_text(markdown(record))
    pareto(rows, args.out / "pareto.png")
    print(f"wrote {args.out}/results.json, results.md, pareto.png")


def markdown(record: dict) -> str:
    lines = [
        "# Error against run time: the paper's robot",
        "",
        f"Reference: {label(record['reference'])}; {record['commands_per_load']} random commands "
        f"per load (0-20 mm pull-ins); tip masses {record['tip_masses_kg']} kg (one scene, mass "
        f"per row) and a {record['follower_force_N']} N follower force at the tip. Errors over "
        "the rows where both converged; time per equilibrium from a warm `solve_batch` of all "
        f"rows (CPU count {record['machine']['cpu_count']}, load average at the end "
        f"{record['load_average_end']:.1f}).",
        "",
        "| configuration | load | tip error mean (mm) | tip error max (mm) | marker RMSE (mm) "
        "| orientation mean (deg) | 0 / 200 / 400 g tip mean (mm) | ms per equilibrium "
        "| compile (s) | converged |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in record["rows"]:
        per_mass = (
            " / ".join(
                f"{r[k]:.3g}" if r.get(k) is not None else "-"
                for k in ("tip_mm_mean_0g", "tip_mm_mean_200g", "tip_mm_mean_400g")
            )
            if r["load"] == "mass"
            else "-"
        )
        lines.append(
            f"| {label(r)} | {r['load']} | {r.get('tip_mm_mean', float('nan')):.3g} "
            f"| {r.get('tip_mm_max', float('nan')):.3g} "
            f"| {r.get('marker_rmse_mm', float('nan')):.3g} "
            f"| {r.get('orientation_deg_mean', float('nan')):.3g} | {per_mass} "
            f"| {r['per_equilibrium_ms']:.1f} | {r['compile_s']:.0f} | {r['converged']:.0%} |"
        )
    return "\n".join(lines) + "\n"


def pareto(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), sharey=False)
    for ax, load, title in zip(
        axes,
        ("mass", "follower"),
        ("0 / 200 / 400 g at the tip", "3.41 N follower force"),
        strict=True,
    ):
        pts = [r for r in rows if r["load"] == load and "tip_mm_mean" in r]
        for r in pts:
            marker = "o" if r["dtype"] == "float64" else "s"
            ax.scatter(r["per_equilibrium_ms"], max(r["tip_mm_mean"], 1e-9), marker=marker)
            ax.annotate(
                f"{r['model']} q{r['quadrature']}"
                + (" f32" if r["dtype"] == "float32" else "")
                + (f" tol {r['tol']:g}" if r["tol"] not in (1e-10, 1e-4) else ""),
                (r["per_equilibrium_ms"], max(r["tip_mm_mean"], 1e-9)),
                fontsize=7,
                xytext=(4, 2),
                textcoords="offset points",
            )
        front = sorted(pts, key=lambda r: r["per_equilibrium_ms"])
        best, line = np.inf, []
        for r in front:
            if r["tip_mm_mean"] < best:
                best = r["tip_mm_mean"]
                line.append((r["per_equilibrium_ms"], max(best, 1e-9)))
        if line:
            ax.plot(*zip(*line, strict=True), color="0.6", lw=1, zorder=0, label="Pareto front")
        ax.set_yscale("log")
        ax.set_xlabel("time per equilibrium in a batch (ms)")
        ax.set_ylabel("mean tip error vs reference (mm)")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    fig.suptitle("Paper's robot: accuracy against run time (circles float64, squares float32)")
    fig.tight_layout()
    fig.savefig(path, dpi=130)


if __name__ == "__main__":
    main()
