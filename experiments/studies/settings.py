"""A study's settings, written once: a frozen dataclass whose fields carry
their help text and their bounds.

  @dataclasses.dataclass(frozen=True)
  class Settings(settings.Base):
    scenes: int = settings.field(14, "Held-out scenes.", lower=1)
    spacings: tuple[float, ...] = settings.field(
        (0.01, 0.005), "MPM particle spacings (m).", lower=0, strict=True)

Constructing one checks every field (type, bounds, NaN and infinities,
allowed choices) and then the study's own ``validate`` (relations between
fields), so a library caller and an entry point get the same refusals. The
entry points derive their flags from these fields
(``experiments.runtime.define_flags``): a field ``scenes`` is the flag
``--scenes``, and every message names it so.
"""

import dataclasses
import functools
import math
import os
import typing
from typing import Any

import mpm
from mpm import budget

InputError = mpm.InputError

# The small pretrained model shipped with the project (experiments/configs/
# small.py; see its provenance.json): the default trained run of the studies
# that use one.
PRETRAINED = os.path.join(os.path.dirname(os.path.dirname(__file__)),
                          "pretrained", "small")

_SCALARS = (bool, int, float, str)


def field(default: Any, help: str, *, lower: float | None = None,  # pylint: disable=redefined-builtin
          upper: float | None = None, strict: bool = False,
          choices: tuple[str, ...] | None = None,
          allow_empty: bool = False, distinct: bool = False,
          flag: bool = True):
  """A settings field with its help text and checks.

  Args:
    default: its value when not given (a tuple for sequences).
    help: one line for ``--help``.
    lower, upper: bounds of a number (each element of a sequence).
    strict: the lower bound itself is not allowed.
    choices: the allowed strings (each element of a sequence).
    allow_empty: an empty sequence is allowed.
    distinct: a sequence may not repeat a value.
    flag: False for fields that no flag sets (set by the entry point).
  """
  return dataclasses.field(default=default, metadata={
      "help": help, "lower": lower, "upper": upper, "strict": strict,
      "choices": choices, "allow_empty": allow_empty, "distinct": distinct,
      "flag": flag})


def element_type(annotation) -> tuple[type, bool, bool]:
  """(scalar type, is a sequence, may be None) of a field's annotation."""
  optional = False
  args = typing.get_args(annotation)
  if typing.get_origin(annotation) in (typing.Union, type(int | None)):
    optional = type(None) in args
    (annotation,) = [a for a in args if a is not type(None)]
    args = typing.get_args(annotation)
  if typing.get_origin(annotation) is tuple:
    return args[0], True, optional
  if annotation not in _SCALARS:
    raise TypeError(f"unsupported settings type {annotation!r}")
  return annotation, False, optional


def check_value(name: str, value, kind: type, sequence: bool,
                meta) -> None:
  """Checks one field's value (not None) against its element type
  (``element_type``) and metadata; raises InputError naming ``--name``."""
  if sequence:
    if not isinstance(value, tuple):
      raise InputError(f"--{name}={value}: allowed: a comma-separated list")
    if not value and not meta.get("allow_empty"):
      raise InputError(f"--{name} is empty; allowed: a comma-separated "
                       "list of at least one value")
    for v in value:
      _check_scalar(name, v, kind, meta)
    if meta.get("distinct") and len(set(value)) != len(value):
      choices = meta.get("choices")
      raise InputError(f"--{name}={','.join(map(str, value))}: allowed: "
                       "distinct values"
                       + (f" of {list(choices)}" if choices else ""))
  else:
    _check_scalar(name, value, kind, meta)


def _check_scalar(name: str, value, kind: type, meta) -> None:
  shown = f"--{name}={value}"
  if kind is float or kind is int:
    if isinstance(value, bool) or not isinstance(
        value, int if kind is int else (int, float)):
      raise InputError(f"{shown}: allowed: "
                       f"{'an integer' if kind is int else 'a number'}")
    if not math.isfinite(value):
      raise InputError(f"{shown}: allowed: a finite number")
    lower, upper = meta["lower"], meta["upper"]
    if lower is not None and (value < lower or
                              (meta["strict"] and value == lower)):
      raise InputError(f"{shown}: allowed: "
                       f"{'>' if meta['strict'] else '>='} {lower:g}")
    if upper is not None and value > upper:
      raise InputError(f"{shown}: allowed: <= {upper:g}")
  elif kind is str:
    if not isinstance(value, str):
      raise InputError(f"{shown}: allowed: a string")
    if meta["choices"] is not None and value not in meta["choices"]:
      raise InputError(f"{shown}: allowed: one of {list(meta['choices'])}")
  elif kind is bool and not isinstance(value, bool):
    raise InputError(f"{shown}: allowed: true or false")


def check_fields(settings) -> None:
  """Checks every field of a settings dataclass against its annotation and
  metadata; raises InputError naming ``--field``."""
  hints = typing.get_type_hints(type(settings))
  for f in dataclasses.fields(settings):
    value = getattr(settings, f.name)
    kind, sequence, optional = element_type(hints[f.name])
    meta = f.metadata
    if value is None:
      if not optional:
        raise InputError(f"--{f.name} is required")
      continue
    check_value(f.name, value, kind, sequence, meta)


@dataclasses.dataclass(frozen=True)
class Base:
  """Settings checked on construction: the fields, then ``validate``."""

  def __post_init__(self):
    check_fields(self)
    self.validate()
    self.simulation_seconds  # pylint: disable=pointless-statement (checks)

  def validate(self) -> None:
    """Relations between fields; raises InputError naming the flags."""

  def simulations(self) -> list[budget.Planned]:
    """The MPM simulations these settings ask for (their sizes, named by
    the flags), refused on construction where one cannot fit this
    machine's memory; none by default."""
    return []

  @functools.cached_property
  def simulation_seconds(self) -> float:
    """The estimated CPU seconds of :meth:`simulations` (checked once, on
    construction: ``budget.check_plan`` refuses what cannot fit)."""
    return budget.check_plan(self.simulations())

  def to_dict(self) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else v
            for k, v in dataclasses.asdict(self).items()}
