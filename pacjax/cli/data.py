"""``pacjax fit`` and ``pacjax inverse``: measured or wanted poses in (see
:mod:`pacjax.cli.main`)."""

from __future__ import annotations

import os
import sys
import time

import click
import numpy as np

import pacjax as pj

from .common import file_error, force_option, output_paths, solver_options


# ------------------------------------------------------------------------------ fit
def _names(text: str) -> tuple[str, ...]:
    return tuple(x.strip() for x in text.split(",") if x.strip())


@click.command()
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
    help="Fraction of frames held out for validation (0: none; default: the CSV's holdout "
    "column where it has one, else 0.2).",
)
@click.option(
    "--holdout-frames",
    default="",
    help="Comma-separated 0-based frame numbers to hold out (instead of --holdout).",
)
@click.option(
    "--stages",
    default="",
    help="Parameter groups fitted in turn, ';' between stages, e.g. "
    "'bending_stiffness;bending_stiffness,linear_density' (instead of --params).",
)
@click.option(
    "--starts",
    default=1,
    show_default=True,
    type=click.IntRange(min=1),
    help="Fits from this many starting points (the scene's values, then random factors "
    "x1/4..x4); the best is kept.",
)
@click.option(
    "--branch-starts",
    default=8,
    show_default=True,
    type=click.IntRange(min=0),
    help="Scattered starts that check each frame is on the equilibrium branch that fits it "
    "best (0: no checks).",
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
@force_option
def fit(
    scene_file,
    data_file,
    params,
    per_segment,
    holdout,
    holdout_frames,
    stages,
    starts,
    branch_starts,
    loss,
    noise,
    max_iterations,
    seed,
    out,
    no_plot,
    force: bool,
):
    """Fit a scene's parameters to static motion-capture frames (pacjax mocap CSV).

    Writes <file>_fitted.toml, <file>_fit.json, <file>_fit.md and, unless --no-plot, the loss
    curve, predicted vs measured backbones and an error histogram (PNG); <file> is the scene
    file's name.
    """
    from ..io.mocapfile import load_mocap
    from ..io.scenefile import load_scene

    try:
        scene, controls, extra = load_scene(scene_file)
    except (ValueError, OSError) as err:
        raise click.ClickException(str(err)) from None
    if holdout_frames:
        try:
            holdout = [int(x) for x in _names(holdout_frames)]
        except ValueError:
            raise click.ClickException(
                f"--holdout-frames must be comma-separated frame numbers, got {holdout_frames!r}"
            ) from None
    _reject_motive_export(data_file)
    suffixes = {"scene": "_fitted.toml", "json": "_fit.json", "md": "_fit.md"}
    if not no_plot:
        suffixes |= {"loss": "_fit_loss.png", "backbones": "_fit_backbones.png"}
        suffixes |= {"errors": "_fit_errors.png"}
    paths = output_paths(out, scene_file, suffixes, force)
    source = click.get_current_context().get_parameter_source("holdout")
    try:
        data = load_mocap(data_file)
        if data.holdout is not None and not holdout_frames:
            if source == click.core.ParameterSource.DEFAULT:
                holdout = 0.0  # identify holds out the frames the column marks
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
            n_starts=starts,
            branch_starts=branch_starts,
            stages=[_names(stage) for stage in stages.split(";")] if stages else None,
            options=solver_options(extra),
        )
    except (ValueError, TypeError) as err:
        raise click.ClickException(str(err)) from None
    name = extra["name"]
    description = f"fitted to {os.path.basename(data_file)}" + (
        f"; {extra['description']}" if extra["description"] else ""
    )
    _write_fit(paths, name, fitted, report, controls, description, extra["solver"])
    _echo_fit(name, report)
    for path in paths.values():
        click.echo(f"wrote {path}")


def _reject_motive_export(data_file: str) -> None:
    """A Motive export is a time series without commands: say how to turn it into static frames,
    rather than fail on its columns."""
    with open(data_file, encoding="utf-8-sig") as f:
        if f.readline().startswith("Format Version"):
            raise click.ClickException(
                f"{data_file} is a Motive export: attach the robot's commands and pick static "
                "frames with pacjax.io.motive.motive_dataset, then save_mocap it"
            )


def _write_fit(paths: dict, name: str, fitted, report, controls, description, solver) -> None:
    """The fitted scene (with the input scene's controls, solver options and description),
    the report (JSON, Markdown) and the figures ``paths`` names."""
    from ..io.scenefile import save_scene

    save_scene(
        paths["scene"],
        fitted,
        controls if fitted.n_tendons else None,
        name=f"{name}_fitted",
        description=description,
        solver=solver or None,
    )
    report.to_json(paths["json"])
    with open(paths["md"], "w", encoding="utf-8") as f:
        f.write(report.to_markdown())
    if "loss" in paths:
        from ..plots import fit as fitplots

        fitplots.plot_loss(report, paths["loss"])
        fitplots.plot_backbones(fitted, report, paths["backbones"])
        fitplots.plot_error_histogram(report, paths["errors"])


