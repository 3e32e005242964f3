"""The ``pacjax`` command line.

- ``pacjax demo [--out DIR]``: the paper's robot with a 200 g payload under a few tendon
  commands, PCC and PAC; prints a table (tip positions, PAC-PCC differences, convergence,
  timings) and writes ``demo.png``.
- ``pacjax solve SCENE.toml [--controls u1,u2,...] [--out DIR]``: solves a scene file (see
  :mod:`pacjax.io.scenefile`) and writes ``<file>.json`` and ``<file>.png``.
- ``pacjax inverse SCENE.toml TARGETS.csv [--out DIR]``: tendon commands that put the tip on
  each ``x,y,z`` row (m) of the CSV (a path, warm-started row to row, or ``--independent``);
  writes ``<file>_commands.csv`` and ``<file>_inverse.png``; exit status 3 when a target was
  not reached.
- ``pacjax batch SCENE.toml --n N [--sampler lhs|uniform|grid] [--out DIR]``: samples N commands,
  solves them chunk by chunk and writes ``<file>_batch.h5``, ``<file>_batch.json`` and
  ``<file>_workspace.png`` (see :mod:`pacjax.cli.batchrun`).
- ``pacjax bench [--batch 1,100] [--models PAC] [--dtypes float64,float32] [--json F] [--md F]``:
  equilibria per second of the paper's robot (see :mod:`pacjax.cli.bench`).

Output files are named after the input file (``runs/arm.toml`` writes ``arm.json``,
``arm_fit.json``, ...) in ``--out`` (default: the current directory); a command that would
replace a file stops before it computes anything, unless ``--force``.

Compiling a solver dominates a first run; JAX's persistent compilation cache (a folder per jaxlib
and processor under ``~/.cache/pacjax-jax``, or ``$PACJAX_CACHE_DIR``; ``PACJAX_CACHE_DIR=off``
disables it; see :mod:`pacjax._cache`) keeps compiled solvers between runs. The command line
imports JAX only when a command runs, so ``--help`` and usage errors answer at once.

User errors (missing or malformed files, wrong number of controls) print one line and exit with
status 1 (2 for usage errors), without a traceback; ``solve`` exits with status 3 when the
solver did not converge (after writing its results).
"""

from __future__ import annotations

import os
import sys

import click
import numpy as np

import pacjax as pj

from .. import _cache
from .common import (
    file_error,
    float_or_none,
    force_option,
    load_with_controls,
    output_dir,
    output_paths,
    progress,
    summary,
    timed_solve,
    write_json,
)
from .data import fit, inverse
from .runs import batch, bench, simulate

