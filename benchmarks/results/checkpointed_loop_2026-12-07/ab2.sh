# The whole change (checkpointed step loop, one trace of the vector field, the start's alignment
# at LLVM level 0) against 34a029c: single.py old and new at once, one a core, then swapped;
# then batch2.py old, new, old, new (both cores).
export PACJAX_CACHE_DIR=off PACJAX_STORED_PROGRAMS=0
OLD=/work/ab_old; NEW=/work/main; PY=/work/main/.venv/bin/python
for round in 1 2; do
  if [ $round = 1 ]; then a=0; b=1; else a=1; b=0; fi
  TAG=old PYTHONPATH=$OLD taskset -c $a $PY single.py & TAG=new PYTHONPATH=$NEW taskset -c $b $PY single.py; wait
done
for tag in old new old new; do
  if [ $tag = old ]; then P=$OLD; else P=$NEW; fi
  TAG=$tag PYTHONPATH=$P $PY batch2.py
done
