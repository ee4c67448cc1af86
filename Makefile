# Each target installs what is missing first (scripts/setup.sh is idempotent and quick).
VENV := .venv
PY := $(VENV)/bin/python
# Integration tests mostly wait (on processes, the simulated robot, a browser): three workers,
# one test file each at a time (pytest-xdist), keep two cores busy. TEST_WORKERS=0 runs serially.
TEST_WORKERS ?= 3
XDIST := $(if $(filter 0,$(TEST_WORKERS)),,-n $(TEST_WORKERS) --dist loadfile)

.PHONY: setup demo test lint unit integration py38 bench reliability clean

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
	$(PY) -m pytest -q $(XDIST) tests/integration

py38: setup
	@bash scripts/test-py38.sh

test: lint
	$(PY) -m pytest -q $(XDIST)
	@bash scripts/test-py38.sh

bench: setup
	$(PY) -m bench

# The fault tests at full scale (several minutes); `make test` runs reduced versions.
# Every measured figure is printed on a line starting with FIGURE.
RELIABILITY := tests/reliability tests/unit/test_loader_fuzz.py tests/integration/test_liveness.py \
	tests/integration/test_fuzz_topics.py tests/integration/test_blackboard_crash.py \
	tests/integration/test_master_restart.py tests/integration/test_duplicates.py tests/integration/test_start_order.py
reliability: setup
	@mkdir -p bench/results
	BMTREE_RELIABILITY=1 $(PY) -m pytest -q -s -p no:cacheprovider $(RELIABILITY) > bench/results/reliability.txt 2>&1; \
	  status=$$?; grep -E '^(FIGURE|FAILED|ERROR)|passed|failed' bench/results/reliability.txt; \
	  echo "(full output: bench/results/reliability.txt)"; exit $$status

clean:
	rm -rf $(VENV) .venv38 build *.egg-info bench/results
