# Two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: install test test-fast lint typecheck pytest demo bench clean

install: $(STAMP)

# Re-install when the package metadata changes.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

lint: install
	$(BIN)/ruff check groundstation sim_device tests benchmarks examples

typecheck: install
	$(BIN)/mypy

# Test workers (pytest-xdist). The real-time flights (mark `realtime`) are one xdist group
# and the grounded virtual vehicles (`virtual_vehicle`) another: one worker each, mostly
# waiting on the wall clock, runs them one after another, while the others run the pure
# tests (tests/conftest.py); so more workers than the 2 cores of CI's machine.
WORKERS ?= 4

# The suite starts some hundreds of Python processes (gs commands, virtual labs, its
# workers). Where the caller's environment sets PYTHONDONTWRITEBYTECODE (the development
# machine's did), each of them compiled the package from source again: 16 % of the CPU of
# the suite's command-line tests. So the tests write and read bytecode as Python does by
# default (__pycache__, ignored by git), compiled once before the workers start.
BYTECODE := env -u PYTHONDONTWRITEBYTECODE

pytest: install
	$(BYTECODE) $(BIN)/python -m compileall -q groundstation sim_device
	$(BYTECODE) $(BIN)/pytest -q -n $(WORKERS) --dist loadgroup --no-loadscope-reorder --durations=12

# The type check and the lint run beside the tests: the real-time flights' worker, not the
# CPU, sets how long the tests take, and mypy's 12 s fit in what it leaves idle
test: install
	$(MAKE) --no-print-directory -j3 lint typecheck pytest

# The edit-run loop: no real-time flight and no long simulation (under 90 s); `make test`
# runs everything
test-fast: install
	$(BYTECODE) $(BIN)/python -m compileall -q groundstation sim_device
	$(BYTECODE) $(BIN)/pytest -q -n 2 -m "not realtime and not virtual_vehicle and not slow"

# `make demo PROTOCOL=asctec-ll` flies the virtual AscTec LL vehicle instead of the X-3D;
# `make demo FLEET=3` a virtual fleet through the Vicon relay (README "Fleet")
PROTOCOL ?= x3d
FLEET ?=
demo: install
ifeq ($(FLEET),)
	$(BIN)/gs fly --config config/sim.yaml --demo --protocol $(PROTOCOL)
else
	$(BIN)/gs fleet demo --vehicles $(FLEET) --config config/sim.yaml
endif

bench: install
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) .mypy_cache .ruff_cache .pytest_cache
