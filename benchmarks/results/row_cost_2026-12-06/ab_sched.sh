cd /work/main
for rep in 1 2; do
  echo "default $(PACJAX_CACHE=0 .venv/bin/python /work/notes/s33/batch_only.py 2>&1 | grep -v Warn | tail -1)"
  echo "noconc $(PACJAX_CACHE=0 XLA_FLAGS=--xla_cpu_enable_concurrency_optimized_scheduler=false .venv/bin/python /work/notes/s33/batch_only.py 2>&1 | grep -v Warn | tail -1)"
done
