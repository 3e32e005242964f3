# `pacjax simulate` of the paper's robot (40 mm step, default 2 s, 20 fps: 41 frames), old
# (FuncAnimation, /work/ab_old) and new (/work/main) alternated, compilation cache warm
# (a first run of each fills it), both cores free.
cd "$(dirname "$0")"
export PACJAX_CACHE_DIR=/tmp/anim_cache
PY=/work/main/.venv/bin/python
run() {
  mkdir -p /tmp/anim_out_$1
  s=$(date +%s.%N)
  PYTHONPATH=$2 $PY -c "import sys, pacjax; print(pacjax.__file__); import pacjax.cli as c; sys.argv=['pacjax','simulate','/work/main/experiments/scenes/stella2023.toml','--controls','0.04,0,0,0,0,0,0,0,0','--out','/tmp/anim_out_$1','--force']; c.main()" 2>&1 | grep -v "Warn\|^wrote"
  e=$(date +%s.%N); echo "$1 wall $(echo "$e - $s" | bc) s"
}
run old /work/ab_old > /dev/null; run new /work/main > /dev/null
for r in 1 2 3; do run old /work/ab_old; run new /work/main; done
