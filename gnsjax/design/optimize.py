"""Optimising a placement, and the baselines it is judged against.

``optimise`` runs optax's Adam on a placement, projected back onto the
allowed ranges after every update; ``sweep`` is the brute-force baseline
(forward rollouts over x); ``central_difference`` checks gradients. Each
takes a simulation driver (``rollouts.GNSDriver`` or ``rollouts.MPMDriver``):
anything with ``placement``, ``rollout(params) -> [T, N, 2]`` and
``value_and_grad(objective, params) -> (value, grad, positions)``.
"""

import time
from typing import Any, Callable, Protocol, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import optax

from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts

Params = placement_lib.Params
Objective = Callable[[jax.Array], jax.Array]


class Driver(Protocol):
  """A simulator as a function of the placement, run on the host."""
  placement: placement_lib.AnyPlacement

  def rollout(self, params: Params) -> np.ndarray:
    ...

  def value_and_grad(self, objective: Objective,
                     params: Params) -> tuple[float, Params, np.ndarray]:
    ...


def optimise(simulation: Driver, objective: Objective, params: Params, *,
             steps: int, learning_rate: float,
             log: Callable[[dict], None] | None = None,
             max_seconds: float | None = None,
             plain: Callable[[np.ndarray], float] | None = None,
             step_scale: Params | None = None) -> list[dict]:
  """Projected Adam on the placement.

  Args:
    simulation: a ``GNSDriver`` or ``MPMDriver``.
    objective: positions [T, N, 2] -> [] to minimise.
    params: the starting placement (inside the allowed ranges).
    steps: gradient evaluations (at most, with ``max_seconds``).
    learning_rate: Adam's step size (m per iteration, roughly).
    log: called with each iteration's record.
    max_seconds: no iteration starts after this much wall time (s).
    plain: positions [T, N, 2] (host) -> float, recorded as "plain" per
      iteration: the plain objective of the rollout at the iterate.
    step_scale: multiplies Adam's updates per entry (a pytree like
      ``params``), for parameters of different ranges.

  Returns:
    One record per iteration: iteration, the placement, the objective and
    its gradient there, seconds taken. The best placement is the record
    with the lowest objective.

  Raises:
    FloatingPointError: a gradient that is not finite.
  """
  placement = simulation.placement
  placement.check(params)
  opt = optax.adam(learning_rate)
  state = opt.init(params)
  history = []
  begin = time.perf_counter()
  for i in range(steps):
    if (max_seconds is not None and
        time.perf_counter() - begin >= max_seconds):
      break
    start = time.perf_counter()
    value, grad, positions = simulation.value_and_grad(objective, params)
    record = {"iteration": i, **as_floats(params, ""), "objective": value,
              **({"plain": plain(positions)} if plain is not None else {}),
              **as_floats(grad, "grad_"),
              "seconds": time.perf_counter() - start}
    history.append(record)
    if log is not None:
      log(record)
    if not rollouts.all_finite(grad):
      raise FloatingPointError(f"iteration {i}: the gradient at {params} is "
                               "not finite")
    updates, state = opt.update(grad, state, params)
    if step_scale is not None:
      updates = jax.tree.map(lambda u, c: u * c, updates, step_scale)
    params = placement.project(optax.apply_updates(params, updates))
  return history


def as_floats(params: Params, prefix: str) -> dict[str, Any]:
  """Host floats of a placement for records: ``x`` as ``{prefix}x``, the
  size as ``{prefix}size0`` and ``{prefix}size1`` (arrays flattened in
  row-major order: a ``MultiPlacement``'s x [2] as x0, x1, its size [2, 2]
  as size0..size3)."""
  out = {}
  for k, v in params.items():
    v = np.asarray(v, np.float64)
    if v.ndim == 0:
      out[prefix + k] = float(v)
    else:
      out.update({f"{prefix}{k}{i}": float(a)
                  for i, a in enumerate(v.ravel())})
  return out


def from_record(record: dict, with_size: bool) -> Params:
  """The placement of an ``optimise`` record (the inverse of ``plain``)."""
  params = {"x": np.float32(record["x"])}
  if with_size:
    params["size"] = np.asarray([record["size0"], record["size1"]],
                                np.float32)
  return params


def central_difference(fn: Callable[[Params], float], params: Params,
                       h: float) -> Params:
  """Central differences of a scalar function of a placement, per entry.

  Args:
    fn: placement -> float (host).
    params: where.
    h: the step (m).
  """
  out = {}
  for k, v in params.items():
    v = np.asarray(v, np.float32)
    flat = np.zeros(v.size, np.float64)
    for i in range(v.size):
      e = np.zeros(v.size, np.float32)
      e[i] = h
      e = e.reshape(v.shape)
      plus = fn(dict(params, **{k: jnp.asarray(v + e)}))
      minus = fn(dict(params, **{k: jnp.asarray(v - e)}))
      flat[i] = (plus - minus) / (2 * h)
    out[k] = flat.reshape(v.shape)
  return out


plain = as_floats  # the former name


def sweep(simulation: Driver, objective_plain: Callable[[np.ndarray], float],
          objective_smooth: Objective, params: Params,
          xs: Sequence[float]) -> list[dict]:
  """Forward rollouts over x (the brute-force baseline): each x's plain and
  smooth objective and seconds (the first includes compilation)."""
  rows = []
  for x in xs:
    p = dict(params, x=jnp.float32(x))
    start = time.perf_counter()
    positions = simulation.rollout(p)
    seconds = time.perf_counter() - start
    rows.append({"x": float(x), "plain": objective_plain(positions),
                 "smooth": float(objective_smooth(jnp.asarray(positions))),
                 "seconds": seconds})
  return rows
