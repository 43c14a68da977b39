#!/usr/bin/env bash
# Installs what the 3D viewer (tools/misc/browse_occ.py) and its browser
# tests need beyond the Python environment, idempotently:
#
#   * three.js and the bundler esbuild, pinned in package.json /
#     package-lock.json, into node_modules/ of the repository (`npm ci`,
#     no install scripts), when npm is on PATH;
#   * with --with-chromium: Debian's chromium (headless, for the browser
#     tests), with apt-get when run as root and chromium is absent.
#
#   bash tools/misc/setup_browser.sh                  # `make viewer`
#   bash tools/misc/setup_browser.sh --with-chromium  # `make test` runs it
#
# Each part that cannot be installed here is skipped with a line saying why
# and what to do; the viewer then says what is missing, and the browser
# tests skip with the same reason. `make test` runs this before pytest.
set -uo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$root"
log() { echo "[setup-browser] $*"; }

# three.js: `npm ci` installs exactly the lock file's versions; it is
# repeated only when the lock file changed since the last install.
stamp="node_modules/.occ-lock-stamp"
want="$(sha256sum package-lock.json | cut -d' ' -f1)"
if [[ -f "$stamp" && "$(cat "$stamp")" == "$want" ]]; then
    log "three.js is up to date (node_modules/three)"
elif command -v npm >/dev/null 2>&1; then
    log "installing three.js from package-lock.json (npm ci)"
    if npm ci --ignore-scripts --no-audit --no-fund --loglevel=error; then
        echo "$want" > "$stamp"
    else
        log "npm ci failed: the viewer needs node_modules/three"
    fi
else
    log "skipped three.js: npm is not installed (install Node.js >= 18"
    log "and run this script again; see docs/visualization.md)"
fi

# Chromium for the browser tests only; the viewer itself runs in the
# user's own browser.
if [[ "${1:-}" != --with-chromium ]]; then
    exit 0
fi
if command -v chromium >/dev/null 2>&1; then
    log "chromium is installed: $(command -v chromium)"
elif [[ "$(id -u)" == 0 ]] && command -v apt-get >/dev/null 2>&1; then
    log "installing Debian's chromium (apt-get)"
    export DEBIAN_FRONTEND=noninteractive
    if ! apt-get install -y -qq --no-install-recommends chromium \
            >/dev/null 2>&1; then
        apt-get update -qq >/dev/null 2>&1 || true
        apt-get install -y -qq --no-install-recommends chromium \
            >/dev/null 2>&1 || log "apt-get could not install chromium"
    fi
    command -v chromium >/dev/null 2>&1 && \
        log "chromium installed: $(chromium --version 2>/dev/null)"
else
    log "skipped chromium: not root or no apt-get (the browser tests skip;"
    log "install chromium by hand to run them)"
fi
exit 0
