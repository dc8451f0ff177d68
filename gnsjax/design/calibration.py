"""Inverse analysis: the sand's friction from an observed final deposit.

Given the final deposit of an avalanche (made by the MPM with material
values the search does not see), find the internal friction angle (deg)
and the basal (ramp and obstacle) Coulomb friction that reproduce it. Both
enter the solver as traced parameters (``mpm.solver.SimParams``), so one
compiled program serves every trial, batched with ``vmap`` and
differentiable.

The misfit compares deposits, not particles: the sand's mass distribution
along x at the last frame (a Gaussian kernel density at ``centres``, so it
is smooth in the parameters), as the mean squared difference relative to
the observed one's mean square. A deposit's mass distribution carries its
runout (basal friction) and its slope (friction angle).

``calibrate`` runs one search (Adam or a baseline) under a budget; the
study that compares them against the hidden truth is
``experiments.studies.calibration``.
"""

import dataclasses
import math
import time
from typing import Any, NamedTuple

from flax import struct
import jax
import jax.numpy as jnp
import numpy as np
import optax

import mpm
from mpm import boundary
from mpm import scene as scene_lib
from mpm import solver
from mpm import transfer
from gnsjax import metrics
from gnsjax.design import baselines

NAMES = ("friction_angle_deg", "basal_friction")
# The ranges searched: the stability study's friction angles (docs/
# tradeoff.md §3) and basal Coulomb coefficients of sand on rough to smooth
# surfaces.
FRICTION_ANGLE_RANGE = (20.0, 50.0)   # deg
BASAL_FRICTION_RANGE = (0.1, 0.9)
BOUNDS = np.array([FRICTION_ANGLE_RANGE, BASAL_FRICTION_RANGE]).T  # [2, 2]


def check(theta) -> np.ndarray:
  """``theta`` [2] as floats, or InputError naming the allowed ranges."""
  theta = np.asarray(theta, np.float64)
  if theta.shape != (2,) or not np.all(np.isfinite(theta)):
    raise scene_lib.InputError(
        f"calibration parameters {theta.tolist()}: expected two finite "
        f"numbers ({', '.join(NAMES)})")
  for name, value, (lo, hi) in zip(NAMES, theta, BOUNDS.T):
    if not lo <= value <= hi:
      raise scene_lib.InputError(
          f"{name} = {value:g}: allowed range [{lo:g}, {hi:g}]")
  return theta


@struct.dataclass
class DepositRollout:
  """The MPM of a scene as a function of its two friction values.

  Attributes:
    state: the initial particle state (traced).
    physics: the other physical parameters and the time step (traced).
    field: the boundary conditions' grid field (traced).
    centres: [K] x positions of the mass distribution (m).
    bandwidth: the kernel's standard deviation (m).
    spec, n_substeps, n_particles, num_frames, max_speed: static.
  """
  state: solver.MPMState
  physics: solver.SimParams
  field: boundary.BoundaryField
  centres: jax.Array
  bandwidth: jax.Array
  spec: transfer.GridSpec = struct.field(pytree_node=False)
  n_substeps: int = struct.field(pytree_node=False)
  n_particles: int = struct.field(pytree_node=False)
  num_frames: int = struct.field(pytree_node=False)
  max_speed: float = struct.field(pytree_node=False)

  @classmethod
  def create(cls, scene: scene_lib.Scene, num_frames: int | None = None,
             bins: int = 64) -> "DepositRollout":
    """The rollout of ``scene`` (host setup only; runs nothing). The mass
    distribution has ``bins`` centres across the domain's width and a
    bandwidth of two particle spacings."""
    s = mpm.setup(scene)
    width = scene.domain.width
    return cls(state=s.state, physics=s.params, field=s.field,
               centres=jnp.linspace(0.0, width, bins),
               bandwidth=jnp.float32(2 * scene.granular.spacing),
               spec=s.spec, n_substeps=s.n_substeps,
               n_particles=s.n_particles,
               num_frames=num_frames or scene.num_frames,
               max_speed=s.max_speed)


