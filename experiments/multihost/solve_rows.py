"""Multi-host batch: every process solves the rows it owns and writes its own part file.

Launch one process per host (the same command on each, only ``--process-id`` differs)::

    # host A (also the coordinator)
    python experiments/multihost/solve_rows.py experiments/scenes/stella2023.toml \
        --n 1000000 --coordinator hostA:12345 --num-processes 2 --process-id 0 --out parts
    # host B
    python experiments/multihost/solve_rows.py experiments/scenes/stella2023.toml \
        --n 1000000 --coordinator hostA:12345 --num-processes 2 --process-id 1 --out parts

Every process draws the same commands (same sampler and seed), keeps the contiguous block of rows
``np.array_split(range(n), process_count)[process_index]`` and solves it with
:func:`pacjax.cli.batchrun.run_batch` (:func:`pacjax.iter_batch` chunk by chunk, sharded over the
process's local devices), writing ``parts/<name>_part<k>.h5`` with the attribute ``first_row``.
No data moves between hosts; ``jax.distributed`` only names the processes. To try it on one
machine, run both commands with ``--coordinator localhost:12345`` in two shells.
"""

import argparse
import os


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("--n", type=int, required=True)
    parser.add_argument("--sampler", default="lhs", choices=("uniform", "lhs", "grid"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--chunk-size", type=int, default=1024)
    parser.add_argument("--coordinator", required=True, help="host:port of process 0")
    parser.add_argument("--num-processes", type=int, required=True)
    parser.add_argument("--process-id", type=int, required=True)
    parser.add_argument("--out", default="parts")
    args = parser.parse_args()

    import jax

    # Before any other JAX call.
    jax.distributed.initialize(
        coordinator_address=args.coordinator,
        num_processes=args.num_processes,
        process_id=args.process_id,
    )
    import numpy as np

    from pacjax.cli import batchrun
    from pacjax.io.scenefile import load_scene

    scene, _, extra = load_scene(args.scene)
    low, high = batchrun.default_ranges(scene)
    commands = batchrun.sample_commands(args.sampler, args.n, low, high, args.seed)
    k, count = jax.process_index(), jax.process_count()
    rows = np.array_split(np.arange(len(commands)), count)[k]
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, f"{extra['name']}_part{k}.h5")
    summary = batchrun.run_batch(
        scene,
        commands[rows],
        path,
        chunk_size=args.chunk_size,
        devices=jax.local_device_count(),
        attrs={
            "first_row": int(rows[0]),
            "process_index": k,
            "process_count": count,
            "sampler": args.sampler,
            "seed": args.seed,
            "n_total": len(commands),
        },
        **extra["solver"],
    )
    print(f"process {k}/{count}: rows {rows[0]}..{rows[-1]} -> {path}")
    for line in summary.lines():
        print("  " + line)


if __name__ == "__main__":
    main()
