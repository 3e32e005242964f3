"""``pacjax simulate``, ``pacjax batch`` and ``pacjax bench``: long runs (see
:mod:`pacjax.cli.main`)."""

from __future__ import annotations

import json
import os
import sys
import time

import click
import numpy as np

import pacjax as pj

from .common import (
    file_error,
    force_option,
    load_with_controls,
    output_paths,
    parse_numbers,
    progress,
    timed_solve,
    write_json,
)


# ------------------------------------------------------------------------------ simulate
@click.command()
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
@click.option(
    "--rtol",
    type=click.FloatRange(min=0, min_open=True),
    help="Relative tolerance of the adaptive steps (absolute: 1 % of it, in SI units); default "
    "pj.simulate's. Below 1e-5 the reference solver (Kvaerno5), many times slower.",
)
@click.option("--fps", default=20, show_default=True, type=click.IntRange(min=1))
@click.option(
    "--out",
    default=".",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Directory for <file>_sim.gif, <file>_tip.png and <file>_sim.json (<file>: the scene "
    "file's name).",
)
@force_option
def simulate(
    scene_file: str,
    controls: str | None,
    duration: float,
    start: str,
    damping_ratio: float,
    rtol: float | None,
    fps: int,
    out: str,
    force: bool,
):
    """Simulate the dynamics of a TOML scene file after a step in commands."""
    import jax

    from ..plots import animation

    scene, u, extra = load_with_controls(scene_file, controls)
    rtol, atol = (pj.dynamics.RTOL, pj.dynamics.ATOL) if rtol is None else (rtol, 1e-2 * rtol)
    suffixes = {"json": "_sim.json", "png": "_tip.png", "gif": "_sim.gif"}
    paths = output_paths(out, scene_file, suffixes, force)
    name = extra["name"]
    q0 = None
    if start == "equilibrium":
        eq, _ = timed_solve(scene, np.zeros(scene.n_tendons), **extra["solver"])
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
            dense=True,  # the tip plot's curve, at any --fps
            rtol=rtol,
            atol=atol,
        )
        jax.block_until_ready(trajectory)
        seconds = time.perf_counter() - begin
    except ValueError as err:
        raise file_error(scene_file, err) from None
    ok = bool(trajectory.successful)
    tips = animation.tip_positions(scene, trajectory)
    result = {
        "scene": os.path.abspath(scene_file),
        "name": name,
        "model": type(scene.model).__name__,
        "controls": [float(v) for v in u],
        "start": start,
        "damping_ratio": damping_ratio,
        "rtol": rtol,
        "atol": atol,
        "success": ok,
        "steps": int(trajectory.num_steps),
        "wall_time_s": seconds,
        "t": [float(v) for v in np.asarray(trajectory.ts)],
        "q": np.asarray(trajectory.q).tolist(),
        "tip_position": tips.tolist(),
        "units": "SI: s, m, rad; wall time includes compilation",
    }
    json_path = paths["json"]
    write_json(json_path, result)
    status = "reached the end" if ok else "FAILED before the end (step limit or solver failure)"
    click.echo(
        f"{name}: {duration:g} s simulated, {status}, {result['steps']} steps, "
        f"{seconds:.1f} s wall (compilation included)"
    )
    t = 1e3 * tips[-1]
    click.echo(f"final tip position: x {t[0]:.1f} mm, y {t[1]:.1f} mm, z {t[2]:.1f} mm")
    click.echo(f"wrote {json_path}")
    title = f"{name}: " + (extra["description"] or os.path.basename(scene_file))
    png_path = paths["png"]
    animation.plot_tip_trajectory(
        scene, trajectory, png_path, title=title, equilibrium=_settled(scene, u, extra)
    )
    click.echo(f"wrote {png_path}")
    if ok:
        gif_path = paths["gif"]
        animation.animate_trajectory(scene, trajectory, gif_path, fps=fps, title=name)
        click.echo(f"wrote {gif_path}")
    else:
        sys.exit(3)


def _settled(scene, u, extra):
    """The static equilibrium under the simulated commands (where a damped motion ends), for
    the tip plot; None when it does not converge."""
    try:
        eq, _ = timed_solve(scene, u, **extra["solver"])
    except ValueError:
        return None
    return eq if bool(eq.converged) else None


