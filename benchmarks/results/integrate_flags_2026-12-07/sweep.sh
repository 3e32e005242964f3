# Each configuration twice, two processes at once (one a core), in alternating order.
cd "$(dirname "$0")"
export PACJAX_CACHE_DIR=off PACJAX_STORED_PROGRAMS=0
PY=/work/main/.venv/bin/python
CONFIGS=("" "--xla_llvm_disable_expensive_passes=true" "--xla_backend_optimization_level=1" "--xla_backend_optimization_level=2" "--xla_cpu_use_fusion_emitters=false" "--xla_cpu_parallel_codegen_split_count=1")
for round in 1 2; do
  for i in 0 2 4; do
    a=${CONFIGS[$i]}; b=${CONFIGS[$((i+1))]}
    if [ $round = 2 ]; then t=$a; a=$b; b=$t; fi
    XLA_FLAGS="$a" taskset -c 0 $PY flags.py 2>/dev/null &
    XLA_FLAGS="$b" taskset -c 1 $PY flags.py 2>/dev/null &
    wait
  done
done
