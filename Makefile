# The README's two commands: `make demo` and `make test`. Both set up the
# pinned environment first (tools/setup_env.sh; a no-op once it is current).
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

demo: setup
	@bash tools/demo.sh

clean-env:
	rm -rf $(VENV)