def _echo_fit(name: str, report) -> None:
    """The fit's outcome, each fitted value (with its standard deviation where known) and the
    train / held-out RMSE."""
    click.echo(f"{name}: {report.message}; {report.iterations} iterations, {report.time_s:.1f} s")
    for pname, p in report.parameters.items():
        for label, value, std in zip(p["labels"], p["value"], p["std"], strict=True):
            sd = "" if std is None else f" +- {std:.3g}"
            click.echo(f"  {pname}{label} = {value:.6g}{sd} {p['unit']}")
    for label, errors in (("train", report.train), ("held-out", report.validation)):
        if errors is None:
            continue
        failed = int((~errors.converged).sum())
        note = f", {failed} not converged: not in the RMSE" if failed else ""
        click.echo(f"{label} RMSE {errors.rmse_mm:.3f} mm ({len(errors.q)} frames{note})")
    branches = report.branches
    if branches is not None and branches.switched.any():
        click.echo(
            f"frames {np.flatnonzero(branches.switched).tolist()} moved to the equilibrium "
            "branch that fits them better"
        )


# ------------------------------------------------------------------------------ inverse
#: Length units a targets file may be written in, and their size in metres.
UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}


def _read_targets(path: str, units: str = "m") -> np.ndarray:
    """Target tip positions (m) from a CSV file: one ``x,y,z`` row per target in ``units``, an
    optional ``x,y,z`` header line, ``#`` comments."""
    rows = []
    with open(path, encoding="utf-8") as f:
        lines = [ln.strip() for ln in f if ln.strip() and not ln.lstrip().startswith("#")]
    for i, line in enumerate(lines):
        cells = [c.strip() for c in line.split(",")]
        try:
            values = [float(c) for c in cells]
        except ValueError:
            if i == 0 and [c.lower() for c in cells] == ["x", "y", "z"]:
                continue
            what = "is a header other than x,y,z" if i == 0 else "is not numbers"
            raise click.ClickException(f"{path}: row {i + 1} {what}: {line!r}") from None
        if len(values) != 3:
            raise click.ClickException(
                f"{path}: row {i + 1} has {len(values)} value(s); expected x,y,z in {units}"
            )
        rows.append(values)
    if not rows:
        raise click.ClickException(f"{path}: no targets (expected rows of x,y,z in {units})")
    targets = np.asarray(rows) * UNITS[units]
    if not np.all(np.isfinite(targets)):
        raise click.ClickException(f"{path}: targets must be finite numbers")
    return targets


#: A target this many robot lengths from the base is a units mistake (millimetres read as
#: metres are 1,000 times too far), not merely out of reach.
UNITS_SUSPECT_REACH = 10.0


def _check_reach(path: str, scene, targets: np.ndarray, units: str) -> None:
    """A target many times further from the base than the robot is long was written in other
    units: say so before anything is compiled (one just out of reach is solved, and reported
    as not reached)."""
    length = float(scene.robot.total_length)
    distance = np.linalg.norm(targets - np.asarray(scene.robot.base_position), axis=1)
    far = int(np.argmax(distance))
    if distance[far] > UNITS_SUSPECT_REACH * length:
        raise click.ClickException(
            f"{path}: row {far + 1}: the target is {distance[far]:.4g} m from the base; the robot "
            f"is {length:.4g} m long. Units? (read as {units}; --units mm|cm|m)"
        )


def _check_tension_limits(scene, upper, max_tension) -> None:
    """Tension-mode tendons have no natural upper command: the CLI asks for its own flags."""
    tension = [i for i, t in enumerate(scene.tendons) if t.mode == "tension"]
    if tension and upper is None and max_tension is None:
        raise click.ClickException(
            f"tendon(s) {tension} are in tension mode: give the largest tension with "
            "--max-tension N (or --upper for every command)"
        )


