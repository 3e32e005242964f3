#!/usr/bin/env bash
# The GPU benchmark of pacjax, in stages that each keep what they measured (pacjax bench writes its
# JSON and Markdown after every measurement), each under its own time limit so that a slow stage
# cannot take the ones after it down with it.
#
#   OUT=bench-gpu bash benchmarks/gpu.sh
#
# Run from the repository root with pacjax importable (installed, or PYTHONPATH=$PWD) and a JAX
# that sees the GPU. Writes into $OUT (the Markdown tables into $MD_DIR, default $OUT):
# machine.txt, bench_pac.{json,md} (PAC float64 and float32 at batch 10,000, the gradient
# through a batch, and with PAC_BASELINE_BATCH > 0 the plain-flow baseline in the same process), bench_models.{json,md} (PCC and PolynomialCurvature(3)),
# bench_baseline.{json,md} (PAC at batch 1,000 against the plain damped flow), with
# STAGE_BATCH_N > 0 batch_run.json (the summary of one `pacjax batch` run of that many rows:
# rate, peak memory), with STAGE_SOROMOX_S > 0 (and SoRoMoX installed) vs_soromox_{a,b}.json (the
# side by side of benchmarks/vs_soromox.py at SOROMOX_ROWS rows, each problem its own stage, run
# first), and log.txt. Each stage's time limit and size can be set from the
# environment (the names below); a stage whose limit is 0 is skipped. benchmarks/RESULTS.md has what it measured on an H100 and an H200.
set -u
OUT=${OUT:-bench-gpu}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
PY=${PYTHON:-python3}
LOG="$OUT/log.txt"
CLI=("$PY" -m pacjax.cli)

stage() {  # stage SECONDS NAME COMMAND...
    local limit=$1 name=$2
    shift 2
    if [ "$limit" -le 0 ]; then
        echo "=== $name: skipped (limit 0)" | tee -a "$LOG"
        return
    fi
    echo "=== $name (limit ${limit} s) $(date +%T)" | tee -a "$LOG"
    local t0=$SECONDS
    timeout "$limit" "$@" >>"$LOG" 2>&1
    echo "=== $name: exit $? after $((SECONDS - t0)) s" | tee -a "$LOG"
}

{
    nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
    "$PY" -c "import pacjax, jax, jaxlib, equinox, diffrax, optimistix; print('jax', jax.__version__, \
'jaxlib', jaxlib.__version__, 'equinox', equinox.__version__, 'diffrax', diffrax.__version__, \
'optimistix', optimistix.__version__); print(jax.devices())"
    nproc
} >"$OUT/machine.txt" 2>&1
cat "$OUT/machine.txt"

for problem in a b; do
    stage "${STAGE_SOROMOX_S:-0}" "vs_soromox_$problem" "$PY" benchmarks/vs_soromox.py \
        --problem "$problem" --rows "${SOROMOX_ROWS:-1000,10000}" \
        --grad-rows "${SOROMOX_GRAD_ROWS:-100}" --json "$OUT/vs_soromox_$problem.json"
done

stage "${STAGE_PAC_S:-240}" bench_pac "${CLI[@]}" bench --models PAC --dtypes float64,float32 \
    --batch "${BATCHES:-10000}" --baseline-batch "${PAC_BASELINE_BATCH:-0}" \
    --grad-batch "${GRAD_BATCH:-1000}" \
    --json "$OUT/bench_pac.json" --md "${MD_DIR:-$OUT}/bench_pac.md"

stage "${STAGE_MODELS_S:-100}" bench_models "${CLI[@]}" bench --models PCC,Poly3 \
    --dtypes "${MODEL_DTYPES:-float64}" --batch "${MODEL_BATCH:-10000}" --baseline-batch 0 --grad-batch 0 \
    --json "$OUT/bench_models.json" --md "${MD_DIR:-$OUT}/bench_models.md"

stage "${STAGE_BASELINE_S:-120}" bench_baseline "${CLI[@]}" bench --models PAC --dtypes float64 \
    --batch "${BASELINE_BATCHES:-1000}" --baseline-batch "${BASELINE_BATCH:-256}" --grad-batch 0 \
    --json "$OUT/bench_baseline.json" --md "${MD_DIR:-$OUT}/bench_baseline.md"

if [ "${STAGE_BATCH_N:-0}" -gt 0 ]; then
    stage "${STAGE_BATCH_S:-200}" batch_run "${CLI[@]}" batch experiments/scenes/stella2023.toml \
        --n "$STAGE_BATCH_N" --sampler uniform --chunk-size "${BATCH_CHUNK:-100000}" --no-plot \
        --out /tmp/pacjax-batch
    cp /tmp/pacjax-batch/*_batch.json "$OUT/batch_run.json" 2>/dev/null
fi
