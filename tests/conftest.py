"""Suite-wide settings: CPU, strict rank promotion, a shared compilation
cache, programs compiled as the entry points compile them
(runtime.cap_cpu_isa)."""

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")
# The cache, set in the environment: the entry points and scripts the tests
# run as subprocesses share it too, from their first import on (jax_md
# compiles ~120 programs when imported).
_CACHE = os.path.join(os.path.dirname(os.path.dirname(__file__)), ".jax_cache")
os.environ.update(JAX_COMPILATION_CACHE_DIR=_CACHE,
                  JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0",
                  JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES="0")

import jax  # pylint: disable=g-import-not-at-top

from experiments import runtime  # pylint: disable=g-import-not-at-top

runtime.cap_cpu_isa()
jax.config.update("jax_numpy_rank_promotion", "raise")
