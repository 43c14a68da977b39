#!/usr/bin/env bash
# Creates (or updates) the pinned environment of this project, idempotently.
#
#   bash tools/misc/setup_env.sh                    # .venv in the repository root
#   PYTHON=python3.10 bash tools/misc/setup_env.sh  # another interpreter for it
#   VENV=/path/to/env bash tools/misc/setup_env.sh  # an existing environment
#
# Supported: CPython 3.9-3.12, torch >= 2.0, mmcv in [2.0.0rc4, 2.2.0) with
# its compiled ops, spconv 2.3 (the CPU `spconv` or a CUDA `spconv-cuXXX`).
# The ranges and their reasons live in tools/misc/env_check.py, which decides each
# step below and stops the setup with a message saying what to change when
# the environment is outside them.
#
# With VENV pointing at an existing environment (for example one with CUDA
# builds of torch, mmcv and spconv), what is installed there and fits is kept:
# torch; mmcv when its ops load; a CUDA spconv-cuXXX, over which the CPU
# `spconv` (same import name) is never installed. Only the missing pinned
# packages are added. A CUDA environment without a usable mmcv is refused
# with the command that installs OpenMMLab's prebuilt wheel, instead of a
# long source build (OCC_BUILD_MMCV=1 builds it anyway).
#
# A stamp file inside the environment holds a hash of requirements/* and of
# the setup scripts; when it matches, nothing is done. mmcv 2.1.0 is only on
# PyPI as source: for a CPU torch its ops are built once per machine (about 8
# minutes on 2 cores) into a wheelhouse outside the repository, keyed by the
# torch version, so fresh clones on the same machine reuse it.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$root"
venv="${VENV:-.venv}"
python_bin="${PYTHON:-python3}"
wheelhouse="${OCC_WHEELHOUSE:-${XDG_CACHE_HOME:-$HOME/.cache}/occ-wheels}"
req="requirements"
mmcv_version="2.1.0"

stamp_of() {
    cat "$req"/*.txt tools/misc/setup_env.sh tools/misc/env_check.py setup.cfg setup.py \
        | sha256sum | cut -d' ' -f1
}

stamp_file="$venv/.occ-env-stamp"
want="$(stamp_of)"
if [[ -f "$stamp_file" && "$(cat "$stamp_file")" == "$want" ]]; then
    echo "[setup] environment $venv is up to date (stamp $want)"
    exit 0
fi

log() { echo "[setup] $*"; }
# One decision of tools/misc/env_check.py: the word on stdout, notes on stderr;
# an unsupported environment stops the setup (exit status 2; called as
# step="$(decide ...)" so that set -e sees the status).
decide() { "$1" tools/misc/env_check.py "$2" || exit 2; }

if [[ -x "$venv/bin/python" ]]; then
    decide "$venv/bin/python" python >/dev/null
else
    decide "$python_bin" python >/dev/null
    log "creating virtual environment $venv with $($python_bin --version)"
    "$python_bin" -m venv "$venv"
fi
py="$venv/bin/python"
pip=("$py" -m pip --disable-pip-version-check)
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

# Every decision is taken before the environment is changed, so that an
# unsupported one is refused untouched (only a new torch comes first: the
# mmcv decision depends on it).
torch_step="$(decide "$py" torch)"
if [[ "$torch_step" == install ]]; then
    # numpy too: mmcv's build below imports torch, which warns without it.
    "${pip[@]}" install -q -c "$req/constraints.txt" torch numpy==1.26.4
fi
mmcv_step="$(decide "$py" mmcv)"
spconv_step="$(decide "$py" spconv)"

log "build tools (requirements/build.txt)"
"${pip[@]}" install -q -r "$req/build.txt"

if [[ "$mmcv_step" == build ]]; then
    torch_tag="$("$py" -c 'import torch; print(torch.__version__)')"
    torch_cuda="$("$py" -c 'import torch; print(torch.version.cuda or "")')"
    dest="$wheelhouse/torch-$torch_tag"
    mkdir -p "$dest"
    if ! ls "$dest"/mmcv-"$mmcv_version"-*.whl >/dev/null 2>&1; then
        log "building mmcv $mmcv_version with its ops against torch $torch_tag"
        log "(once per machine, about 8 minutes on 2 cores) into $dest"
        # --no-build-isolation: mmcv's setup.py imports pkg_resources, which
        # recent setuptools (84.2.1 when this was written) lacks. Without the
        # flag pip 23.2+ (Python 3.12's venvs) prepares the sdist's metadata
        # with the newest setuptools and fails; the pinned build tools
        # installed above still have it.
        "${pip[@]}" download -q --no-deps --no-build-isolation \
            --no-binary :all: -d "$tmp" "mmcv==$mmcv_version"
        # FORCE_CUDA: mmcv compiles CUDA kernels only where it sees a GPU
        # or this flag; a CUDA torch (OCC_BUILD_MMCV=1) wants them.
        MAX_JOBS="${MAX_JOBS:-2}" MMCV_WITH_OPS=1 \
            FORCE_CUDA="$([[ -n "$torch_cuda" ]] && echo 1 || echo 0)" \
            "${pip[@]}" wheel -q --no-deps --no-build-isolation \
            -w "$tmp/wheel" "$tmp"/mmcv-"$mmcv_version".tar.gz
        mv "$tmp"/wheel/mmcv-"$mmcv_version"-*.whl "$dest"/
    fi
    log "installing mmcv from $dest"
    "${pip[@]}" install -q --no-deps --force-reinstall \
        "$dest"/mmcv-"$mmcv_version"-*.whl
fi

runtime="$req/runtime.txt"
if [[ "$spconv_step" == keep ]]; then
    # Leave the pinned CPU spconv out: it would overwrite the CUDA one.
    runtime="$tmp/runtime.txt"
    grep -v -E '^spconv([<>=!~ ;]|$)' "$req/runtime.txt" > "$runtime"
fi

log "runtime and test requirements"
"${pip[@]}" install -q -c "$req/constraints.txt" \
    -r "$runtime" -r "$req/tests.txt"
log "OpenMMLab packages and devkits (--no-deps, see requirements/openmmlab.txt)"
"${pip[@]}" install -q --no-deps -r "$req/openmmlab.txt"
log "this project (editable)"
"${pip[@]}" install -q --no-deps --no-build-isolation -e .

log "checking that the stack imports"
"$py" - <<'PYEOF'
import mmcv
import mmdet
import mmdet3d
import mmengine
import spconv
import torch
from mmdet3d.utils import register_all_modules
from spconv.cppconstants import CPU_ONLY_BUILD

register_all_modules()
import projects.occ_common  # noqa: F401,E402

print(f'[setup] torch {torch.__version__} '
      f'({"CUDA " + torch.version.cuda if torch.version.cuda else "CPU"}), '
      f'mmengine {mmengine.__version__}, mmcv {mmcv.__version__}, '
      f'mmdet {mmdet.__version__}, mmdet3d {mmdet3d.__version__}, '
      f'spconv {spconv.__version__} ({"CPU" if CPU_ONLY_BUILD else "CUDA"})')
PYEOF
echo "$want" > "$stamp_file"
log "done"
