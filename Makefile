# Two entry points, both creating or reusing .venv with nothing but Python 3.11+:
#   make demo   fly the default mission (the paper's sine scenario) end to end
#   make test   run the test suite
#   make test-fast  the pure tests only (no processes, no sockets): 48-59 s on the 2-core VM, 70-83 s in its slow hours
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-fast lint bench clean

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "Python 3.11+ needed, found " + sys.version.split()[0]'
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet --config-settings editable_mode=compat -e '.[test]'
	@touch $(STAMP)

demo: $(STAMP)
	$(BIN)/bsst sim missions/sine.toml --out runs/demo-sine --overwrite

# the suite starts some hundreds of Python processes (vehicles, controllers, bsst commands): with bytecode
# caching off (PYTHONDONTWRITEBYTECODE, set on some machines) each compiles the project's sources again
# (~0.12 s a process) and pytest rewrites every test module again in each worker
test: $(STAMP)
	env -u PYTHONDONTWRITEBYTECODE $(BIN)/python -m pytest

# the test modules marked `pytestmark = pytest.mark.process` start processes or open sockets; the rest is pure
# (and CPU-bound: one worker per core, where make test runs six)
test-fast: $(STAMP)
	env -u PYTHONDONTWRITEBYTECODE $(BIN)/python -m pytest -n 2 -m "not process"

lint: $(STAMP)
	$(BIN)/ruff check .

bench: $(STAMP)
	$(BIN)/python benchmarks/offline.py

# numba's caches need no cleaning after a change (bridge/autopilot/kernelcache.py); clean removes them anyway
clean:
	rm -rf runs .pytest_cache
	find . -path ./.venv -prune -o \( -name '*.nbi' -o -name '*.nbc' \) -print | xargs rm -f
