"""Input features and targets of the learned simulator (pure functions).

Shapes: C input frames (6), N nodes (moving particles first, then static
boundary particles, then padding), E edges. Velocities and accelerations are
finite differences per frame (m/frame, m/frame^2), normalised with the
dataset's statistics.

Node features: the last C - 1 velocities, normalised, flattened [N, 2(C-1)];
then the distances to the four domain walls divided by the connectivity
radius R and clipped to [-1, 1] [N, 4]. Edge features: the displacement
x_sender - x_receiver divided by R [E, 2] and its norm [E, 1]. The particle
type enters the model through a learned embedding.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp


class Stats(NamedTuple):
  """Normalisation statistics, each [2] (see ``gnsjax.data.load_stats``)."""
  vel_mean: jax.Array
  vel_std: jax.Array
  acc_mean: jax.Array
  acc_std: jax.Array


def velocities(positions: jax.Array) -> jax.Array:
  """Per-frame velocities [C - 1, N, 2] of positions [C, N, 2]."""
  return positions[1:] - positions[:-1]


def node_features(positions: jax.Array, stats: Stats, bounds: jax.Array,
                  radius: float) -> jax.Array:
  """Node features [N, 2 (C - 1) + 4].

  Args:
    positions: [C, N, 2] input frames (m).
    stats: normalisation statistics.
    bounds: [2, 2] domain [[x_min, x_max], [y_min, y_max]] (m).
    radius: connectivity radius R (m).
  """
  v = (velocities(positions) - stats.vel_mean[None, None]) / stats.vel_std[
      None, None]
  v = jnp.transpose(v, (1, 0, 2)).reshape(positions.shape[1], -1)
  last = positions[-1]
  walls = jnp.concatenate([last - bounds[None, :, 0], bounds[None, :, 1] - last],
                          -1)
  return jnp.concatenate([v, jnp.clip(walls / radius, -1.0, 1.0)], -1)


def edge_features(position: jax.Array, senders: jax.Array,
                  receivers: jax.Array, radius: float) -> jax.Array:
  """Edge features [E, 3] from the last input positions [N, 2] (m)."""
  d = (position[senders] - position[receivers]) / radius
  # The norm's gradient at a self-edge (d = 0) would be 0/0: inverse design
  # differentiates with respect to positions.
  sq = jnp.sum(d * d, -1, keepdims=True)
  norm = jnp.where(sq > 0, jnp.sqrt(jnp.where(sq > 0, sq, 1.0)), 0.0)
  return jnp.concatenate([d, norm], -1)


def target_acceleration(positions: jax.Array, target: jax.Array,
                        stats: Stats) -> jax.Array:
  """Normalised acceleration [N, 2] that takes the inputs to ``target``.

  Args:
    positions: [C, N, 2] input frames; target: [N, 2] next positions.
  """
  acc = target - 2 * positions[-1] + positions[-2]
  return (acc - stats.acc_mean[None]) / stats.acc_std[None]


def integrate(positions: jax.Array, normalized_acc: jax.Array,
              stats: Stats) -> jax.Array:
  """Next positions [N, 2] by semi-implicit Euler with dt = 1 frame.

  v_{t+1} = (x_t - x_{t-1}) + a,  x_{t+1} = x_t + v_{t+1}.
  """
  acc = normalized_acc * stats.acc_std[None] + stats.acc_mean[None]
  velocity = positions[-1] - positions[-2] + acc
  return positions[-1] + velocity