# ------------------------------------------------------------------------------ batch
def _per_tendon(text: str | None, option: str):
    """``--low``/``--high``: one number, or comma-separated numbers (one per tendon)."""
    if text is None:
        return None
    values = parse_numbers(text, option)
    if not values:
        raise click.ClickException(f"{option} is empty")
    return values[0] if len(values) == 1 else values


@click.command()
@click.argument("scene_file", required=False, type=click.Path(exists=True, dir_okay=False))
@click.option("--n", "n", type=click.IntRange(min=1), help="Number of commands.")
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
    "pacjax.cli.batchrun.default_ranges).",
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
    help="Directory for <file>_batch.h5, <file>_batch.json and <file>_workspace.png (<file>: the "
    "scene file's name).",
)
@click.option("--no-plot", is_flag=True, help="Skip the workspace figure.")
@force_option
@click.option(
    "--resume",
    type=click.Path(exists=True, dir_okay=False),
    help="Continue the interrupted run that wrote this HDF5 file, with the settings stored in it "
    "(the rows it holds are kept, the others solved).",
)
def batch(
    scene_file,
    n,
    sampler,
    seed,
    low,
    high,
    chunk_size,
    tol,
    use_float32,
    out,
    no_plot,
    force,
    resume,
):
    """Sample N tendon commands of a TOML scene, solve them chunk by chunk and write the
    equilibria (commands, q, markers, tip pose, converged, stable, residual, steps) to an HDF5
    file as they are solved, with a workspace plot and a JSON summary. An interrupted run
    continues with `pacjax batch --resume FILE.h5`."""
    import jax.numpy as jnp

    from . import batchrun

    if resume is None:
        if scene_file is None or n is None:
            raise click.UsageError("give SCENE_FILE and --n (or --resume FILE.h5)")
        scene, extra, lo, hi, commands, options = _batch_inputs(
            scene_file, n, sampler, seed, low, high, tol, use_float32
        )
        suffixes = {"h5": "_batch.h5", "json": "_batch.json"}
        paths = output_paths(
            out, scene_file, suffixes | ({} if no_plot else {"png": "_workspace.png"}), force
        )
        attrs = _batch_attrs(scene_file, sampler, seed, lo, hi, use_float32, options)
        attrs |= {"n": n, "chunk_size": chunk_size}
    else:
        scene, extra, commands, options, attrs = _resumed_inputs(resume, scene_file)
        sampler, use_float32 = attrs["sampler"], attrs["dtype"] == "float32"
        lo, hi = np.asarray(attrs["low"]), np.asarray(attrs["high"])
        chunk_size = int(attrs["chunk_size"])
        stem = resume[: -len("_batch.h5")] if resume.endswith("_batch.h5") else resume[:-3]
        paths = {"h5": resume, "json": f"{stem}_batch.json"}
        if not no_plot:
            paths["png"] = f"{stem}_workspace.png"
    if use_float32:
        scene = pj.astype(scene, jnp.float32)
    name = extra["name"]
    if len(commands) != attrs["n"] and resume is None:
        click.echo(
            f"grid: {round(len(commands) ** (1 / scene.n_tendons))} values per tendon, "
            f"{len(commands)} rows"
        )
    bar = progress(len(commands), "batch")
    with bar:
        summary = batchrun.run_batch(
            scene,
            commands,
            paths["h5"],
            chunk_size=chunk_size,
            attrs=attrs,
            on_rows=bar.update,
            resume=resume is not None,
            **options,
        )
    report = {
        "scene": os.path.abspath(scene_file) if scene_file else None,
        "name": name,
        "model": type(scene.model).__name__,
        **{
            k: _plain(v)
            for k, v in attrs.items()
            if k not in ("scene_toml", "low", "high", "rows_written")
        },
        "low": lo.tolist(),
        "high": hi.tolist(),
        **summary.as_dict(),
        "file": os.path.abspath(paths["h5"]),
    }
    write_json(paths["json"], report, indent=2)
    click.echo(f"{name} ({report['model']}, {report['dtype']}, {sampler} sampling):")
    for line in summary.lines():
        click.echo("  " + line)
    if not no_plot:
        paths["png"] = batchrun.plot_workspace(paths["h5"], paths["png"], title=name)
    for path in paths.values():
        click.echo(f"wrote {path}")


def _plain(value):
    """A JSON value of an HDF5 attribute (numpy scalars and arrays as Python ones)."""
    return value.tolist() if isinstance(value, np.ndarray | np.generic) else value


