"""Gradients of an objective smoothed in the design parameters.

Over a whole avalanche the pathwise derivative of an objective f(theta) is
exact and still a poor descent direction: f is continuous but full of kinks
(contact, stick and slip, plastic branches) that the flow multiplies, so its
slope at theta says little about its change over any finite step
(``docs/inverse_design.md``). The Gaussian smoothing

    F_sigma(theta) = E[f(theta + sigma * eps)],   eps ~ N(0, I),

is as smooth as the Gaussian whatever f is, and its gradient is the slope of
f at the scale sigma. Two Monte Carlo estimators of grad F_sigma, both over
antithetic pairs (eps, -eps), which cancel the odd part of the noise:

- ``pathwise`` (first order, reparameterisation): mean of grad f(theta +
  sigma eps). Needs f differentiable almost everywhere; exact for a
  quadratic with a single pair. It inherits the pathwise bias where f
  jumps (a step's derivative is zero almost everywhere).
- ``score`` (zeroth order, score function / Gaussian smoothing, as in
  evolution strategies): mean of (f(theta + sigma eps) - f(theta - sigma
  eps)) eps / (2 sigma). Forward runs only; unbiased for F_sigma even when f
  jumps, at a variance that grows with the number of parameters.

``sigma`` is the user's scale, in the parameters' units (m for positions and
sizes): a scalar, or one value per parameter (a pytree like ``params``).
Through the MPM the samples are vmapped, so one compiled program evaluates
them all (the MPM batches well); through the learned simulator
(``looped_smoothed_value_and_grad``) they run one at a time. Perturbed
designs outside the allowed ranges are the caller's concern: the drivers'
versions project them onto the placement's ranges (the projection's
derivative is zero outside).
"""

import functools
from typing import Callable

import jax
import jax.numpy as jnp
from jax import flatten_util
import numpy as np

from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts

Params = placement_lib.Params
ESTIMATORS = ("pathwise", "score")


def check_num_samples(num_samples: int) -> None:
  """Raises ValueError unless ``num_samples`` is even and >= 2."""
  if num_samples < 2 or num_samples % 2:
    raise ValueError(f"num_samples = {num_samples}; allowed: an even "
                     "number >= 2 (antithetic pairs)")


