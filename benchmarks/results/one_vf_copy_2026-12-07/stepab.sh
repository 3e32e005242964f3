# The step's cost with a held Jacobian (stepcost.py), alternated on one core. Ran one round
# (old, scan) before it was stopped for the tests; the while-loop variants it also listed were
# not kept (see README.md).
export PACJAX_CACHE_DIR=off PACJAX_STORED_PROGRAMS=0
PY=/work/main/.venv/bin/python
for round in 1 2 3; do
  TAG=old PYTHONPATH=/work/ab_old taskset -c 0 $PY stepcost.py 2>&1 | tail -1
  TAG=scan PYTHONPATH=/work/v_scan taskset -c 0 $PY stepcost.py 2>&1 | tail -1
done
