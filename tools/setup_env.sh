#!/usr/bin/env bash
# Creates (or updates) the pinned environment of this project, idempotently.
#
#   bash tools/setup_env.sh            # .venv in the repository root
#   VENV=/path/to/env bash tools/setup_env.sh
#
# With VENV pointing at an existing environment (for example one with a CUDA
# build of torch and mmcv), the torch and mmcv already installed there are
# kept when their versions fit (torch 2.x, mmcv >= 2.0.0rc4, < 2.2.0) and only
# the missing pinned packages are added.
#
# A stamp file inside the environment holds a hash of requirements/* and of
# this script; when it matches, nothing is done. mmcv 2.1.0 is only on PyPI as
# source: its CPU ops are built once per machine (about 8 minutes on 2 cores)
# into a wheelhouse outside the repository, keyed by the torch version, so
# fresh clones on the same machine reuse it.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
venv="${VENV:-.venv}"
python_bin="${PYTHON:-python3}"
wheelhouse="${OCC_WHEELHOUSE:-${XDG_CACHE_HOME:-$HOME/.cache}/occ-wheels}"
req="requirements"
mmcv_version="2.1.0"

stamp_of() {
    cat "$req"/*.txt tools/setup_env.sh setup.cfg setup.py | sha256sum | cut -d' ' -f1
}

stamp_file="$venv/.occ-env-stamp"
want="$(stamp_of)"
if [[ -f "$stamp_file" && "$(cat "$stamp_file")" == "$want" ]]; then
    echo "[setup] environment $venv is up to date (stamp $want)"
    exit 0
fi

log() { echo "[setup] $*"; }

if [[ ! -x "$venv/bin/python" ]]; then
    log "creating virtual environment $venv with $($python_bin --version)"
    "$python_bin" -m venv "$venv"
fi
py="$venv/bin/python"
pip=("$py" -m pip --disable-pip-version-check)

has_module() { "$py" -c "import $1" >/dev/null 2>&1; }

log "build tools (requirements/build.txt)"
"${pip[@]}" install -q -r "$req/build.txt"

if has_module torch; then
    log "keeping installed torch $("$py" -c 'import torch; print(torch.__version__)')"
else
    log "installing torch (CPU build)"
    # numpy too: mmcv's build below imports torch, which warns without it.
    "${pip[@]}" install -q -c "$req/constraints.txt" torch==2.13.0 \
        numpy==1.26.4
fi

mmcv_ok() {
    "$py" - <<'EOF' >/dev/null 2>&1
import mmcv
from mmcv.ops import nms  # noqa: F401  (proves the compiled ops load)
from packaging.version import Version
assert Version('2.0.0rc4') <= Version(mmcv.__version__) < Version('2.2.0')
EOF
}

if mmcv_ok; then
    log "keeping installed mmcv $("$py" -c 'import mmcv; print(mmcv.__version__)')"
else
    torch_tag="$("$py" -c 'import torch; print(torch.__version__)')"
    dest="$wheelhouse/torch-$torch_tag"
    mkdir -p "$dest"
    if ! ls "$dest"/mmcv-"$mmcv_version"-*.whl >/dev/null 2>&1; then
        log "building mmcv $mmcv_version with CPU ops against torch $torch_tag"
        log "(once per machine, about 8 minutes on 2 cores) into $dest"
        tmp="$(mktemp -d)"
        "${pip[@]}" download -q --no-deps --no-binary :all: -d "$tmp" \
            "mmcv==$mmcv_version"
        MAX_JOBS="${MAX_JOBS:-2}" MMCV_WITH_OPS=1 \
            "${pip[@]}" wheel -q --no-deps --no-build-isolation \
            -w "$tmp/wheel" "$tmp"/mmcv-"$mmcv_version".tar.gz
        mv "$tmp"/wheel/mmcv-"$mmcv_version"-*.whl "$dest"/
        rm -rf "$tmp"
    fi
    log "installing mmcv from $dest"
    "${pip[@]}" install -q --no-deps --force-reinstall \
        "$dest"/mmcv-"$mmcv_version"-*.whl
fi

log "runtime and test requirements"
"${pip[@]}" install -q -c "$req/constraints.txt" \
    -r "$req/runtime.txt" -r "$req/tests.txt"
log "OpenMMLab packages and devkits (--no-deps, see requirements/openmmlab.txt)"
"${pip[@]}" install -q --no-deps -r "$req/openmmlab.txt"
log "this project (editable)"
"${pip[@]}" install -q --no-deps --no-build-isolation -e .

log "checking that the stack imports"
"$py" - <<'EOF'
import mmcv
import mmdet
import mmdet3d
import mmengine
import spconv
import torch
from mmdet3d.utils import register_all_modules

register_all_modules()
import projects.occ_common  # noqa: F401,E402

print(f'[setup] torch {torch.__version__}, mmengine {mmengine.__version__}, '
      f'mmcv {mmcv.__version__}, mmdet {mmdet.__version__}, '
      f'mmdet3d {mmdet3d.__version__}, spconv {spconv.__version__}')
EOF
echo "$want" > "$stamp_file"
log "done"
