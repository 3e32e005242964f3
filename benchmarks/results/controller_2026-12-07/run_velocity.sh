cd "$(dirname "$0")"
export PACJAX_CACHE_DIR=off PACJAX_STORED_PROGRAMS=0
PY=/work/main/.venv/bin/python
taskset -c 0 $PY controller_velocity.py '{"velocity_weight": 0.3}' 2>/dev/null &
taskset -c 1 $PY controller_velocity.py '{"velocity_weight": 0.1}' 2>/dev/null &
wait
taskset -c 0 $PY controller_velocity.py '{"velocity_weight": 0.0}' 2>/dev/null &
wait
