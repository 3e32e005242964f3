"""What a new user waits for: the first call of each entry point, each in a fresh process.

Usage: python benchmarks/first_run.py [--robots paper,tension] [--entries solve,batch,...]
       [--modes off,cold,warm] [--repeat 1] [--json out.json]

For each robot and entry point a fresh Python process imports pacjax, builds the scene and makes
the first call; the parent records

- ``import_s``: ``import pacjax`` plus the first attribute (which imports JAX);
- ``first_s``: the first call, blocked until its result is ready (tracing, compiling or loading
  from the cache, and running);
- ``warm_s``: the same call again in the same process (run time alone); ``first_s - warm_s`` is
  what compilation costs;
- ``trace_s``, ``lower_s``, ``compile_s``: of the first call, the seconds JAX spent tracing
  Python to jaxprs, lowering them to StableHLO and compiling them with XLA (or loading them from
  the cache), from ``jax.monitoring``; ``programs``: how many programs XLA compiled, and the
  three longest.

Modes: ``off`` (no persistent compilation cache), ``cold`` (a new, empty cache that the call
fills) and ``warm`` (the same cache again, in a new process). The entry points:

- ``solve``: ``pj.solve_equilibrium`` of one command;
- ``batch``: ``pj.solve_batch`` of 100 random commands;
- ``identify``: ``pj.identify`` of the bending stiffness, started 50 % high, from 16 synthetic
  frames in the world frame with 1 mm noise (made once, beforehand, in another process, and
  read from a mocap CSV);
- ``inverse``: ``pj.inverse_statics`` of one reachable tip target;
- ``simulate``: ``pj.simulate`` of 0.1 s after a step in commands.

Robots: ``paper`` (``pj.presets.stella2023(pj.PAC())``, hanging, 200 g payload, 9 length-mode
tendons) and ``tension`` (``experiments/scenes/tendon_single.toml``: one PCC segment, three
tendons in tension mode). Also timed: ``pacjax --help`` (median of 5). Nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
TENSION_SCENE = os.path.join(HERE, "..", "experiments", "scenes", "tendon_single.toml")
ENTRIES = ("solve", "batch", "identify", "inverse", "simulate")
ROBOTS = ("paper", "tension")
MODES = ("off", "cold", "warm")


# ------------------------------------------------------------------------------ child side
def _scene(robot: str):
    import pacjax as pj

    if robot == "paper":
        return pj.presets.stella2023(pj.PAC(), tip_mass=0.2), 0.02
    scene, _, _ = pj.io.load_scene(TENSION_SCENE)
    return scene, 3.0


def _commands(n_tendons: int, top: float, n: int, seed: int):
    import numpy as np

    return np.random.default_rng(seed).uniform(0.0, top, (n, n_tendons))


def _call(entry: str, robot: str, data_dir: str):
    """A function that makes the entry point's call (its result blocked on by the caller)."""
    import numpy as np

    import pacjax as pj

    scene, top = _scene(robot)
    u = _commands(scene.n_tendons, top, 1, seed=1)[0]
    if entry == "solve":
        return lambda: pj.solve_equilibrium(scene, u)
    if entry == "batch":
        commands = _commands(scene.n_tendons, top, 100, seed=2)
        return lambda: pj.solve_batch(scene, commands)
    if entry == "identify":
        dataset = pj.io.load_mocap(os.path.join(data_dir, f"{robot}_mocap.csv"))
        start = _scaled_stiffness(scene, 1.5)  # the fit starts 50 % off
        return lambda: pj.identify(start, dataset, ("bending_stiffness",), max_iterations=20)
    if entry == "inverse":
        with open(os.path.join(data_dir, f"{robot}_target.json"), encoding="utf-8") as f:
            target = np.asarray(json.load(f))
        bounds = {"max_tension": 2 * top} if robot == "tension" else {}
        return lambda: pj.inverse_statics(scene, target, **bounds)
    if entry == "simulate":
        return lambda: pj.simulate(scene, (0.0, 0.1), u)
    raise ValueError(f"unknown entry {entry!r}")


def _scaled_stiffness(scene, factor: float):
    import equinox as eqx

    segments = tuple(
        eqx.tree_at(lambda s: s.bending_stiffness, seg, factor * seg.bending_stiffness)
        for seg in scene.robot.segments
    )
    return eqx.tree_at(lambda s: s.robot.segments, scene, segments)


def _make_data(robot: str, data_dir: str) -> None:
    """16 synthetic frames and one reachable target, written for the measuring processes."""
    import numpy as np

    import pacjax as pj

    scene, top = _scene(robot)
    # In the world frame: the fit is of the stiffness alone (a random mocap frame, the
    # default, would need `mocap_transform` fitted too; without it the fit had nothing to
    # converge to).
    commands = _commands(scene.n_tendons, top, 16, seed=3)
    dataset, _ = pj.synthetic_mocap(scene, commands, seed=0, transform=None)
    pj.io.save_mocap(os.path.join(data_dir, f"{robot}_mocap.csv"), dataset)
    eq = pj.solve_equilibrium(scene, _commands(scene.n_tendons, top, 1, seed=4)[0])
    tip, _ = pj.tip_pose(scene, eq.q)
    with open(os.path.join(data_dir, f"{robot}_target.json"), "w", encoding="utf-8") as f:
        json.dump([float(v) for v in np.asarray(tip)], f)


