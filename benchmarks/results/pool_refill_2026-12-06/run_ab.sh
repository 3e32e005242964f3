#!/bin/bash
# Alternated A/B of the slot pool: old = d50fe77 (worktree /work/ab_old), new = /work/main.
cd "$(dirname "$0")"
PY=/work/main/.venv/bin/python
for i in 1 2; do
  for d in ab_old main; do
    tag=$([ $d = main ] && echo new || echo old)
    rm -rf /tmp/pjcache_ab; mkdir -p /tmp/pjcache_ab
    PYTHONPATH=/work/$d PACJAX_CACHE_DIR=/tmp/pjcache_ab $PY -m pacjax.cli.main bench --batch 1,16,100,1000 --dtypes float64 --baseline-batch 0 --grad-batch 16 --json bench_paper_${tag}_$i.json > bench_paper_${tag}_$i.txt 2>&1
    rm -rf /tmp/pjcache_ab; mkdir -p /tmp/pjcache_ab
    PYTHONPATH=/work/$d PACJAX_CACHE_DIR=/tmp/pjcache_ab $PY -m pacjax.cli.main bench --scene /work/main/experiments/scenes/tendon_single.toml --batch 100,1000 --dtypes float64 --baseline-batch 0 --grad-batch 0 --json bench_tension_${tag}_$i.json > bench_tension_${tag}_$i.txt 2>&1
    PYTHONPATH=/work/$d $PY /work/main/benchmarks/first_run.py --robots paper --entries batch,identify --modes cold,warm --json first_run_${tag}_$i.json > first_run_${tag}_$i.txt 2>&1
  done
done
echo done
