cd /work/notes/s33
for rep in 1 2 3; do
  echo "old $(cd /work/main && PYTHONPATH=/work/ab_old taskset -c 0 .venv/bin/python /work/notes/s33/vfone.py 2>&1 | grep -v Warn)"
  echo "new $(cd /work/main && taskset -c 0 .venv/bin/python /work/notes/s33/vfone.py 2>&1 | grep -v Warn)"
done
for rep in 1 2; do
  echo "old $(PYTHONPATH=/work/ab_old taskset -c 0 /work/main/.venv/bin/python single.py 2>&1 | grep -v Warn)"
  echo "new $(taskset -c 0 /work/main/.venv/bin/python single.py 2>&1 | grep -v Warn)"
done
