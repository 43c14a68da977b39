#!/usr/bin/env bash
# The srun line that tools/slurm_train.sh and tools/slurm_test.sh share:
#   slurm_srun.sh PARTITION JOB_NAME TOOL [TOOL_ARGS]
# runs `python -u tools/TOOL TOOL_ARGS` as GPUS tasks (default 8),
# GPUS_PER_NODE a node (default 8), each with CPUS_PER_TASK cores (default
# 5, for its data loader workers); SRUN_ARGS passes further options to srun
# and PYTHON names the interpreter.
set -euo pipefail
PARTITION=$1
JOB_NAME=$2
TOOL=$3
GPUS=${GPUS:-8}
GPUS_PER_NODE=${GPUS_PER_NODE:-8}
CPUS_PER_TASK=${CPUS_PER_TASK:-5}
SRUN_ARGS=${SRUN_ARGS:-""}
tools="$(cd "$(dirname "$0")/.." && pwd)"
PY="${PYTHON:-python}"

# SRUN_ARGS is split into words on purpose: it holds several options.
# shellcheck disable=SC2086
PYTHONPATH="$tools/..${PYTHONPATH:+:$PYTHONPATH}" \
srun -p "$PARTITION" \
    --job-name="$JOB_NAME" \
    --gres=gpu:"$GPUS_PER_NODE" \
    --ntasks="$GPUS" \
    --ntasks-per-node="$GPUS_PER_NODE" \
    --cpus-per-task="$CPUS_PER_TASK" \
    --kill-on-bad-exit=1 \
    $SRUN_ARGS \
    "$PY" -u "$tools/$TOOL" "${@:4}"
