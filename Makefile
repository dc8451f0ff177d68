# The two commands of the README: `make demo` and `make test`. Both create (or
# reuse) a local virtual environment and install the project into it.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= out
SAND_BLOCK_DIR ?=

.PHONY: demo test test-all bench wheels clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	$(PY) -m experiments.demo --out=$(OUT)/demo

# --durations: the log of every run (CI's too) names the slowest tests.
test: $(STAMP)
	$(PY) -m pytest -n 2 -q --durations=15

test-all: $(STAMP)
	$(PY) -m pytest -n 2 -q -m ""

# The gns benchmark times the shared sand block window, which is not part of
# the repository: make bench SAND_BLOCK_DIR=/path/to/window
bench: $(STAMP)
	@test -n "$(SAND_BLOCK_DIR)" || { echo "make bench needs SAND_BLOCK_DIR=<directory of sand_block_window.npz>" >&2; exit 2; }
	$(PY) -m pip install -q -e ".[bench]"
	$(PY) -m experiments.benchmarks --what=mpm,gns --out=docs/benchmarks --sand_block_dir=$(SAND_BLOCK_DIR)

# The pure-Python wheels an accelerator machine lacks (it has jax, flax, optax,
# orbax-checkpoint, h5py, absl-py, tqdm and matplotlib, and no network), for
# experiments/benchmarks/gpu.sh to install from .whl/ there
# (docs/performance.md).
# jax-md's own needs at import (e3nn-jax, sympy, mpmath, attrs, einops,
# frozendict) are here too; pymatgen is not: jax-md imports it only for its
# materials modules, which gnsjax does not load.
WHEEL_DIR ?= .whl
WHEELS := jraph==0.0.6.dev0 jax-md==0.2.29 e3nn-jax==0.21.0 sympy==1.14.0 \
	mpmath==1.3.0 attrs==26.1.0 einops==0.8.2 frozendict==2.5.1 \
	ml-collections==1.1.0 cma==4.5.0 tensorboardX==2.6.5
WHEEL_PLATFORMS := --platform any --platform manylinux_2_28_x86_64 \
	--platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64

wheels:
	rm -rf $(WHEEL_DIR).tmp && mkdir -p $(WHEEL_DIR).tmp
	$(PYTHON) -m pip download -q --no-deps --only-binary=:all: \
	  --python-version 3.12 --implementation cp $(WHEEL_PLATFORMS) \
	  -d $(WHEEL_DIR).tmp $(WHEELS)
	rm -rf $(WHEEL_DIR) && mv $(WHEEL_DIR).tmp $(WHEEL_DIR)
	@du -ch $(WHEEL_DIR)/*.whl | tail -1 \
	  | sed 's/total/in $(WHEEL_DIR)\/ (at most 64M can travel)/'

clean:
	rm -rf $(VENV) $(OUT) .jax_cache $(WHEEL_DIR)