#: The options that choose a batch's commands, solver and files: a resumed run takes them from
#: its file (its outputs go beside it).
_RUN_SETTINGS = ("n", "sampler", "seed", "low", "high", "chunk_size", "tol", "use_float32", "out")


def _resumed_inputs(path: str, scene_file: str | None):
    """``(scene, extra, commands, solver options, attrs)`` of the run that wrote the batch file
    ``path``, rebuilt from the settings stored in it (the scene file's text, the sampler and its
    seed, the ranges, the precision and tolerance); one-line errors for a file that cannot be
    resumed or options that would change the run."""
    import h5py

    from ..io.scenefile import scene_from_toml
    from . import batchrun

    context = click.get_current_context()
    given = [
        "--" + name.replace("use_", "").replace("_", "-")
        for name in _RUN_SETTINGS
        if context.get_parameter_source(name) != click.core.ParameterSource.DEFAULT
    ]
    if given:
        raise click.UsageError(
            f"--resume continues the run with the settings stored in {path}: "
            f"drop {', '.join(given)}"
        )
    try:
        with h5py.File(path, "r") as f:
            attrs = dict(f.attrs)
    except OSError as err:
        raise click.ClickException(f"{path}: not a readable batch file ({err})") from None
    missing = [k for k in ("scene_toml", "n", "chunk_size", "rows_written") if k not in attrs]
    if missing:
        raise click.ClickException(
            f"{path}: cannot be resumed: no {', '.join(missing)} (written by another version, "
            "or not by pacjax batch)"
        )
    text = str(attrs["scene_toml"])
    if scene_file is not None:
        with open(scene_file, encoding="utf-8") as f:
            if f.read() != text:
                raise click.ClickException(
                    f"{scene_file} is not the scene {path} was solved for (leave it out to use "
                    "the file's copy)"
                )
    try:
        scene, _, extra = scene_from_toml(text, source=f"{path} (its scene)")
        commands = batchrun.sample_commands(
            str(attrs["sampler"]), int(attrs["n"]), attrs["low"], attrs["high"], int(attrs["seed"])
        )
    except (ValueError, TypeError) as err:
        raise click.ClickException(str(err)) from None
    options = dict(extra["solver"]) | {"tol": float(attrs["tol"])}
    return scene, extra, commands, options, attrs


def _batch_inputs(scene_file, n, sampler, seed, low, high, tol, use_float32):
    """``(scene, extra, lo, hi, commands, solver options)`` of ``pacjax batch``, every one checked
    before anything is compiled (a bad range or option fails at once, not after a compilation);
    errors are one-line :class:`click.ClickException` naming the file."""
    from ..io.scenefile import load_scene
    from . import batchrun

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
        raise file_error(scene_file, err) from None
    return scene, extra, lo, hi, commands, options


def _batch_attrs(scene_file, sampler, seed, lo, hi, use_float32, options) -> dict:
    """The HDF5 file's attributes: the scene file's text and how the commands were drawn and
    solved, so that the file alone says how to reproduce it."""
    with open(scene_file, encoding="utf-8") as f:
        scene_text = f.read()
    from .._statics.options import DEFAULT_TOL

    return {
        "scene_toml": scene_text,
        "sampler": sampler,
        "seed": seed,
        "low": lo,
        "high": hi,
        "dtype": "float32" if use_float32 else "float64",
        "tol": float(options.get("tol") or DEFAULT_TOL["float32" if use_float32 else "float64"]),
    }


# ------------------------------------------------------------------------------ bench
@click.command()
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
        from ..io.scenefile import load_scene

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
        save=lambda record: _write_bench(record, json_path, md_path),
    )
    try:
        record = benchmod.run(**options)
    except (ValueError, TypeError) as err:
        raise click.ClickException(str(err)) from None
    click.echo(benchmod.to_markdown(record))
    for path in (json_path, md_path):
        if path:
            click.echo(f"wrote {path}")


def _write_bench(record, json_path, md_path):
    """Write the benchmark record so far (after every measurement: a stopped run keeps it)."""
    from . import bench as benchmod

    if json_path:
        with open(json_path, "w", encoding="utf-8") as f:
            json.dump(record, f, indent=2)
            f.write("\n")
    if md_path:
        with open(md_path, "w", encoding="utf-8") as f:
            f.write(benchmod.to_markdown(record))
