"""The deep profile of the scene-space campaign (issue 28): many structures from the space a user
can write (``tests/scene_space.py``: 1-24 segments, every strain model and per-segment mixes,
0-20 point masses, forces and moments at arbitrary sites, tendons with 2-40 rings or channels,
anchors anywhere, length and tension mode, gravity and base in any direction, float32 and
float64), many value draws on each, every property checked on each draw. Every draw is solved
singly and as a batch; the tip's gradient through the equilibrium, ``find_equilibria`` and 10 ms
of ``simulate`` run on a structure's first draw and then every ``--every``-th, since after their
compilations they are what a draw's time goes to on large structures.

Each structure costs its compilations (seconds to minutes on 2 cores); its draws reuse them, so
programs are compiled at LLVM's optimisation level 0 (the campaign checks properties, not
speed; ``XLA_FLAGS`` setting a level stands). Every draw is recorded (structure, result code,
any broken property, a crash's message and where it was raised, and the drawn values of any
draw that did not end in a successful single solve) in
``benchmarks/results/campaign.json``, rewritten after every draw so that an interrupted run keeps
what it did; ``--resume`` continues one at its next structure (``runs`` says from which
structure each commit drew), and ``--minutes`` stops a run after its last structure that started
within that time.

Each structure runs in a child process. A draw that gives no result within ``--draw-seconds``
(``--first-draw-seconds`` for a structure's first, which compiles every program) is recorded as
a ``hang``, with the operation it was in and the values it drew, and the child is killed; a
child that dies (an abort inside XLA, a segmentation fault, memory) is recorded as a ``crash``
with its exit status. Either way the campaign goes on with the next structure.

    python benchmarks/campaign.py --structures 200 --draws 50 [--seed 0] [--every K]
        [--structure-seconds T] [--shard i/n] [--resume] [--minutes M]
        [--first-draw-seconds S] [--draw-seconds S]

A structure's warm single and batch solves take tens of milliseconds where its compilations take
minutes, so a campaign of many scenes draws many values on each structure, up to ``--draws``
within ``--structure-seconds``. ``--shard i/n`` splits one plan over n processes (one per core,
each with its own ``--out``): structure ``k`` runs in shard ``k % n``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os

if "--xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = " ".join(
        filter(None, [os.environ.get("XLA_FLAGS"), "--xla_backend_optimization_level=0"])
    )
import queue
import subprocess
import sys
import threading
import time
import traceback
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from scene_space import (  # noqa: E402
    PropertyFailure,
    build,
    check,
    draw_structure,
    is_validation_error,
    values,
)

OUT = ROOT / "benchmarks" / "results" / "campaign.json"
#: Beyond the single and batch solves (one compilation each per structure), on the draws that
#: ``--every`` picks.
OPERATIONS = ("gradient", "find_equilibria", "simulate")
#: A child's line that carries a draw's record.
_RECORD = "CAMPAIGN-RECORD "
#: A child's line that names the operation a draw starts.
_OPERATION = "CAMPAIGN-OPERATION "
#: A child's line with a draw's values, before its operations: a hang or crash record keeps them.
_VALUES = "CAMPAIGN-VALUES "


@dataclasses.dataclass(frozen=True)
class Plan:
    """A campaign: ``structures`` drawn from ``seed``; on each, up to ``draws`` value draws,
    none started after ``structure_seconds`` (its compilations included; the first draw always
    runs), ``OPERATIONS`` on the first and then every ``every``-th; this process runs the
    structures ``k`` with ``k % shards == shard``."""

    structures: int
    draws: int
    seed: int
    every: int = 1
    structure_seconds: float | None = None
    shard: int = 0
    shards: int = 1


def run_structure(
    structure,
    k: int,
    plan: Plan,
    on_draw=lambda record: None,
    on_operation=lambda name: None,
    on_values=lambda values: None,
) -> list[dict]:
    """The value draws of structure ``k``; one record per draw, each also passed to
    ``on_draw`` as soon as it is made (each draw's values to ``on_values`` before it runs, and
    each operation's name to ``on_operation`` as it starts). The single and batch solves run on
    every draw."""
    records = []
    t_start = time.perf_counter()

    @settings(
        max_examples=plan.draws,
        deadline=None,
        database=None,
        derandomize=False,
        suppress_health_check=list(HealthCheck),
    )
    @given(data=st.data())
    def one(data):
        # Drawn even when the structure's time is up: hypothesis replays an example's draws
        # and calls a test whose draws change between runs flaky.
        drawn = data.draw(values(structure))
        budget = plan.structure_seconds
        if records and budget is not None and time.perf_counter() - t_start > budget:
            return  # hypothesis still counts the example; it costs nothing more
        record = {"structure": structure.describe()}
        on_values(drawn)
        t0 = time.perf_counter()
        try:
            scene, controls = build(structure, drawn)
            further = OPERATIONS if len(records) % plan.every == 0 else ()
            found = check(scene, controls, structure.dtype, further, on_operation)
            record.update(outcome="ok", operations=["single", "batch", *further], **found)
        except PropertyFailure as err:
            record.update(outcome="property", error=str(err))
        except Exception as err:  # noqa: BLE001 -- a crash is what the campaign looks for
            if is_validation_error(err):
                record.update(outcome="rejected", error=str(err))
            else:
                record_crash(record, err)
        record["seconds"] = time.perf_counter() - t0
        if record["outcome"] != "ok" or record.get("single") != "successful":
            record["values"] = drawn  # to rebuild the scene: build(structure, values)
        records.append(record)
        on_draw(record)

    np.random.seed(plan.seed + k)  # hypothesis seeds from its own generator; keep numpy's too
    one()
    return records


def record_crash(record: dict, err: BaseException) -> None:
    """Records ``err`` as a crash: its message's first line and where it was raised."""
    lines = str(err).strip().splitlines() or [""]
    where = traceback.extract_tb(err.__traceback__)[-1] if err.__traceback__ else None
    at = f" (at {where.filename}:{where.lineno})" if where else ""
    record.update(outcome="crash", error=f"{type(err).__name__}: {lines[0]}{at}")


def structures_of(n_structures: int, seed: int) -> list:
    """The campaign's structures (the same in the parent and in every child)."""
    rng = np.random.default_rng(seed)
    return [draw_structure(rng) for _ in range(n_structures)]


def run_child(k: int, describe: str, plan: Plan, limits: tuple[float, float], on_draw) -> None:
    """Structure ``k`` of the campaign ``plan`` in a child process, each draw's record passed to
    ``on_draw`` as it comes; a ``hang`` record (naming the operation it was in) where the child
    gives none within ``limits`` (seconds for the first draw, with every compilation, and for
    each later one), a ``crash`` record where it dies."""
    command = [sys.executable, __file__, "--child", str(k), "--plan"]
    command.append(json.dumps(dataclasses.asdict(plan)))
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
    lines: queue.Queue = queue.Queue()

    def read():
        for line in proc.stdout:
            lines.put(line)
        lines.put(None)

    threading.Thread(target=read, daemon=True).start()
    given, operation, values = 0, "starting", None
    limit = limits[0]
    deadline = time.perf_counter() + limit
    while True:
        try:
            line = lines.get(timeout=max(deadline - time.perf_counter(), 0.0))
        except queue.Empty:
            proc.kill()
            proc.wait()
            what = f"draw {given}: no result in {limit:g} s, in {operation}"
            on_draw(_failed(describe, "hang", what, values))
            return
        if line is None:
            break
        if line.startswith(_OPERATION):
            operation = line[len(_OPERATION) :].strip()
        elif line.startswith(_VALUES):
            values = json.loads(line[len(_VALUES) :])
        elif line.startswith(_RECORD):
            given += 1
            on_draw(json.loads(line[len(_RECORD) :]))
            limit = limits[1]
            deadline = time.perf_counter() + limit
    status = proc.wait()
    if status != 0:
        what = f"draw {given}: the process ended with status {status}"
        on_draw(_failed(describe, "crash", what, values))


def _failed(describe: str, outcome: str, error: str, values=None) -> dict:
    """The record of a draw that gave no result, with its values where the child sent them (to
    rebuild the scene: ``build(structure, values)``)."""
    record = {"structure": describe, "outcome": outcome, "error": error, "seconds": None}
    if values is not None:
        record["values"] = values
    return record


def child(k: int, plan: Plan) -> None:
    """Runs structure ``k``; one ``_RECORD`` line per draw on stdout."""
    warnings.simplefilter("ignore")
    structure = structures_of(plan.structures, plan.seed)[k]

    def emit(record):
        print(_RECORD + json.dumps(record), flush=True)

    def started(name):
        print(_OPERATION + name, flush=True)

    def drawn(values):
        print(_VALUES + json.dumps(values), flush=True)

    run_structure(structure, k, plan, emit, started, drawn)


def main(
    plan: Plan,
    resume: bool,
    minutes: float | None,
    limits: tuple[float, float] = (3600.0, 900.0),
    out: Path = OUT,
) -> dict:
    done = json.loads(out.read_text()) if resume and out.exists() else None
    records = done["records"] if done else []
    start = done["structures_done"] if done else 0
    records = [r for r in records if r.get("structure_index", 0) < start]
    structures = structures_of(plan.structures, plan.seed)
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT
    ).stdout.strip()
    t0 = time.perf_counter()
    previous_wall = (done or {}).get("wall_s", 0.0)
    # Which commit drew which structures: a resumed record holds the draws of several.
    runs = (done or {}).get("runs", []) + [
        {"commit": commit, "date": time.strftime("%Y-%m-%d"), "from_structure": start}
    ]

    def save(structures_done: int) -> dict:
        result = {
            "commit": commit,
            "date": time.strftime("%Y-%m-%d"),
            "runs": runs,
            "plan": dataclasses.asdict(plan),
            "structures_done": structures_done,
            "draws": len(records),
            "tally": dict(Counter(r["outcome"] for r in records)),
            "results": dict(Counter(r.get("single", "-") for r in records)),
            "draw_seconds_limits": list(limits),
            "wall_s": previous_wall + time.perf_counter() - t0,
            "records": records,
        }
        out.write_text(json.dumps(result, indent=1) + "\n")
        return result

    result = save(start)
    for k in range(start, plan.structures):
        if k % plan.shards != plan.shard:
            continue
        if minutes is not None and time.perf_counter() - t0 > 60 * minutes:
            break

        def on_draw(record, k=k):
            record["structure_index"] = k
            records.append(record)
            save(k)

        run_child(k, structures[k].describe(), plan, limits, on_draw)
        result = save(k + 1)
        print(
            f"{k + 1}/{plan.structures} {structures[k].describe()}: {result['tally']}", flush=True
        )
    return result


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--structures", type=int, default=200)
    parser.add_argument("--draws", type=int, default=50, help="value draws per structure, at most")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--every",
        type=int,
        default=1,
        help="the gradient, find_equilibria and simulate on the first draw and every k-th",
    )
    parser.add_argument(
        "--structure-seconds",
        type=float,
        help="start no draw of a structure after this time (compilations included)",
    )
    parser.add_argument("--shard", default="0/1", help="i/n: run the structures k with k %% n == i")
    parser.add_argument("--resume", action="store_true")
    parser.add_argument("--minutes", type=float, help="start no structure after this time")
    parser.add_argument(
        "--first-draw-seconds",
        type=float,
        default=3600.0,
        help="a structure's first draw (with its compilations) that takes longer is a hang",
    )
    parser.add_argument(
        "--draw-seconds",
        type=float,
        default=900.0,
        help="a later draw that takes longer is a hang",
    )
    parser.add_argument("--out", type=Path, default=OUT, help="the record (JSON)")
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--plan", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child is not None:
        child(args.child, Plan(**json.loads(args.plan)))
    else:
        shard, shards = (int(x) for x in args.shard.split("/"))
        if not 0 <= shard < shards:
            parser.error(f"--shard must be i/n with 0 <= i < n, got {args.shard}")
        plan = Plan(
            args.structures,
            args.draws,
            args.seed,
            args.every,
            args.structure_seconds,
            shard,
            shards,
        )
        limits = (args.first_draw_seconds, args.draw_seconds)
        main(plan, args.resume, args.minutes, limits, args.out)
