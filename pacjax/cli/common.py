"""Helpers shared by the ``pacjax`` subcommands (see :mod:`pacjax.cli.main`)."""

from __future__ import annotations

import json
import math
import os
import sys
import time

import click
import numpy as np

import pacjax as pj

__all__ = [
    "float_or_none",
    "load_with_controls",
    "output_dir",
    "parse_controls",
    "parse_numbers",
    "progress",
    "summary",
    "timed_solve",
    "write_json",
]


def timed_solve(scene, controls, **options):
    import jax

    start = time.perf_counter()
    eq = pj.solve_equilibrium(scene, controls, **options)
    jax.block_until_ready(eq)
    return eq, time.perf_counter() - start


def solver_options(extra: dict) -> pj.SolverOptions:
    """The scene file's ``[solver]`` table as :class:`pacjax.SolverOptions` (its ``fallback``
    is an argument of the single and batched solves, not an option of the workflows)."""
    fields = {k: v for k, v in extra["solver"].items() if k != "fallback"}
    return pj.SolverOptions(**fields)


def summary(scene, q, controls):
    """Tip pose, marker positions and tendon tensions at ``q``, in one compiled call (op by
    op, these kinematics take seconds)."""
    tip = pj.tip_pose(scene, q)
    marker_positions = pj.markers(scene, q) if scene.markers else None
    tensions = pj.tendon_tensions(scene, q, controls) if scene.n_tendons else None
    return tip, marker_positions, tensions


#: Seconds between two progress lines where there is no terminal to draw a bar on.
LOG_INTERVAL = 10.0


class Progress:
    """Progress of a long command: a tqdm bar on a terminal; elsewhere (a log file, a pipe, a
    batch job) a line every ``interval`` seconds with the count, the rate and the time left, so
    that a log shows a run is alive. Counts in one ``unit`` throughout."""

    def __init__(self, total: int, desc: str, unit: str = "eq", interval=None, file=None):
        self.total, self.desc, self.unit = total, desc, unit
        self.interval = LOG_INTERVAL if interval is None else interval
        self.file = sys.stderr if file is None else file
        self.done = 0
        self.note = ""
        self.bar = None
        if self.file.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=desc, unit=unit, file=self.file, leave=False)
        self.start = self.last = time.monotonic()

    def update(self, n: int = 1) -> None:
        self.done += n
        if self.bar is not None:
            self.bar.update(n)
        elif time.monotonic() - self.last >= self.interval:
            self.log()

    def set_postfix_str(self, note: str, refresh: bool = True) -> None:
        """What is being done now (shown beside the bar, or in the next log line)."""
        self.note = note
        if self.bar is not None:
            self.bar.set_postfix_str(note, refresh=refresh)

    def log(self) -> None:
        """One line: ``DESC: DONE/TOTAL UNIT (PERCENT %), RATE UNIT/s, TIME left``."""
        now = time.monotonic()
        self.last = now
        elapsed = now - self.start
        line = f"{self.desc}: {self.done}/{self.total} {self.unit}"
        if self.done and elapsed > 0:
            rate = self.done / elapsed
            left = (self.total - self.done) / rate
            line += (
                f" ({100 * self.done / self.total:.0f} %), {rate:.1f} {self.unit}/s, "
                f"{_duration(left)} left"
            )
        if self.note:
            line += f" [{self.note}]"
        print(line, file=self.file, flush=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.close()


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def progress(total: int, desc: str, unit: str = "eq") -> Progress:
    """A :class:`Progress` on stderr."""
    return Progress(total, desc, unit)


def float_or_none(x) -> float | None:
    """A JSON-safe float (NaN and infinities become null)."""
    value = float(np.asarray(x))
    return value if math.isfinite(value) else None


def output_dir(out: str) -> str:
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as err:
        raise click.ClickException(f"cannot create output directory {out!r}: {err}") from None
    return out


#: ``--force``: the one way a command may replace files it wrote before.
force_option = click.option(
    "--force", is_flag=True, help="Overwrite output files that already exist."
)


def output_paths(out: str, input_file: str, suffixes: dict[str, str], force: bool) -> dict:
    """``{what: path}`` of a command's output files in ``out``, each named after the input
    file (``runs/arm.toml`` and ``"_fit.json"`` give ``OUT/arm_fit.json``), so that two inputs
    never write the same file. Checked before anything is computed: a file that exists already
    is a one-line error unless ``force``."""
    out = output_dir(out)
    stem = os.path.splitext(os.path.basename(input_file))[0]
    paths = {what: os.path.join(out, stem + suffix) for what, suffix in suffixes.items()}
    existing = [p for p in paths.values() if os.path.exists(p)]
    if existing and not force:
        more = f" (and {len(existing) - 1} more)" if len(existing) > 1 else ""
        raise click.ClickException(
            f"{existing[0]} exists{more}: --force overwrites, --out DIR writes elsewhere"
        )
    return paths


def parse_numbers(text: str, option: str) -> list[float]:
    """Comma-separated numbers of a command-line option; a one-line user error otherwise."""
    try:
        return [float(v) for v in text.replace(" ", "").split(",") if v != ""]
    except ValueError:
        raise click.ClickException(
            f"{option} must be comma-separated numbers, got {text!r}"
        ) from None


def parse_controls(text: str, n_tendons: int) -> np.ndarray:
    values = parse_numbers(text, "--controls")
    if len(values) != n_tendons:
        raise click.ClickException(
            f"--controls has {len(values)} value(s) but the scene has {n_tendons} tendon(s)"
        )
    return np.asarray(values)


def file_error(path: str, err: Exception) -> click.ClickException:
    """A one-line user error about ``path``: the file named once, whether or not the message
    already starts with it (scene-file errors do)."""
    message = str(err)
    return click.ClickException(message if message.startswith(f"{path}:") else f"{path}: {message}")


def load_with_controls(scene_file: str, controls: str | None):
    """``(scene, controls, extra)`` of a scene file: ``--controls`` if given, else the file's
    ``controls``, else zeros. A malformed file or ``--controls`` is a one-line user error."""
    from ..io.scenefile import load_scene

    try:
        scene, file_controls, extra = load_scene(scene_file)
    except (ValueError, OSError) as err:
        raise click.ClickException(str(err)) from None
    if controls is not None:
        u = parse_controls(controls, scene.n_tendons)
    elif file_controls is not None:
        u = file_controls
    else:
        u = np.zeros(scene.n_tendons)
    return scene, u, extra


def write_json(path: str, result: dict, indent: int | None = None) -> None:
    with open(path, "w", encoding="utf-8") as f:
        json.dump(result, f, indent=indent)
        f.write("\n")
