# Default against classic emitters (XLA_FLAGS): single (flags.py) two at once one a core, then
# the batch of 64 (both cores), alternated.
cd "$(dirname "$0")"
export PACJAX_CACHE_DIR=off PACJAX_STORED_PROGRAMS=0
PY=/work/main/.venv/bin/python
C="--xla_cpu_use_fusion_emitters=false"
for round in 1 2; do
  XLA_FLAGS="" taskset -c 0 $PY flags.py 2>/dev/null & XLA_FLAGS="$C" taskset -c 1 $PY flags.py 2>/dev/null & wait
  XLA_FLAGS="$C" taskset -c 0 $PY flags.py 2>/dev/null & XLA_FLAGS="" taskset -c 1 $PY flags.py 2>/dev/null & wait
  XLA_FLAGS="" $PY batch.py 2>/dev/null
  XLA_FLAGS="$C" $PY batch.py 2>/dev/null
done
