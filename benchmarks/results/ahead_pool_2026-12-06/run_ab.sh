#!/bin/bash
# Alternated A/B of the step tried ahead in the batch's pool: old = 3b255d6 (worktree
# /work/ab_old), new = /work/main.
cd "$(dirname "$0")"
PY=/work/main/.venv/bin/python
for i in 1 2; do
  for d in ab_old main; do
    tag=$([ $d = main ] && echo new || echo old)
    rm -rf /tmp/pjcache_ab; mkdir -p /tmp/pjcache_ab
    PYTHONPATH=/work/$d PACJAX_CACHE_DIR=/tmp/pjcache_ab $PY -m pacjax.cli.main bench --batch 1,16,100,1000 --dtypes float64 --baseline-batch 0 --grad-batch 0 --json bench_paper_${tag}_$i.json > bench_paper_${tag}_$i.txt 2>&1
    PYTHONPATH=/work/$d $PY /work/main/benchmarks/first_run.py --robots paper --entries solve,batch,identify,inverse --modes cold,warm --json first_run_${tag}_$i.json > first_run_${tag}_$i.txt 2>&1
  done
done
echo done
