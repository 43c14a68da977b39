# The README's two commands: `make demo` and `make test`. Both set up the
# pinned environment first (tools/misc/setup_env.sh; a no-op once it is current).
# `make setup VENV=/path/to/env` completes an existing (e.g. CUDA)
# environment, keeping its torch, mmcv and spconv-cuXXX where they fit;
# PYTHON=python3.10 picks the interpreter of a new one (docs/get_started.md).
VENV ?= .venv
PY := $(VENV)/bin/python
export VENV

.PHONY: setup viewer test test-slow lint demo clean-env

setup:
	@bash tools/misc/setup_env.sh

# three.js and esbuild for tools/misc/browse_occ.py (npm ci; needs Node.js).
viewer:
	@bash tools/misc/setup_browser.sh

lint: setup
	$(PY) -m flake8 projects tools tests configs demo
	$(PY) -m isort --check-only --diff projects tools tests configs demo

# Two pytest-xdist workers of one thread each (tests/conftest.py), a module
# per worker at a time so that module fixtures are built once.
# TEST_WORKERS=0 runs in-process. `make test` runs every test but the
# end-to-end tier (`slow`: tools/train.py runs, DDP, kill-and-resume,
# builds, the viewer in headless Chromium); `make test-slow` runs that tier;
# CI (.ci/run) runs both. Both install the viewer's three.js (npm); the
# slow tier also Debian's chromium when run as root (its browser tests skip,
# saying why, where it cannot be installed).
TEST_WORKERS ?= 2
test: lint
	@bash tools/misc/setup_browser.sh
	$(PY) -m pytest tests -m "not slow" -n $(TEST_WORKERS) --dist loadscope

test-slow: setup
	@bash tools/misc/setup_browser.sh --with-chromium
	$(PY) -m pytest tests -m slow -n $(TEST_WORKERS) --dist loadscope

# Synthetic world -> train and evaluate both tiny models -> table + pictures
# in demo_out/ (see README). DEMO_ARGS passes options to demo/synthetic_demo.py.
demo: setup
	$(PY) demo/synthetic_demo.py $(DEMO_ARGS)

clean-env:
	rm -rf $(VENV)
