cd /work/main
for rep in 1 2; do
  echo "default $(.venv/bin/python /work/notes/s33/batch_only.py 2>&1 | grep -v Warn | tail -1)"
  echo "ynnoff $(XLA_FLAGS=--xla_cpu_experimental_ynn_fusion_type= .venv/bin/python /work/notes/s33/batch_only.py 2>&1 | grep -v Warn | tail -1)"
done
