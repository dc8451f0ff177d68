"""The learned simulator on one window: graph, features, model, loss, step.

Pure functions of arrays; the caller jits them. Shapes: C input frames,
N nodes (padded), E edges (capacity of the neighbour list).
"""

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp

from gnsjax import features
from gnsjax import models
from gnsjax import noise as noise_lib


class Context(NamedTuple):
  """What the model needs besides the state (all traced arrays).

  Attributes:
    stats: normalisation statistics.
    bounds: [2, 2] domain [[x_min, x_max], [y_min, y_max]] (m).
  """
  stats: features.Stats
  bounds: jax.Array


def predict(model: models.EncodeProcessDecode, params, positions: jax.Array,
            particle_type: jax.Array, senders: jax.Array,
            receivers: jax.Array, context: Context,
            radius: float) -> jax.Array:
  """Normalised accelerations [N, 2] from input positions [C, N, 2]."""
  node_f = features.node_features(positions, context.stats, context.bounds,
                                  radius)
  edge_f = features.edge_features(positions[-1], senders, receivers, radius)
  return model.apply(params, node_f, particle_type, edge_f, senders,
                     receivers)


@dataclasses.dataclass(frozen=True)
class ModelPredictor:
  """Predictor of normalised accelerations by the learned model.

  A predictor is a hashable callable
  ``(params, positions [C, N, 2], particle_type, senders, receivers, context,
  radius) -> [N, 2]``; rollouts take it as a static argument, so the same
  machinery runs the model, or an oracle in tests.
  """
  model: models.EncodeProcessDecode

  def __call__(self, params, positions, particle_type, senders, receivers,
               context, radius):
    return predict(self.model, params, positions, particle_type, senders,
                   receivers, context, radius)


def step(predictor, params, positions, particle_type, moving, senders,
         receivers, context, radius) -> jax.Array:
  """Next positions [N, 2]: moving nodes advance, the others stay."""
  acc = predictor(params, positions, particle_type, senders, receivers,
                  context, radius)
  nxt = features.integrate(positions, acc, context.stats)
  return jnp.where(moving[:, None], nxt, positions[-1])


def add_noise(key: jax.Array, window: jax.Array, moving: jax.Array,
              noise_std: float) -> tuple[jax.Array, jax.Array]:
  """Noisy inputs [C, N, 2] and the adjusted target [N, 2] of a window.

  Args:
    window: [C + 1, N, 2], the inputs then the target.
    moving: bool [N]; only moving particles get noise.
  """
  inputs, target = window[:-1], window[-1]
  n = noise_lib.random_walk(key, inputs.shape, noise_std)
  n = n * moving[None, :, None]
  return inputs + n, noise_lib.adjust_target(target, n)


def loss(model, params, inputs, target, particle_type, moving, senders,
         receivers, context, radius) -> jax.Array:
  """MSE of normalised acceleration over the moving particles []."""
  acc = predict(model, params, inputs, particle_type, senders, receivers,
                context, radius)
  want = features.target_acceleration(inputs, target, context.stats)
  err = jnp.sum((acc - want)**2, -1) * moving
  return jnp.sum(err) / jnp.maximum(jnp.sum(moving), 1) / 2
