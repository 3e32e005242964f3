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
    fps: int,
    out: str,
    force: bool,
):
    """Simulate the dynamics of a TOML scene file after a step in commands."""
    import jax

    from ..plots import animation

    scene, u, extra = load_with_controls(scene_file, controls)
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
    animation.plot_tip_trajectory(scene, trajectory, png_path, title=title)
    click.echo(f"wrote {png_path}")
    if ok:
        gif_path = paths["gif"]
        animation.animate_trajectory(scene, trajectory, gif_path, fps=fps, title=name)
        click.echo(f"wrote {gif_path}")
    else:
        sys.exit(3)


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
@click.argument("scene_file", type=click.Path(exists=True, dir_okay=False))
@click.option("--n", "n", required=True, type=click.IntRange(min=1), help="Number of commands.")
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
def batch(
    scene_file, n, sampler, seed, low, high, chunk_size, tol, use_float32, out, no_plot, force
):
    """Sample N tendon commands of a TOML scene, solve them chunk by chunk and write the
    equilibria (commands, q, markers, tip pose, converged, stable, residual, steps) to an HDF5
    file as they are solved, with a workspace plot and a JSON summary."""
    import jax.numpy as jnp

    from . import batchrun

    scene, extra, lo, hi, commands, options = _batch_inputs(
        scene_file, n, sampler, seed, low, high, tol, use_float32
    )
    if use_float32:
        scene = pj.astype(scene, jnp.float32)
    suffixes = {"h5": "_batch.h5", "json": "_batch.json"}
    paths = output_paths(
        out, scene_file, suffixes | ({} if no_plot else {"png": "_workspace.png"}), force
    )
    name = extra["name"]
    attrs = _batch_attrs(scene_file, sampler, seed, lo, hi, use_float32, options)
    if len(commands) != n:
        click.echo(
            f"grid: {round(len(commands) ** (1 / scene.n_tendons))} values per tendon, "
            f"{len(commands)} rows"
        )
    bar = progress(len(commands), "batch")
    with bar:
        bar.unit = "eq"
        summary = batchrun.run_batch(
            scene,
            commands,
            paths["h5"],
            chunk_size=chunk_size,
            attrs=attrs,
            on_chunk=bar.update,
            **options,
        )
    report = {
        "scene": os.path.abspath(scene_file),
        "name": name,
        "model": type(scene.model).__name__,
        **{k: v for k, v in attrs.items() if k != "scene_toml"},
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
