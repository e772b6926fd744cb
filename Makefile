# Everything a fresh machine with Python 3.11 needs: `make run`, `make test`.
PYTHON ?= python3.11
VENV   ?= .venv
PY     := $(VENV)/bin/python
RUNTIME := $(VENV)/.installed-runtime
DEV     := $(VENV)/.installed-dev
# Test processes in parallel (pytest-xdist); `make test JOBS=1` runs them one by one.
JOBS   ?= 2

.PHONY: run test test-long test-fast lint bench clean install install-dev warm

$(VENV)/bin/python:
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found (set PYTHON=...)"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

# `make run` installs what a run needs; `make test` adds the test and lint tools. Both then
# compile the numba kernels into their cache (cosim/sim/warm.py, about 25 s once), so that
# no run, and no test process, compiles them again.
$(RUNTIME): pyproject.toml | $(VENV)/bin/python
	$(PY) -m pip install --quiet -e .
	$(PY) -m cosim.sim.warm
	touch $(RUNTIME)

$(DEV): pyproject.toml | $(VENV)/bin/python
	$(PY) -m pip install --quiet -e ".[dev,dask]"
	$(PY) -m cosim.sim.warm
	touch $(DEV) $(RUNTIME)

install: $(RUNTIME)
install-dev: $(DEV)

# compile the numba kernels again (after editing one: otherwise the first run compiles it)
warm: $(RUNTIME)
	$(PY) -m cosim.sim.warm

run: $(RUNTIME)
	$(VENV)/bin/cosim run

test: $(DEV)
	$(VENV)/bin/ruff check .
	$(PY) -m pytest -q -n $(JOBS)

# The long checks (marked `long`: whole families of runs, minutes each), after `make test`.
test-long: $(DEV)
	$(PY) -m pytest -q -n $(JOBS) -m long

# The unit tests only (no SUMO), about a minute.
test-fast: $(DEV)
	$(PY) -m pytest -q -n $(JOBS) -m "not sumo and not long"

lint: $(DEV)
	$(VENV)/bin/ruff check .

bench: $(DEV)
	$(PY) benchmarks/bench_cosim.py

clean:
	rm -rf $(VENV) outputs .pytest_cache
