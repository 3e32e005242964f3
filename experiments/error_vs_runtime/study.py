"""Error against run time: which model, quadrature, dtype and tolerance for the paper's robot.

Usage: python experiments/error_vs_runtime/study.py [--n 40] [--quick] [--out DIR]
       [--jobs J --cores-per-job C] [--time-limit S] [--task-time-limit S]
       [--loads mass,follower]
       [--follower-reference MODEL] [--merge-only --raw DIR]

Each (configuration, load) is solved in its own process (``--jobs`` at a time, each pinned to
``--cores-per-job`` CPUs, so that a large host stands for several small machines); its raw result
goes to ``--raw`` and the tables are made from there, so a run cut by ``--time-limit`` keeps what
finished and can be resumed.

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
from pacjax.cli.bench import machine_info, random_commands, timed

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


def tasks(quick: bool, references: dict) -> list[tuple[str, dict, str]]:
    """``(key, configuration, load)`` of every solve for the loads in ``references`` (load ->
    reference configuration), the references first, then the follower loads (the longest)
    before the masses, so parallel jobs finish together. A configuration that is its load's
    reference is not compared with itself."""
    loads = [load for load in ("follower", "mass") if load in references]
    out = [(f"reference-{load}", references[load], load) for load in loads]
    for load in loads:
        for config in configurations(quick):
            if (config["dtype"] == "float32" and load == "follower") or config == references[load]:
                continue
            key = f"{label(config)}-{load}".replace(" ", "_")
            out.append((key, config, load))
    return out


def load_rows(n: int) -> dict:
    commands = random_commands(n, seed=1)
    mass_rows = np.repeat(np.asarray(TIP_MASSES), n)
    return {
        "mass": (np.tile(commands, (len(TIP_MASSES), 1)), mass_rows),
        "follower": (commands, None),
    }


def run_task(key: str, config: dict, load: str, n: int, raw: Path) -> None:
    """Solve one configuration under one load and save its raw result in ``raw/KEY.npz``."""
    meta = dict(config=config, load=load, machine=machine_info())
    meta["cores"] = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    try:
        result = solve(config, load, *load_rows(n)[load])
    except ValueError as err:  # e.g. too few quadrature points for the model
        meta["skipped"] = str(err)
        (raw / f"{key}.json").write_text(json.dumps(meta, indent=2))
        return
    arrays = {k: v for k, v in result.items() if isinstance(v, np.ndarray)}
    np.savez(raw / f"{key}.npz", **arrays)
    meta.update({k: v for k, v in result.items() if not isinstance(v, np.ndarray)})
    (raw / f"{key}.json").write_text(json.dumps(meta, indent=2))


def run_all(todo, args) -> None:
    """Run the tasks as subprocesses, ``--jobs`` at a time, each pinned to its own
    ``--cores-per-job`` CPUs (XLA:CPU sizes its thread pool from the affinity), so that on a
    large host every job sees the small machine it stands for."""
    import subprocess
    import sys

    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    per = args.cores_per_job or (len(cpus) if cpus else 1)
    slots = [cpus[i : i + per] for i in range(0, len(cpus), per)] if cpus else [None]
    slots = [c for c in slots if c is None or len(c) == per][: max(args.jobs, 1)]
    running: dict = {}
    pending = list(todo)
    deadline = time.time() + args.time_limit if args.time_limit else np.inf
    while pending or running:
        if time.time() > deadline:  # what finished is kept; the rest is reported as not run
            for key, proc, log, _ in running.values():
                proc.kill()
                proc.wait()
                log.close()
                (args.raw / f"{key}.json").unlink(missing_ok=True)
                print(f"{key}: stopped at the time limit", flush=True)
            return
        free = [s for s in range(len(slots)) if s not in running]
        while pending and free:
            key, _, _ = pending.pop(0)
            slot = free.pop(0)
            cmd = [sys.executable, __file__, "--task", key, "--n", str(args.n)]
            cmd += ["--raw", str(args.raw), "--loads", args.loads]
            cmd += ["--follower-reference", args.follower_reference]
            cmd += ["--quick"] if args.quick else []
            cores = slots[slot]
            pre = (lambda c=cores: os.sched_setaffinity(0, c)) if cores else None
            log = open(args.raw / f"{key}.log", "w")  # noqa: SIM115 (closed when it ends)
            proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, preexec_fn=pre)
            running[slot] = (key, proc, log, time.time())
        time.sleep(1.0)
        for slot, (key, proc, log, t0) in list(running.items()):
            if args.task_time_limit and proc.poll() is None:
                if time.time() - t0 > args.task_time_limit:  # reported as not run
                    proc.kill()
                    proc.wait()
                    print(f"{key}: stopped after {args.task_time_limit:.0f} s", flush=True)
            if proc.poll() is not None:
                log.close()
                print(f"{key}: exit {proc.returncode} after {time.time() - t0:.0f} s", flush=True)
                del running[slot]


def merge(todo, n: int, raw: Path) -> dict:
    """Errors of every finished task against the reference, and the record."""

    def read(key):
        meta_path, arr_path = raw / f"{key}.json", raw / f"{key}.npz"
        if not meta_path.exists():
            return None, None
        meta = json.loads(meta_path.read_text())
        arrays = dict(np.load(arr_path)) if arr_path.exists() else None
        return meta, arrays

    loads = sorted({load for _, _, load in todo})
    references = {load: read(f"reference-{load}") for load in loads}
    reference = {load: arrays for load, (_, arrays) in references.items()}
    rows, missing = [], []
    ref_meta = next((meta for meta, _ in references.values() if meta), {})
    for key, config, load in todo:
        if key.startswith("reference"):
            continue
        meta, result = read(key)
        if meta is None or reference[load] is None:
            missing.append(key)
            continue
        if result is None:
            print(f"skipped {label(config)}: {meta['skipped']}", flush=True)
            continue
        row = dict(config, load=load, **errors(result, reference[load]))
        row.update({k: meta[k] for k in ("per_equilibrium_ms", "compile_s", "first_call_s")})
        if load == "mass":  # errors per tip mass
            for k, m in enumerate(TIP_MASSES):
                sl = slice(k * n, (k + 1) * n)
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
    return {
        "machine": ref_meta.get("machine", machine_info()),
        "cores_per_job": ref_meta.get("cores"),
        "commands_per_load": n,
        "tip_masses_kg": list(TIP_MASSES),
        "follower_force_N": TIP_FORCE,
        "reference": REFERENCE,
        "references": {
            load: next(c for k, c, x in todo if k == f"reference-{x}" and x == load)
            for load in loads
        },
        "reference_converged": {
            k: float(v["converged"].mean()) for k, v in reference.items() if v is not None
        },
        "not_run": missing,
        "rows": rows,
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=40, help="random commands per load")
    parser.add_argument("--quick", action="store_true", help="float64 models only")
    parser.add_argument("--out", type=Path, default=HERE)
    parser.add_argument("--raw", type=Path, help="raw results per task (default OUT/raw)")
    parser.add_argument("--jobs", type=int, default=1, help="tasks run at once")
    parser.add_argument(
        "--cores-per-job", type=int, default=0, help="CPUs pinned to each task (0: all)"
    )
    parser.add_argument("--merge-only", action="store_true", help="tables from --raw only")
    parser.add_argument(
        "--time-limit", type=float, default=0.0, help="stop unfinished tasks after S seconds"
    )
    parser.add_argument(
        "--task-time-limit", type=float, default=0.0, help="stop a task after S seconds"
    )
    parser.add_argument(
        "--loads",
        default="mass,follower",
        help="comma-separated loads to run (mass, follower); the rows of the others are kept "
        "from OUT/results.json",
    )
    parser.add_argument(
        "--follower-reference",
        default=REFERENCE["model"],
        choices=list(MODELS),
        help="reference model for the follower load (12 points, float64, tol 1e-12)",
    )
    parser.add_argument("--task", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    args.raw = args.raw or args.out / "raw"
    args.raw.mkdir(parents=True, exist_ok=True)
    loads = [x.strip() for x in args.loads.split(",") if x.strip()]
    if not loads or set(loads) - {"mass", "follower"}:
        parser.error(f"--loads must name mass and/or follower, got {args.loads!r}")
    references = {"mass": REFERENCE, "follower": dict(REFERENCE, model=args.follower_reference)}
    todo = tasks(args.quick, {load: references[load] for load in loads})
    if args.task is not None:
        key, config, load = next(t for t in todo if t[0] == args.task)
        run_task(key, config, load, args.n, args.raw)
        return
    started = time.time()
    if not args.merge_only:
        run_all([t for t in todo if not (args.raw / f"{t[0]}.json").exists()], args)
    record = merge(todo, args.n, args.raw)
    existing = args.out / "results.json"
    if set(loads) != {"mass", "follower"} and existing.exists():
        kept = json.loads(existing.read_text())
        if kept["commands_per_load"] == args.n:  # the other loads' rows, from their own run
            record["rows"] = [r for r in kept["rows"] if r["load"] not in loads] + record["rows"]
            for load, ref in kept.get("references", {"mass": kept["reference"]}).items():
                record["references"].setdefault(load, ref)
            record["not_run"] = [k for k in kept["not_run"] if k.split("-")[-1] not in loads] + [
                k for k in record["not_run"]
            ]
            record["earlier_run"] = {k: kept[k] for k in ("machine", "wall_s", "cores_per_job")}
    record["wall_s"] = time.time() - started
    record["load_average_end"] = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    (args.out / "results.json").write_text(json.dumps(record, indent=2))
    (args.out / "results.md").write_text(markdown(record))
    pareto(record["rows"], args.out / "pareto.png")
    print(f"wrote {args.out}/results.json, results.md, pareto.png")


def markdown(record: dict) -> str:
    lines = [
        "# Error against run time: the paper's robot",
        "",
        "References: "
        + "; ".join(f"{load}: {label(ref)}" for load, ref in sorted(record["references"].items()))
        + f". {record['commands_per_load']} random commands "
        f"per load (0-20 mm pull-ins); tip masses {record['tip_masses_kg']} kg (one scene, mass "
        f"per row) and a {record['follower_force_N']} N follower force at the tip. Errors over "
        "the rows where both converged; time per equilibrium from a warm `solve_batch` of all "
        f"rows on {record['cores_per_job']} pinned CPU cores of a {record['machine']['cpu_count']}"
        f"-core host ({record['machine']['processor']}; load average at the end "
        f"{record['load_average_end']:.1f}).",
        "",
    ]
    if record["not_run"]:
        lines += [f"Not run (time ran out): {', '.join(record['not_run'])}.", ""]
    lines += [
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
    """Mean tip error against time per equilibrium, one panel per load that has rows: colour by
    model, filled circles float64 at the default settings, squares float32, open markers the
    other quadratures and tolerances; the grey line is the Pareto front."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    titles = {"mass": "0 / 200 / 400 g at the tip", "follower": "3.41 N follower force at the tip"}
    loads = [load for load in titles if any(r["load"] == load and "tip_mm_mean" in r for r in rows)]
    if not loads:
        return
    models = list(MODELS)
    colours = dict(zip(models, plt.get_cmap("tab10").colors, strict=False))
    fig, axes = plt.subplots(1, len(loads), figsize=(6.5 * len(loads), 5.0), squeeze=False)
    for ax, load in zip(axes[0], loads, strict=True):
        pts = [r for r in rows if r["load"] == load and "tip_mm_mean" in r]
        for r in pts:
            default = r["quadrature"] == 8 and r["tol"] in (1e-10, 1e-4)
            marker = {"float64": "o", "float32": "s"}[r["dtype"]] if default else "D"
            x, y = r["per_equilibrium_ms"], max(r["tip_mm_mean"], 1e-9)
            ax.scatter(
                x,
                y,
                marker=marker,
                s=60,
                color=colours[r["model"]],
                facecolors=colours[r["model"]] if default else "none",
                linewidths=1.5,
                label=label(r),
                zorder=3,
            )
        front = sorted(pts, key=lambda r: r["per_equilibrium_ms"])
        best, line = np.inf, []
        for r in front:
            if r["tip_mm_mean"] < best:
                best = r["tip_mm_mean"]
                line.append((r["per_equilibrium_ms"], max(best, 1e-9)))
        ax.plot(*zip(*line, strict=True), color="0.6", lw=1, zorder=1, label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        plain = matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}")
        ax.xaxis.set_major_formatter(plain)
        ax.xaxis.set_minor_formatter(plain)
        ax.tick_params(axis="x", which="minor", labelsize=7)
        ax.set_xlabel("time per equilibrium in a batch (ms)")
        ax.set_ylabel("mean tip error against the reference (mm)")
        ax.set_title(titles[load])
        ax.grid(True, which="both", alpha=0.3)
    labelled = {}  # every configuration once, from whichever panel shows it
    for ax in axes[0]:
        for handle, text in zip(*ax.get_legend_handles_labels(), strict=True):
            labelled.setdefault(text, handle)
    axes[0][-1].legend(
        labelled.values(),
        labelled.keys(),
        loc="center left",
        bbox_to_anchor=(1.02, 0.5),
        fontsize=8,
        frameon=False,
    )
    fig.suptitle(
        "Paper's robot: accuracy against run time (filled: 8 points at tol 1e-10 (float64) "
        "or 1e-4 (float32); open diamonds: other settings)",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=130, bbox_inches="tight")
    plt.close(fig)


if __name__ == "__main__":
    main()
