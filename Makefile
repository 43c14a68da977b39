# The README's two commands: `make demo` and `make test`. Both set up the
# pinned environment first (tools/setup_env.sh; a no-op once it is current).
# `make setup VENV=/path/to/env` completes an existing (e.g. CUDA)
# environment, keeping its torch, mmcv and spconv-cuXXX where they fit;
# PYTHON=python3.10 picks the interpreter of a new one (docs/install.md).
VENV ?= .venv
PY := $(VENV)/bin/python
export VENV

.PHONY: setup test lint demo clean-env

setup:
	@bash tools/setup_env.sh

lint: setup
	$(PY) -m flake8 projects tools tests configs
	$(PY) -m isort --check-only --diff projects tools tests configs

test: lint
	$(PY) -m pytest tests

# Synthetic world -> train and evaluate both tiny models -> table + pictures
# in demo_out/ (see README). DEMO_ARGS passes options to tools/demo.py.
demo: setup
	$(PY) tools/demo.py $(DEMO_ARGS)

clean-env:
	rm -rf $(VENV)