def perturbations(key: jax.Array, params: Params, num_samples: int
                  ) -> jax.Array:
  """Standard normal directions [num_samples, P] in antithetic pairs (row
  2i + 1 = -row 2i), P the number of scalar parameters."""
  check_num_samples(num_samples)
  flat, _ = flatten_util.ravel_pytree(params)
  half = jax.random.normal(key, (num_samples // 2, flat.size), flat.dtype)
  return jnp.stack([half, -half], axis=1).reshape(num_samples, flat.size)


def smoothed_value_and_grad(fn: Callable[[Params], jax.Array], params: Params,
                            key: jax.Array, *, sigma, num_samples: int,
                            estimator: str = "pathwise"
                            ) -> tuple[jax.Array, Params, Params]:
  """Monte Carlo estimates of F_sigma(params) and its gradient (pure).

  Args:
    fn: params -> [] (traceable; differentiable for ``pathwise``).
    params: where (a dict of arrays).
    key: the random key of the perturbations.
    sigma: smoothing scale(s), in the parameters' units: a scalar or a pytree
      like ``params``.
    num_samples: perturbed designs (even: antithetic pairs).
    estimator: ``"pathwise"`` or ``"score"``.

  Returns:
    (the mean of f over the perturbed designs, the gradient estimate, and
    its standard error from the spread of the pairs' estimates), the last
    two as pytrees like ``params``.
  """
  _check_estimator(estimator)
  flat, unravel = flatten_util.ravel_pytree(params)
  scale = _flat_sigma(sigma, params, flat)
  eps = perturbations(key, params, num_samples)
  thetas = flat[None] + scale[None] * eps                       # [S, P]
  flat_fn = lambda theta: fn(unravel(theta))
  if estimator == "pathwise":
    values, grads = jax.vmap(jax.value_and_grad(flat_fn))(thetas)
  else:
    values, grads = jax.vmap(flat_fn)(thetas), None
  value, grad, stderr = _estimate(values, grads, eps, scale)
  return value, unravel(grad), unravel(stderr)


def _check_estimator(estimator: str) -> None:
  if estimator not in ESTIMATORS:
    raise ValueError(f"estimator = {estimator!r}; allowed: {ESTIMATORS}")


def _estimate(values, grads, eps, scale):
  """(mean value, gradient, standard error) [P] from the values [S] (and,
  pathwise, the gradients [S, P]) at the designs theta + scale * eps."""
  if grads is not None:
    pairs = jnp.mean(grads.reshape(-1, 2, eps.shape[1]), axis=1)  # [S/2, P]
  else:
    # Antithetic pairs: (f(+) - f(-)) / 2 per pair, times its direction.
    v = values.reshape(-1, 2)
    pairs = ((v[:, 0] - v[:, 1]) / 2)[:, None] * eps[::2] / scale[None]
  grad = jnp.mean(pairs, axis=0)
  stderr = jnp.std(pairs, axis=0, ddof=1) / jnp.sqrt(pairs.shape[0]) \
      if pairs.shape[0] > 1 else jnp.full_like(grad, jnp.nan)
  return jnp.mean(values), grad, stderr


def _flat_sigma(sigma, params: Params, flat: jax.Array) -> jax.Array:
  if isinstance(sigma, dict):
    scale, _ = flatten_util.ravel_pytree(
        {k: jnp.broadcast_to(jnp.asarray(sigma[k], flat.dtype),
                             jnp.shape(v)) for k, v in params.items()})
  else:
    scale = jnp.full_like(flat, sigma)
  if not isinstance(scale, jax.core.Tracer) and not np.all(
      np.asarray(scale) > 0):
    raise ValueError(f"sigma = {sigma}; allowed: > 0 (the parameters' units, "
                     "m for positions and sizes)")
  return scale


@functools.partial(jax.jit, static_argnames=("objective", "num_samples",
                                             "estimator"))
def _mpm_smoothed(sim, params, key, sigma, objective, num_samples, estimator):
  def fn(p):
    x, _, _ = rollouts.mpm_positions(sim, sim.placement.project(p))
    return objective(x)

  return smoothed_value_and_grad(fn, params, key, sigma=sigma,
                                 num_samples=num_samples, estimator=estimator)


def mpm_smoothed_value_and_grad(sim: rollouts.MPMRollout, objective,
                                params: Params, key: jax.Array, *, sigma,
                                num_samples: int = 16,
                                estimator: str = "pathwise"
                                ) -> tuple[float, Params, Params]:
  """F_sigma, its gradient and the gradient's standard error through the
  MPM (``smoothed_value_and_grad``), the samples batched (vmap).

  Each perturbed design is projected onto the placement's allowed ranges.
  ``objective`` (positions [T, N, 2] -> []) is a static argument: pass the
  same function object each time to reuse the compiled program.

  Raises:
    FloatingPointError: a value or gradient that is not finite, naming the
      scene and the placement.
  """
  sim.placement.check(params)
  _flat_sigma(sigma, params, flatten_util.ravel_pytree(params)[0])
  value, grad, stderr = _mpm_smoothed(sim, params, key, sigma, objective,
                                      num_samples, estimator)
  _check_finite(sim.placement, estimator, params, value, grad)
  return float(value), grad, stderr


def _check_finite(placement, estimator: str, params: Params, value,
                  grad) -> None:
  if not (np.isfinite(value) and rollouts.all_finite(grad)):
    raise FloatingPointError(
        f"{placement.scene.name}: the smoothed ({estimator}) objective or its "
        f"gradient at {jax.tree.map(np.asarray, params)} is not finite")


def driver_smoothed_value_and_grad(driver, objective, params: Params,
                                   key: jax.Array, *, sigma,
                                   num_samples: int = 16,
                                   estimator: str = "pathwise"
                                   ) -> tuple[float, Params, Params]:
  """``smoothed_value_and_grad`` through a driver: an ``MPMDriver``'s designs
  as one batch (``mpm_smoothed_value_and_grad``), any other's
  (``rollouts.GNSDriver``) one at a time (``looped_smoothed_value_and_grad``).
  """
  if isinstance(driver, rollouts.MPMDriver):
    return mpm_smoothed_value_and_grad(
        driver.sim, objective, params, key, sigma=sigma,
        num_samples=num_samples, estimator=estimator)
  return looped_smoothed_value_and_grad(
      driver, objective, params, key, sigma=sigma, num_samples=num_samples,
      estimator=estimator)


def looped_smoothed_value_and_grad(driver, objective, params: Params,
                                   key: jax.Array, *, sigma,
                                   num_samples: int = 16,
                                   estimator: str = "pathwise"
                                   ) -> tuple[float, Params, Params]:
  """``smoothed_value_and_grad`` through any driver, one perturbed design at
  a time on the host.

  The same perturbations, projection and estimates as the batched MPM
  version; the learned simulator's driver keeps a neighbour list on the
  host (grown on overflow), so its designs run one after another.

  Raises:
    FloatingPointError: a value or gradient that is not finite.
  """
  _check_estimator(estimator)
  placement = driver.placement
  placement.check(params)
  flat, unravel = flatten_util.ravel_pytree(params)
  scale = _flat_sigma(sigma, params, flat)
  eps = perturbations(key, params, num_samples)
  values, grads = [], []
  for theta in np.asarray(flat[None] + scale[None] * eps):
    # The projection's derivative (zero across a bound) as in the batch.
    p, pullback = jax.vjp(placement.project, unravel(jnp.asarray(theta)))
    if estimator == "pathwise":
      value, grad, _ = driver.value_and_grad(objective, p)
      grads.append(flatten_util.ravel_pytree(pullback(grad)[0])[0])
    else:
      value = float(objective(jnp.asarray(driver.rollout(p))))
    values.append(value)
  value, grad, stderr = _estimate(jnp.asarray(values),
                                  jnp.stack(grads) if grads else None, eps,
                                  scale)
  _check_finite(placement, estimator, params, value, grad)
  return float(value), unravel(grad), unravel(stderr)


class SmoothedDriver:
  """A driver whose gradients are smoothed (for ``optimize.optimise``).

  ``value_and_grad`` returns the smoothed objective F_sigma and its
  estimated gradient (``driver_smoothed_value_and_grad``: the MPM's designs
  batched, the GNS's one at a time); each call draws new perturbations (the
  key is the seed folded with the call count, so a run is reproducible).
  """

  def __init__(self, driver, *, sigma, num_samples: int = 16,
               estimator: str = "score", seed: int = 0):
    _check_estimator(estimator)
    check_num_samples(num_samples)
    self.driver, self.sigma = driver, sigma
    self.num_samples, self.estimator = num_samples, estimator
    self._key, self._calls = jax.random.key(seed), 0

  @property
  def placement(self) -> placement_lib.AnyPlacement:
    return self.driver.placement

  def rollout(self, params: Params) -> np.ndarray:
    return self.driver.rollout(params)

  def value_and_grad(self, objective, params: Params
                     ) -> tuple[float, Params, np.ndarray]:
    """(F_sigma, its gradient estimate, positions [T, N, 2] at ``params``)."""
    key = jax.random.fold_in(self._key, self._calls)
    self._calls += 1
    value, grad, _ = driver_smoothed_value_and_grad(
        self.driver, objective, params, key, sigma=self.sigma,
        num_samples=self.num_samples, estimator=self.estimator)
    return value, grad, self.driver.rollout(params)
