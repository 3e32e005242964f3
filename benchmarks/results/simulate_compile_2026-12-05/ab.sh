#!/bin/bash
# alternate old (HEAD worktree) and new (working tree) bench_dynamics, PAC, the default solver, no batch
for i in 1 2; do
  for side in new old; do
    if [ $side = old ]; then root=/work/ab_old; else root=/work/main; fi
    cd $root && PYTHONPATH=$root taskset -c 0 /work/main/.venv/bin/python benchmarks/bench_dynamics.py --models PAC --solvers rosenbrock23 --batch 0 --repeats 3 --json /work/notes/s24/ab2/${side}_$i.json > /work/notes/s24/ab2/${side}_$i.txt 2>&1
  done
done