@click.command()
@click.argument("scene_file", type=click.Path(exists=True, dir_okay=False))
@click.argument("targets_file", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "--out",
    default=".",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Directory for <file>_commands.csv and <file>_inverse.png (<file>: the scene file's "
    "name).",
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
    "--max-tension",
    type=click.FloatRange(min=0, min_open=True),
    help="Tension limit, N (needed when a tendon is in tension mode).",
)
@click.option(
    "--units",
    type=click.Choice(sorted(UNITS)),
    default="m",
    show_default=True,
    help="Length unit of the targets file.",
)
@click.option("--no-plot", is_flag=True, help="Skip the figure.")
@force_option
def inverse(
    scene_file: str,
    targets_file: str,
    out: str,
    independent: bool,
    tol: float,
    upper: float | None,
    max_tension: float | None,
    units: str,
    no_plot: bool,
    force: bool,
):
    """Tendon commands that put the tip of a TOML scene on the targets of a CSV file (x,y,z per
    row, in metres unless --units). Exits with status 3 when a target was not reached."""
    from ..io.scenefile import load_scene

    try:
        scene, _, extra = load_scene(scene_file)
    except (ValueError, OSError) as err:
        raise click.ClickException(str(err)) from None
    targets = _read_targets(targets_file, units)
    _check_reach(targets_file, scene, targets, units)
    _check_tension_limits(scene, upper, max_tension)
    suffixes = {"csv": "_commands.csv"} | ({} if no_plot else {"png": "_inverse.png"})
    paths = output_paths(out, scene_file, suffixes, force)
    name = extra["name"]
    options = dict(reached_tol=tol, upper=upper, max_tension=max_tension)
    options["options"] = solver_options(extra)
    result, seconds = _solve_targets(scene_file, scene, targets, independent, options)

    reached = np.asarray(result.reached)
    csv_path = paths["csv"]
    _write_commands(csv_path, scene.n_tendons, targets, result)
    controls = np.asarray(result.controls)
    click.echo(
        f"{name}: {int(reached.sum())}/{len(targets)} targets reached within {1e3 * tol:g} mm, "
        f"largest error {1e3 * float(np.max(result.error)):.3g} mm, {seconds:.1f} s"
    )
    if len(controls) > 1:
        jumps = np.abs(np.diff(controls, axis=0)).max(axis=0)
        tension = np.asarray([t.mode == "tension" for t in scene.tendons])
        parts = [f"{1e3 * jumps[~tension].max():.2f} mm"] if (~tension).any() else []
        parts += [f"{jumps[tension].max():.3g} N"] if tension.any() else []
        click.echo(f"largest command change between neighbouring rows: {', '.join(parts)}")
    click.echo(f"wrote {csv_path}")
    if not no_plot:
        png_path = paths["png"]
        _plot_inverse(png_path, scene, name, targets, result)
        click.echo(f"wrote {png_path}")
    if not reached.all():
        sys.exit(3)


def _solve_targets(scene_file: str, scene, targets: np.ndarray, independent: bool, options):
    """``(result per target, seconds)``: every target from fresh starts, or the rows as a path
    (:func:`pacjax.track`, each warm-started from the previous one)."""
    import jax

    start = time.perf_counter()
    try:
        if independent:
            results = [pj.inverse_statics(scene, t, **options) for t in targets]
            result = jax.tree_util.tree_map(lambda *xs: np.stack(xs), *results)
        else:
            result = pj.track(scene, targets, **options).waypoints
    except ValueError as err:
        raise file_error(scene_file, err) from None
    return result, time.perf_counter() - start


def _write_commands(path: str, n_tendons: int, targets: np.ndarray, result) -> None:
    """``<file>_commands.csv``: per target, whether it was reached, the error, the tip, the
    commands, the tensions and the iterations."""
    controls = np.asarray(result.controls)
    reached = np.asarray(result.reached)
    header = (
        ["target_x", "target_y", "target_z", "reached", "error_m", "tip_x", "tip_y", "tip_z"]
        + [f"u{i}" for i in range(n_tendons)]
        + [f"tension{i}" for i in range(n_tendons)]
        + ["iterations"]
    )
    with open(path, "w", encoding="utf-8") as f:
        f.write("# pacjax inverse: commands u (m pull-in, or N tension), tensions N, lengths m\n")
        f.write(",".join(header) + "\n")
        for i in range(len(targets)):
            row = list(targets[i]) + [int(reached[i]), float(result.error[i])]
            row += list(np.asarray(result.position[i])) + list(controls[i])
            row += list(np.asarray(result.tensions[i])) + [int(result.iterations[i])]
            f.write(",".join(f"{v:.9g}" if isinstance(v, float) else str(v) for v in row) + "\n")


def _plot_inverse(path: str, scene, name: str, targets: np.ndarray, result) -> None:
    """``<file>_inverse.png``: up to six reached backbones, evenly spread over the rows, their
    tendons shaded by tension, with the targets and the reached tips."""
    from ..plots import equilibria as plots

    reached = np.asarray(result.reached)
    shown = np.unique(np.linspace(0, len(targets) - 1, min(len(targets), 6)).astype(int))
    controls = np.asarray(result.controls)
    cases = {f"target {i + 1}": (scene, np.asarray(result.q[i]), controls[i]) for i in shown}
    plots.plot_equilibria(
        scene,
        cases,
        path,
        title=f"{name}: reached backbones ({int(reached.sum())}/{len(targets)} reached)",
        markers=False,
        targets={"target": targets, "reached tip": np.asarray(result.position)},
    )
