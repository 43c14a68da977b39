#!/usr/bin/env bash
# What a GPU must show before a paper config trains on it, in about 8
# minutes on one GPU (steps 1-3; step 4 compiles, minutes per model),
# everything written as JSON (or JUnit XML) to OUT_DIR:
#   1. cuda_tests.xml  the tests marked `cuda` (CUDA kernels, CUDA autocast)
#   2. ddp_nccl.json   with 2+ GPUs: the paper models, 2 nccl ranks x 3 steps
#   3. train_fp32.json, train_amp_fp16.json, train_amp_bf16.json:
#      5 training steps of each paper model at the paper's input size and
#      batch, one GPU (seconds a step, peak CUDA memory, losses)
#   4. compiled_*.json, cudagraph_*.json: each paper model's prediction
#      eager and under torch.compile (inductor; then mode reduce-overhead,
#      CUDA graphs), side by side in alternating rounds (benchmark.py
#      --eager-vs-compiled; the compilation adds minutes per model)
#   5. summary.json    each step's exit status and seconds
# Usage (from the repository root, in the environment that has CUDA torch):
#   bash tools/analysis_tools/gpu_check.sh [OUT_DIR]   # default work_dirs/gpu_check
# PYTHON picks the interpreter (default: python). Exit status: the number of
# steps that failed.
set -u
PYTHON=${PYTHON:-python}
OUT=${1:-work_dirs/gpu_check}
mkdir -p "$OUT"

if ! "$PYTHON" -c 'import sys, torch; sys.exit(0 if torch.cuda.is_available() else 1)'; then
    echo "gpu_check: no CUDA device visible to $PYTHON (torch.cuda.is_available() is False)" >&2
    exit 2
fi
GPUS=$("$PYTHON" -c 'import torch; print(torch.cuda.device_count())')
PAPER_CONFIGS=(
    configs/occ_cyl/occcyl_r50-swins_3xb1-24e_surroundocc-nus.py
    configs/sdg_occ/sdgocc-fusion_r50_4xb2-24e_occ3d-nus.py
    configs/sdg_occ/sdgocc-kl_r50_4xb2-24e_occ3d-nus.py
)
STEPS=()
FAILED=0

# step NAME TIMEOUT_S COMMAND...: run, log to OUT/NAME.log, record status.
step() {
    local name=$1 limit=$2
    shift 2
    local start=$SECONDS
    echo "gpu_check: $name ..."
    timeout "$limit" "$@" >"$OUT/$name.log" 2>&1
    local rc=$?
    local took=$((SECONDS - start))
    echo "gpu_check: $name exit $rc after ${took} s (log: $OUT/$name.log)"
    [ "$rc" -ne 0 ] && FAILED=$((FAILED + 1))
    STEPS+=("{\"step\": \"$name\", \"exit\": $rc, \"seconds\": $took}")
}

step cuda_tests 120 "$PYTHON" -m pytest -q -rs -m cuda tests \
    --junitxml "$OUT/cuda_tests.xml"
if [ "$GPUS" -ge 2 ]; then
    step ddp_nccl 90 "$PYTHON" tools/analysis_tools/ddp_check.py \
        "${PAPER_CONFIGS[@]}" --ranks 2 --iters 3 --device cuda \
        --batch-size 1 --json "$OUT/ddp_nccl.json"
else
    echo "gpu_check: ddp_nccl skipped: $GPUS GPU visible, 2 needed"
    STEPS+=("{\"step\": \"ddp_nccl\", \"skipped\": \"$GPUS GPU visible\"}")
fi
step train_fp32 90 "$PYTHON" tools/analysis_tools/ddp_check.py \
    "${PAPER_CONFIGS[@]}" --ranks 1 --iters 5 --device cuda \
    --json "$OUT/train_fp32.json"
for amp in fp16 bf16; do
    step "train_amp_$amp" 90 "$PYTHON" tools/analysis_tools/ddp_check.py \
        "${PAPER_CONFIGS[@]}" --ranks 1 --iters 5 --device cuda \
        --amp "$amp" --json "$OUT/train_amp_$amp.json"
done
for cfg in "${PAPER_CONFIGS[@]}"; do
    name=$(basename "$cfg" .py)
    for mode in default reduce-overhead; do
        kind=compiled
        [ "$mode" = reduce-overhead ] && kind=cudagraph
        step "${kind}_$name" 600 "$PYTHON" tools/analysis_tools/benchmark.py \
            "$cfg" --synthetic-batch --device cuda --eager-vs-compiled \
            --compile "$mode" --warmup 3 --runs 10 \
            --json "$OUT/${kind}_$name.json"
    done
done

{
    echo "{\"gpus\": $GPUS, \"failed\": $FAILED, \"steps\": ["
    for i in "${!STEPS[@]}"; do
        [ "$i" -gt 0 ] && echo ","
        echo "  ${STEPS[$i]}"
    done
    echo "]}"
} >"$OUT/summary.json"
echo "gpu_check: $FAILED step(s) failed; results in $OUT"
exit "$FAILED"
