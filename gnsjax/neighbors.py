"""jax-md's neighbour lists (``partition``, ``space``) without the rest of
jax-md.

``import jax_md`` runs ``jax_md/__init__.py``, which imports every one of
its submodules: ``jax_md.rigid_body`` runs jax operations at import (so it
compiles, and starts jax's backend) and ``jax_md.energy`` pulls in e3nn_jax
and scipy.signal. On this project's 2-core CPU that is about 6 CPU-seconds
in every process that builds a graph, most of a bad-input refusal's time.
``partition`` and ``space`` need only ``jax_md.util`` and
``jax_md.dataclasses``.

So, unless jax_md is already imported, its package is registered without
running its ``__init__``; the package's ``__getattr__`` imports any other
submodule on first use, so ``import jax_md; jax_md.energy`` and
``from jax_md import simulate`` still work in the same process.
"""

import importlib
import importlib.util
import sys


def _register_package_without_init() -> None:
  if "jax_md" in sys.modules:
    return
  spec = importlib.util.find_spec("jax_md")
  if spec is None:
    raise ImportError("jax-md is not installed (pip install jax-md)")
  package = importlib.util.module_from_spec(spec)  # __path__, not executed

  def submodule(name: str):
    if name.startswith("__"):
      raise AttributeError(f"module 'jax_md' has no attribute {name!r}")
    return importlib.import_module(f"jax_md.{name}")

  package.__getattr__ = submodule
  sys.modules["jax_md"] = package


_register_package_without_init()

# pylint: disable=g-import-not-at-top,wrong-import-position
from jax_md import partition  # noqa: E402
from jax_md import space  # noqa: E402

__all__ = ["partition", "space"]
