export PACJAX_CACHE_DIR=off PACJAX_STORED_PROGRAMS=0
cd /work/notes/s34
PY=/work/main/.venv/bin/python
for r in 1 2; do
  PYTHONPATH=/work/main TAG=old$r $PY batch2.py
  PYTHONPATH=/work/dev TAG=new$r $PY batch2.py
done
for r in 1 2; do
  PYTHONPATH=/work/main TAG=old$r taskset -c $((r-1)) $PY single.py & PYTHONPATH=/work/dev TAG=new$r taskset -c $((2-r)) $PY single.py; wait
done
