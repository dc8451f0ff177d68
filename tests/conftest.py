"""Suite-wide settings: CPU, strict rank promotion, a shared compilation
cache, quick compilation, the entry points' instruction set
(runtime.cap_cpu_isa)."""

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")
# The cache, set in the environment: the entry points and scripts the tests
# run as subprocesses share it too.
_CACHE = os.path.join(os.path.dirname(os.path.dirname(__file__)), ".jax_cache")
os.environ.update(JAX_COMPILATION_CACHE_DIR=_CACHE,
                  JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0",
                  JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES="0")

# Compiling is most of the suite's time: the tests (and the entry points
# they run) compile with LLVM at -O0 and XLA's classic fusion emitters, which
# compute the same (the MPM's chunk program compiles in 3.6 s against 6.0 s
# with the new emitters); run by hand, the entry points keep XLA's defaults.
# A test that looks at how production fuses (the op profile's scatters)
# compiles its program with production's emitters.
QUICK_XLA_FLAGS = ("--xla_backend_optimization_level=0",
                   "--xla_cpu_use_fusion_emitters=false")
_flags = os.environ.get("XLA_FLAGS", "").split()
os.environ["XLA_FLAGS"] = " ".join(
    _flags + [f for f in QUICK_XLA_FLAGS if f not in _flags])

import jax  # pylint: disable=g-import-not-at-top

from experiments import runtime  # pylint: disable=g-import-not-at-top

runtime.cap_cpu_isa()
jax.config.update("jax_numpy_rank_promotion", "raise")

# The costliest files first (their CPU seconds, docs/performance.md): under
# `--dist loadfile` the two workers then end together, on small files.
_FIRST = ("tests/experiments/entry_points_test.py",
          "tests/gnsjax/design/rollouts_test.py",
          "tests/gnsjax/rollout_test.py",
          "tests/gnsjax/train_test.py",
          "tests/gnsjax/solids_test.py",
          "tests/experiments/inverse_design_test.py",
          "tests/gnsjax/design/smoothing_test.py",
          "tests/gnsjax/distributed_test.py",
          "tests/experiments/bad_input_test.py",
          "tests/experiments/gns_entry_points_test.py",
          "tests/experiments/pareto_test.py",
          "tests/experiments/evaluation_test.py")


def pytest_collection_modifyitems(items):
  rank = {path: i for i, path in enumerate(_FIRST)}
  items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0],
                                       len(_FIRST)))
