cd "$(dirname "$0")"
export PACJAX_CACHE_DIR=off PACJAX_STORED_PROGRAMS=0
PY=/work/main/.venv/bin/python
for v in '{}' '{"pcoeff": 0.3, "icoeff": 0.3}' '{"pcoeff": 0.4, "icoeff": 0.3}' '{"error_order": 2}' '{"error_order": 2, "pcoeff": 0.3, "icoeff": 0.3}' '{"pcoeff": 0.2, "icoeff": 0.4}' '{"safety": 0.8}' '{"factormax": 3.0}'; do
  $PY controller.py "$v" 2>/dev/null
done
