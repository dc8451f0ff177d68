"""Suite-wide settings: CPU, strict rank promotion, a shared compilation cache
(for programs compiled as the entry points compile them: runtime.cap_cpu_isa,
which also reaches the entry points the tests run as subprocesses)."""

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax  # pylint: disable=g-import-not-at-top

from experiments import runtime  # pylint: disable=g-import-not-at-top

runtime.cap_cpu_isa()
_CACHE = os.path.join(os.path.dirname(os.path.dirname(__file__)), ".jax_cache")
jax.config.update("jax_compilation_cache_dir", _CACHE)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
jax.config.update("jax_numpy_rank_promotion", "raise")
