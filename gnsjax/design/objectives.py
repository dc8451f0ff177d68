"""Objectives of an avalanche, as pure functions of a rollout (inverse design).

Each objective maps sand positions [T, N, 2] (metres; frame 0 is the
initial state, the sand flows toward smaller x) to a scalar that inverse
design minimises. Where the plain definition is piecewise constant or has
kinks in the positions, the differentiable objective is a smooth surrogate
with a temperature (metres); the plain value is kept beside it for reporting:

- ``runout``: how far the avalanche front travels, front(0) - front(T-1).
  The front is the smallest x, smoothed as a soft minimum
  -tau log sum_i exp(-x_i / tau); the soft minimum lies below the minimum by
  at most tau log N, and the difference front(0) - front(T-1) cancels most
  of that. The plain value takes the 1% quantile (``gnsjax.metrics.runout``).
- ``passed_fraction``: the mass fraction that ends beyond a protected line,
  x < x_p. The plain fraction is a step function of each position (zero
  gradient almost everywhere); the surrogate counts each particle by
  sigmoid((x_p - x_i) / tau).
- ``centroid``: squared distance (m^2) between the deposit's centroid x and a
  target x. Smooth as it is.

All particles carry equal mass (the lattice spacing is uniform), so mass
fractions are particle fractions.
"""

import dataclasses
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from gnsjax import metrics

# Default temperatures (m): about one particle spacing of the small config.
RUNOUT_TEMPERATURE = 0.01
FRACTION_TEMPERATURE = 0.01


def soft_min(values: jax.Array, temperature: float) -> jax.Array:
  """Smooth minimum [] of values [N]: -tau logsumexp(-v / tau) <= min(v)."""
  return -temperature * jax.nn.logsumexp(-values / temperature)


def runout(positions: jax.Array,
           temperature: float = RUNOUT_TEMPERATURE) -> jax.Array:
  """Distance [] (m) the soft front travels from frame 0 to the last frame."""
  return (soft_min(positions[0, :, 0], temperature) -
          soft_min(positions[-1, :, 0], temperature))


def passed_fraction(positions: jax.Array, x_protect: float,
                    temperature: float = FRACTION_TEMPERATURE) -> jax.Array:
  """Smooth fraction [] of the sand beyond x < x_protect at the last frame."""
  return jnp.mean(jax.nn.sigmoid((x_protect - positions[-1, :, 0]) /
                                 temperature))


def centroid(positions: jax.Array, target_x: float) -> jax.Array:
  """(mean x of the last frame - target_x)^2 [] (m^2)."""
  return (jnp.mean(positions[-1, :, 0]) - target_x)**2


@dataclasses.dataclass(frozen=True)
class Objective:
  """A named objective: the smooth function to minimise and its plain value.

  Attributes:
    name: "runout", "passed_fraction" or "centroid".
    smooth: positions [T, N, 2] -> [] (differentiable).
    plain: positions [T, N, 2] (numpy) -> float, the non-smoothed value.
    unit: of both values.
  """
  name: str
  smooth: Callable[[jax.Array], jax.Array]
  plain: Callable[[np.ndarray], float]
  unit: str


NAMES = ("runout", "passed_fraction", "centroid")


def _named(fn: Callable, name: str) -> Callable:
  """``fn`` with ``__name__`` ``name`` (error messages name the objective)."""
  fn.__name__ = fn.__qualname__ = name
  return fn


def make(name: str, *, x_protect: float = 0.6, target_x: float = 0.6,
         temperature: float | None = None) -> Objective:
  """The objective ``name`` with its parameters.

  Args:
    name: one of ``NAMES``.
    x_protect: the protected line (m) of "passed_fraction".
    target_x: the target centroid x (m) of "centroid".
    temperature: of the smooth surrogate (m); default per objective.

  Raises:
    ValueError: an unknown name or a non-positive temperature.
  """
  if temperature is not None and not temperature > 0:
    raise ValueError(f"temperature = {temperature}: must be > 0 (metres)")
  if name == "runout":
    tau = temperature or RUNOUT_TEMPERATURE
    return Objective(
        name, _named(lambda p: runout(p, tau), name),
        lambda p: float(metrics.runout(p[0]) - metrics.runout(p[-1])), "m")
  if name == "passed_fraction":
    tau = temperature or FRACTION_TEMPERATURE
    return Objective(
        name, _named(lambda p: passed_fraction(p, x_protect, tau), name),
        lambda p: float(np.mean(np.asarray(p)[-1, :, 0] < x_protect)), "")
  if name == "centroid":
    return Objective(
        name, _named(lambda p: centroid(p, target_x), name),
        lambda p: float((np.mean(np.asarray(p)[-1, :, 0]) - target_x)**2),
        "m^2")
  raise ValueError(f"objective: unknown {name!r}; allowed: {list(NAMES)}")
