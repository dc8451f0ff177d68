# The two commands of the README: `make demo` and `make test`. Both create (or
# reuse) a local virtual environment and install the project into it.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= out

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

bench: $(STAMP)
	$(PY) -m pip install -q -e ".[bench]"
	$(PY) -m experiments.benchmarks --out=docs/benchmarks

clean:
	rm -rf $(VENV) $(OUT) .jax_cache
