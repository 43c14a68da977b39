#!/usr/bin/env bash
# Evaluation on a slurm cluster, one task per GPU, as mmdet3d's:
#   [GPUS=8] [GPUS_PER_NODE=8] tools/slurm_test.sh PARTITION JOB_NAME \
#       CONFIG CHECKPOINT [ARGS]
# CPUS_PER_TASK, SRUN_ARGS and PYTHON as in tools/misc/slurm_srun.sh.
set -euo pipefail
if [[ $# -lt 4 ]]; then
    echo "usage: $0 PARTITION JOB_NAME CONFIG CHECKPOINT [ARGS]" >&2
    exit 2
fi
exec bash "$(dirname "$0")/misc/slurm_srun.sh" "$1" "$2" test.py "$3" "$4" \
    --launcher=slurm "${@:5}"