def final_positions(sim: DepositRollout, theta: jax.Array, remat: bool = True
                    ) -> tuple[jax.Array, jax.Array, jax.Array]:
  """The last frame's sand [N, 2] (m) at ``theta`` = (friction angle in
  deg, basal friction), with per-frame finite flags and largest speeds
  [T - 1] for ``mpm.check_frames``. Pure and differentiable."""
  physics = sim.physics.replace(
      friction_angle=jnp.deg2rad(theta[0]).astype(jnp.float32),
      boundary_friction=jnp.asarray(theta[1], jnp.float32))
  _, x, max_speed, finite = solver.rollout(
      sim.state, physics, sim.field, sim.spec, sim.num_frames - 1,
      sim.n_substeps, remat=remat)
  return x[-1, :sim.n_particles], finite, max_speed


def mass_distribution(x: jax.Array, centres: jax.Array, bandwidth
                      ) -> jax.Array:
  """The sand's mass fraction per metre along x [K] at ``centres`` [K], a
  Gaussian kernel density of the positions ``x`` [N, 2]."""
  z = (centres[:, None] - x[None, :, 0]) / bandwidth
  norm = bandwidth * math.sqrt(2 * math.pi)
  return jnp.mean(jnp.exp(-0.5 * z**2), -1) / norm


def misfit(x: jax.Array, observed: jax.Array, sim: DepositRollout
           ) -> jax.Array:
  """Mean squared difference of the mass distributions of ``x`` [N, 2] and
  ``observed`` [K], relative to the observed one's mean square."""
  got = mass_distribution(x, sim.centres, sim.bandwidth)
  return jnp.mean((got - observed)**2) / jnp.mean(observed**2)


class Result(NamedTuple):
  """Values [B] and, per trial, finite flags and speeds [B, T - 1]."""
  values: np.ndarray
  finite: np.ndarray
  max_speed: np.ndarray


@jax.jit
def _final(sim, theta):
  return final_positions(sim, theta, remat=False)


@jax.jit
def _batch(sim, thetas, observed):
  def one(theta):
    x, finite, speed = final_positions(sim, theta, remat=False)
    return misfit(x, observed, sim), finite, speed
  return jax.vmap(one)(thetas)


@jax.jit
def _value_and_grad(sim, theta, observed):
  def loss(t):
    x, finite, speed = final_positions(sim, t)
    return misfit(x, observed, sim), (finite, speed)
  return jax.value_and_grad(loss, has_aux=True)(theta)


@dataclasses.dataclass
class Calibration:
  """The misfit of trial frictions against an observed deposit, checked.

  Attributes:
    sim: the rollout of the scene.
    observed: [K] the observed deposit's mass distribution.
    observed_positions: [N, 2] the observed deposit (m), for its front.
    scene: the scene (its name in errors).
    batch_size: trials per vmapped program (shorter batches are padded).
  """
  sim: DepositRollout
  observed: jax.Array
  observed_positions: np.ndarray
  scene: scene_lib.Scene
  batch_size: int = 8

  @classmethod
  def observe(cls, scene: scene_lib.Scene, truth, num_frames=None,
              batch_size: int = 8) -> "Calibration":
    """The calibration problem whose observation is the MPM's deposit at
    ``truth`` = (friction angle deg, basal friction)."""
    sim = DepositRollout.create(scene, num_frames)
    problem = cls(sim, None, None, scene, batch_size)
    x = problem.deposit(truth)
    observed = mass_distribution(jnp.asarray(x), sim.centres, sim.bandwidth)
    return dataclasses.replace(problem, observed=observed,
                               observed_positions=x)

  def deposit(self, theta) -> np.ndarray:
    """The MPM's final sand [N, 2] (m) at one trial, checked."""
    theta = check(theta)
    x, finite, speed = _final(self.sim, jnp.asarray(theta, jnp.float32))
    self._check([theta], [np.asarray(finite)], [np.asarray(speed)])
    return np.asarray(x)

  def front_error(self, theta) -> float:
    """|front - observed front| at one trial over the observed runout
    distance (a fraction; ``gnsjax.metrics.front_error_relative``)."""
    start = np.asarray(self.sim.state.x[:self.sim.n_particles])
    return metrics.front_error_relative(self.deposit(theta),
                                        self.observed_positions, start)

  def _check(self, thetas, finite, speed):
    for t, f, s in zip(thetas, finite, speed):
      mpm.check_frames(f"{self.scene.name} (friction {t[0]:.2f} deg, basal "
                       f"{t[1]:.3f})", 1, f, s, self.sim.max_speed)

  def __call__(self, thetas: np.ndarray) -> np.ndarray:
    """Misfits [B] of trials [B, 2] (one vmapped program per call)."""
    padded, b = baselines.pad_batch(thetas, self.batch_size, "trials")
    values, finite, speed = map(np.asarray, _batch(
        self.sim, jnp.asarray(padded, jnp.float32), self.observed))
    self._check(padded[:b], finite[:b], speed[:b])
    return values[:b].astype(np.float64)

  def value_and_grad(self, theta) -> tuple[float, np.ndarray]:
    """The misfit and its gradient [2] at one trial (pathwise)."""
    theta = np.asarray(theta, np.float64)
    (value, (finite, speed)), grad = _value_and_grad(
        self.sim, jnp.asarray(theta, jnp.float32), self.observed)
    self._check([theta], [np.asarray(finite)], [np.asarray(speed)])
    return float(value), np.asarray(grad, np.float64)


