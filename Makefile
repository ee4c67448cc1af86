# Each target installs what is missing first (scripts/setup.sh is idempotent and quick).
VENV := .venv
PY := $(VENV)/bin/python

.PHONY: setup demo test lint unit integration py38 bench clean

setup:
	@bash scripts/setup.sh

demo: setup
	$(VENV)/bin/bmtree demo

lint: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/vermin -q --no-tips --violations -t=3.8- --eval-annotations --backport dataclasses comm modules blackboard coordinator basicmodutil_pkg

unit: setup
	$(PY) -m pytest -q tests/unit

integration: setup
	$(PY) -m pytest -q tests/integration

py38: setup
	@bash scripts/test-py38.sh

test: lint
	$(PY) -m pytest -q
	@bash scripts/test-py38.sh

bench: setup
	$(PY) -m bench

clean:
	rm -rf $(VENV) .venv38 build *.egg-info bench/results