#: The demo's tendon commands: pull-ins (m) of the nine tendons, three per section at 90, 210
#: and 330 degrees around the cross-section (section 1 free, sections 2 and 3 in Bowden cables).
DEMO_COMMANDS = {
    "section 1 bend": (0.04, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    "S-shape": (0.0, 0.04, 0.0, 0.05, 0.0, 0.05, 0.0, 0.0, 0.0),
    "all contracted": (0.03,) * 9,
    "combined": (0.045, 0.01, 0.01, 0.0, 0.035, 0.0, 0.01, 0.01, 0.04),
}
DEMO_MODELS = ("PCC", "PAC")


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(pj.__version__, prog_name="pacjax")
def cli():
    """Statics of tendon-driven continuum robots: PCC, PAC and polynomial curvature."""
    _cache.enable_from_environment()


def main() -> None:
    """Console-script entry point."""
    cli(prog_name="pacjax")


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
    out = output_dir(out)
    rows, compile_s, groups = _solve_demo(tip_mass)
    tips = {(c, m): tip for c, m, tip, _, _ in rows}
    _echo_demo_table(rows, tips, compile_s, tip_mass)
    path = _plot_demo(groups, tips, out, tip_mass)
    click.echo(f"wrote {path}")


def _solve_demo(tip_mass: float):
    """Every demo command with every model, each solved twice (the second, already compiled,
    times the solve alone); returns the table's rows ``(command, model, tip, eq, warm s)``, each
    model's compile time and ``{command: {model: (scene, q, controls)}}`` for the figure."""
    rows = []
    compile_s = {}
    groups: dict[str, dict] = {name: {} for name in DEMO_COMMANDS}
    bar = progress(2 * len(DEMO_COMMANDS) * len(DEMO_MODELS), "demo", unit="solve")
    with bar:
        for model_name in DEMO_MODELS:
            scene = pj.presets.stella2023(getattr(pj, model_name)(), tip_mass=tip_mass)
            for i, (command, controls) in enumerate(DEMO_COMMANDS.items()):
                bar.set_postfix_str(
                    f"{model_name}: {'compiling' if i == 0 else command}", refresh=True
                )
                eq, first = timed_solve(scene, np.asarray(controls))
                bar.update()
                _, warm = timed_solve(scene, np.asarray(controls))  # same work, compiled
                bar.update()
                if i == 0:
                    compile_s[model_name] = max(first - warm, 0.0)
                (tip, _), _, _ = summary(scene, eq.q, np.asarray(controls))
                rows.append((command, model_name, np.asarray(tip), eq, warm))
                groups[command][model_name] = (scene, eq.q, np.asarray(controls))
    return rows, compile_s, groups


def _echo_demo_table(rows, tips: dict, compile_s: dict, tip_mass: float) -> None:
    """The demo's table (tips, PAC-PCC differences, convergence, timings) and the commands."""
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


def _plot_demo(groups: dict, tips: dict, out: str, tip_mass: float) -> str:
    """``demo.png``: one column per command, PCC and PAC overlaid; returns its path."""
    from ..plots import equilibria as plots

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
    return path


# ------------------------------------------------------------------------------ solve


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
    help="Directory for <file>.json and <file>.png (<file>: the scene file's name).",
)
@click.option("--no-plot", is_flag=True, help="Skip the figure.")
@force_option
def solve(scene_file: str, controls: str | None, out: str, no_plot: bool, force: bool):
    """Solve the equilibrium of a TOML scene file."""
    scene, u, extra = load_with_controls(scene_file, controls)
    suffixes = {"json": ".json"} | ({} if no_plot else {"png": ".png"})
    paths = output_paths(out, scene_file, suffixes, force)
    name = extra["name"]
    try:
        eq, seconds = timed_solve(scene, u, **extra["solver"])
    except ValueError as err:
        raise file_error(scene_file, err) from None

    result, tip = _solve_result(scene_file, name, scene, u, eq, seconds)
    json_path = paths["json"]
    write_json(json_path, result, indent=2)
    _echo_solve(name, eq, result, seconds, tip)
    click.echo(f"wrote {json_path}")
    if not no_plot:
        from ..plots import equilibria as plots

        png_path = paths["png"]
        label = f"{result['model']} ({'converged' if result['converged'] else 'not converged'})"
        plots.plot_equilibria(
            scene,
            {label: eq.q},
            png_path,
            title=f"{name}: " + (extra["description"] or os.path.basename(scene_file)),
            controls=u,
        )
        click.echo(f"wrote {png_path}")
    if not result["converged"]:
        sys.exit(3)


def _solve_result(scene_file: str, name: str, scene, u, eq, seconds: float):
    """``(record, tip position)`` of one solve: the record is ``<file>.json``'s content; the tip
    is returned as computed (the scene's dtype) for the printed summary."""
    (tip, rotation), marker_positions, tensions = summary(scene, eq.q, u)
    result = {
        "scene": os.path.abspath(scene_file),
        "name": name,
        "model": type(scene.model).__name__,
        "controls": [float(v) for v in u],
        "q": [float(v) for v in np.asarray(eq.q)],
        "coordinate_names": list(scene.coordinate_names()),
        "converged": bool(eq.converged),
        "residual_norm": float_or_none(eq.residual_norm),
        "stable": bool(eq.stable),
        "min_hessian_eigenvalue": float_or_none(eq.min_hessian_eigenvalue),
        "steps": int(eq.steps),
        "reason": eq.reason,
        "energy": float_or_none(eq.energy),
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
    return result, tip


def _echo_solve(name: str, eq, result: dict, seconds: float, tip) -> None:
    """The solve's status, tip position (mm) and tendon tensions, one line each."""
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


for _command in (fit, inverse, simulate, batch, bench):
    cli.add_command(_command)


if __name__ == "__main__":
    main()
