"""Frozen dataclasses that are JAX pytrees, with static (shape-setting) fields.

After jax-md's ``dataclasses.py``: a field is a traced array leaf unless it is
declared with :func:`static_field`, in which case it is hashable metadata that
changes the compiled program when it changes.
"""

import dataclasses
from typing import TypeVar

import jax

T = TypeVar("T")


def static_field(**kwargs):
  """A dataclass field stored as pytree metadata (static under ``jit``)."""
  metadata = dict(kwargs.pop("metadata", {}))
  metadata["static"] = True
  return dataclasses.field(metadata=metadata, **kwargs)


def pytree_dataclass(cls: type[T]) -> type[T]:
  """Makes ``cls`` a frozen dataclass registered as a pytree.

  Fields made with :func:`static_field` become metadata; all others are leaves.
  The class gains ``replace(**changes)``.
  """
  cls = dataclasses.dataclass(frozen=True)(cls)
  fields = dataclasses.fields(cls)
  data = [f.name for f in fields if not f.metadata.get("static")]
  meta = [f.name for f in fields if f.metadata.get("static")]
  jax.tree_util.register_dataclass(cls, data_fields=data, meta_fields=meta)
  cls.replace = dataclasses.replace
  return cls
