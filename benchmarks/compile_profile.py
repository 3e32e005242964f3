"""Where the test suite's time goes: XLA compilation, tracing, or running.

A pytest plugin that records, per test, its wall time and JAX's compile events (backend
compiles, jaxpr traces, lowering to MLIR, persistent-cache hits), one JSON line per test in
``OUT.<worker>``; run as a script it sums them and lists the costliest tests and files::

    PYTHONPATH=benchmarks COMPILE_PROFILE_OUT=/tmp/prof PACJAX_CACHE_DIR=/tmp/empty-cache \\
        python -m pytest -q -p compile_profile
    python benchmarks/compile_profile.py /tmp/prof

A test with hundreds of compiles runs JAX operations one by one (each a small program);
wrapped in one ``jax.jit`` it compiles once. An empty cache directory gives CI's fresh clone.
"""

import collections
import glob
import json
import os
import sys
import time

COMPILE = "/jax/core/compile/backend_compile_duration"
TRACE = "/jax/core/compile/jaxpr_trace_duration"
LOWER = "/jax/core/compile/jaxpr_to_mlir_module_duration"
SAVED = "/jax/compilation_cache/compile_time_saved_sec"

_events = collections.Counter()
_rows = []


def _listener(event, duration, **kwargs):
    _events[event] += duration
    _events[event + "#n"] += 1


def pytest_configure(config):
    import jax

    jax.monitoring.register_event_duration_secs_listener(_listener)


def pytest_runtest_call(item):
    _events.clear()
    item.stash_start = time.perf_counter()


def pytest_runtest_teardown(item):
    start = getattr(item, "stash_start", None)
    if start is not None:
        _rows.append({"test": item.nodeid, "wall": time.perf_counter() - start, **_events})


def pytest_sessionfinish(session):
    out = os.environ.get("COMPILE_PROFILE_OUT", "compile_profile")
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    with open(f"{out}.{worker}", "w") as f:
        f.writelines(json.dumps(row) + "\n" for row in _rows)


def summary(prefix: str, top: int = 40) -> str:
    rows = [json.loads(line) for path in glob.glob(f"{prefix}.*") for line in open(path)]
    total = collections.Counter()
    files = collections.defaultdict(collections.Counter)
    for row in rows:
        for key in ("wall", COMPILE, TRACE, LOWER, SAVED):
            total[key] += row.get(key, 0.0)
            files[row["test"].split("::")[0]][key] += row.get(key, 0.0)
    lines = [
        f"{len(rows)} tests: {total['wall']:.0f} s in tests, {total[COMPILE]:.0f} s compiling, "
        f"{total[TRACE]:.0f} s tracing, {total[LOWER]:.0f} s lowering, {total[SAVED]:.0f} s "
        "saved by the cache",
        f"{'wall':>6} {'compile':>7} {'#':>4} {'trace':>6}  test",
    ]
    for row in sorted(rows, key=lambda r: -r["wall"])[:top]:
        lines.append(
            f"{row['wall']:6.1f} {row.get(COMPILE, 0):7.1f} {int(row.get(COMPILE + '#n', 0)):4d} "
            f"{row.get(TRACE, 0):6.1f}  {row['test']}"
        )
    lines.append(f"{'wall':>6} {'compile':>7} {'':>4} {'trace':>6}  file")
    for name, t in sorted(files.items(), key=lambda kv: -kv[1]["wall"])[:top]:
        lines.append(f"{t['wall']:6.1f} {t[COMPILE]:7.1f} {'':>4} {t[TRACE]:6.1f}  {name}")
    return "\n".join(lines)


if __name__ == "__main__":
    print(summary(sys.argv[1] if len(sys.argv) > 1 else "compile_profile"))