def _child(entry: str, robot: str, data_dir: str, cache: str | None) -> dict:
    start = time.perf_counter()
    import pacjax as pj

    if cache:
        pj.enable_compilation_cache(cache)
    else:
        pj.Scene  # noqa: B018  (the first attribute imports JAX)
    import_s = time.perf_counter() - start
    call = _call(entry, robot, data_dir)
    programs = _listen_to_compilations()
    first_s = _timed(call)
    first = _summarise(programs)  # before the warm call adds nothing, or a recompilation
    return {"import_s": import_s, "first_s": first_s, "warm_s": _timed(call)} | first


def _timed(call) -> float:
    import jax

    t = time.perf_counter()
    jax.block_until_ready(call())
    return time.perf_counter() - t


#: JAX's monitoring events of a compilation (seconds, per jitted function).
EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "trace_s",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower_s",
    "/jax/core/compile/backend_compile_duration": "compile_s",
}


def _listen_to_compilations() -> dict:
    """``{(kind, function): seconds}`` of every trace, lowering and XLA compilation from now on
    (a compilation loaded from the persistent cache counts under ``compile_s``)."""
    import jax

    seen: dict = {}

    def listener(event, duration, **kwargs):
        if event in EVENTS:
            key = (EVENTS[event], kwargs.get("fun_name", "?"))
            seen[key] = seen.get(key, 0.0) + duration

    jax.monitoring.register_event_duration_secs_listener(listener)
    return seen


def _summarise(programs: dict) -> dict:
    """Totals per kind, the number of programs compiled and the three longest compilations."""
    row = {kind: 0.0 for kind in EVENTS.values()}
    for (kind, _), seconds in programs.items():
        row[kind] += seconds
    compiles = sorted(
        ((s, name) for (kind, name), s in programs.items() if kind == "compile_s"), reverse=True
    )
    row["programs"] = len(compiles)
    row["longest"] = [f"{name} {s:.2f} s" for s, name in compiles[:3]]
    return row


# ------------------------------------------------------------------------------ parent side
def _run_child(args: list[str], env: dict) -> dict:
    out = subprocess.run(
        [sys.executable, os.path.abspath(__file__), *args],
        env=env,
        capture_output=True,
        text=True,
    )
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1] if out.stderr.strip() else "?"}
    return json.loads(out.stdout.strip().splitlines()[-1])


def _help_seconds() -> float:
    times = []
    for _ in range(5):
        t = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "pacjax.cli.main", "--help"], capture_output=True, check=True
        )
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def _measure(robots, entries, modes, repeat: int) -> list[dict]:
    env = {**os.environ, "PACJAX_CACHE_DIR": "off"}
    rows = []
    with tempfile.TemporaryDirectory(prefix="pacjax-first-run-") as work:
        for robot in robots:
            if {"identify", "inverse"} & set(entries):
                result = _run_child(["--make-data", robot, work], env)
                if "error" in result:
                    raise SystemExit(f"{robot}: making the data failed: {result['error']}")
            for entry in entries:
                for r in range(repeat):
                    cache = os.path.join(work, f"cache-{robot}-{entry}-{r}")
                    for mode in modes:
                        if mode == "cold":
                            shutil.rmtree(cache, ignore_errors=True)
                        args = ["--child", entry, robot, work]
                        args += ["--cache", cache] if mode != "off" else []
                        row = {"robot": robot, "entry": entry, "mode": mode, "repeat": r}
                        row.update(_run_child(args, env))
                        rows.append(row)
                        print(_format_row(row), flush=True)
    return rows


def _format_row(row: dict) -> str:
    head = f"{row['robot']:<8} {row['entry']:<9} {row['mode']:<5}"
    if "error" in row:
        return f"{head} FAILED: {row['error']}"
    return (
        f"{head} import {row['import_s']:5.2f} s  first call {row['first_s']:6.2f} s "
        f"(trace {row['trace_s']:5.2f}, lower {row['lower_s']:5.2f}, XLA {row['compile_s']:5.2f}"
        f" s, {row['programs']} programs)  warm call {row['warm_s']:6.3f} s"
        f"\n    longest: {'; '.join(row['longest'])}"
    )


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        entry, robot, data_dir = sys.argv[2:5]
        cache = sys.argv[6] if len(sys.argv) > 6 else None
        print(json.dumps(_child(entry, robot, data_dir, cache)))
        return
    if len(sys.argv) > 1 and sys.argv[1] == "--make-data":
        _make_data(sys.argv[2], sys.argv[3])
        print("{}")
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default=",".join(ROBOTS))
    parser.add_argument("--entries", default=",".join(ENTRIES))
    parser.add_argument("--modes", default=",".join(MODES))
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--json", help="Write the records here.")
    args = parser.parse_args()
    robots, entries, modes = (a.split(",") for a in (args.robots, args.entries, args.modes))
    for name, given, known in (("robot", robots, ROBOTS), ("entry", entries, ENTRIES)):
        for value in given:
            if value not in known:
                parser.error(f"unknown {name} {value!r}; choose from {', '.join(known)}")
    for mode in modes:
        if mode not in MODES:
            parser.error(f"unknown mode {mode!r}; choose from {', '.join(MODES)}")

    help_s = _help_seconds()
    print(f"pacjax --help: {help_s:.2f} s (median of 5)", flush=True)
    rows = _measure(robots, entries, modes, args.repeat)
    if args.json:
        record = {
            "date": time.strftime("%Y-%m-%d"),
            "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
            "help_s": help_s,
            "rows": rows,
        }
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(record, f, indent=1)


if __name__ == "__main__":
    main()