# ------------------------------------------------------------- searching ---

METHODS = ("adam",) + baselines.METHODS


def _to_unit(theta) -> np.ndarray:
  return (np.asarray(theta, np.float64) - BOUNDS[0]) / (BOUNDS[1] - BOUNDS[0])


def _from_unit(u) -> np.ndarray:
  return BOUNDS[0] + np.asarray(u, np.float64) * (BOUNDS[1] - BOUNDS[0])


def adam(problem: Calibration, start, *, budget: baselines.Budget,
         learning_rate: float = 0.05) -> list[dict]:
  """Projected Adam on the pathwise gradient, in the box scaled to
  [0, 1]^2 (``learning_rate`` is a fraction of each range per step); one
  gradient evaluation per step, recorded like the baselines' trace."""
  budget.check()
  opt = optax.adam(learning_rate)
  u = _to_unit(check(start))
  state = opt.init(u)
  trace, best, t0 = [], np.inf, time.perf_counter()
  while True:
    seconds = time.perf_counter() - t0
    if ((budget.seconds is not None and seconds >= budget.seconds) or
        (budget.evaluations is not None and len(trace) >= budget.evaluations)):
      return trace
    theta = _from_unit(u)
    value, grad = problem.value_and_grad(theta)
    best = min(best, value)
    trace.append({"evaluation": len(trace),
                  "seconds": time.perf_counter() - t0,
                  "vector": theta.tolist(), "value": value, "best": best})
    updates, state = opt.update(grad * (BOUNDS[1] - BOUNDS[0]), state, u)
    u = np.clip(optax.apply_updates(u, updates), 0.0, 1.0)


def calibrate(method: str, problem: Calibration, start, *,
              budget: baselines.Budget, learning_rate: float = 0.05,
              points: int = 5, seed: int = 0) -> dict[str, Any]:
  """One search from ``start`` under ``budget`` (after compiling: the
  warm-up call's seconds are reported apart). Returns {"trace", "warmup_s"}.
  """
  if method not in METHODS:
    raise ValueError(f"method: unknown {method!r}; allowed: {list(METHODS)}")
  start = check(start)
  t0 = time.perf_counter()
  if method == "adam":
    problem.value_and_grad(start)
  else:
    problem(start[None])
  warmup = time.perf_counter() - t0
  if method == "adam":
    trace = adam(problem, start, budget=budget, learning_rate=learning_rate)
  else:
    trace = baselines.run(method, problem, BOUNDS[0], BOUNDS[1], start,
                          budget=budget, batch_size=problem.batch_size,
                          seed=seed, points=points)
  return {"trace": trace, "warmup_s": warmup}
