"""Process-wide settings shared by the entry points."""

import os

import jax


def enable_compilation_cache(path: str | None = None) -> str:
  """Caches compiled XLA programs on disk, so reruns skip compilation.

  Returns:
    The cache directory (``$GNSJAX_CACHE_DIR`` or ~/.cache/gnsjax/jax).
  """
  path = path or os.environ.get("GNSJAX_CACHE_DIR") or os.path.join(
      os.path.expanduser("~"), ".cache", "gnsjax", "jax")
  jax.config.update("jax_compilation_cache_dir", path)
  jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
  return path
