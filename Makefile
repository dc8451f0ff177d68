# The two commands of the README: `make demo` and `make test`. Both create (or
# reuse) a local virtual environment and install the project into it.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= out
SAND_BLOCK_DIR ?=

.PHONY: demo test test-all bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	$(PY) -m experiments.demo --out=$(OUT)/demo

test: $(STAMP)
	$(PY) -m pytest -n 2 -q

test-all: $(STAMP)
	$(PY) -m pytest -n 2 -q -m ""

# The gns benchmark times the shared sand block window, which is not part of
# the repository: make bench SAND_BLOCK_DIR=/path/to/window
bench: $(STAMP)
	@test -n "$(SAND_BLOCK_DIR)" || { echo "make bench needs SAND_BLOCK_DIR=<directory of sand_block_window.npz>" >&2; exit 2; }
	$(PY) -m pip install -q -e ".[bench]"
	$(PY) -m experiments.benchmarks --what=mpm,gns --out=docs/benchmarks --sand_block_dir=$(SAND_BLOCK_DIR)

clean:
	rm -rf $(VENV) $(OUT) .jax_cache
