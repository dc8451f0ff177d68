"""Input features and targets of the learned simulator (pure functions).

Shapes: C input frames (6), N nodes (moving particles first, then any static
boundary particles, then padding), E edges. One *learned step* spans
``frame_stride`` stored frames; velocities and accelerations are finite
differences per learned step (m/step, m/step^2), normalised with statistics
of the same stride.

Node features [N, 2 (C - 1) + 3]: the last C - 1 velocities, normalised and
flattened; then what the node sees of the solids, from the scene's signed
distance field (``mpm.SDFGrid``: ramp, obstacles and the domain's walls):
the signed distance phi / S clipped to [-1, 1], and the outward unit normal
weighted by clip(1 - phi / S, 0, 1), which fades to zero at S so the
features are continuous. S is the model's ``solid_range``, by default the
connectivity radius R. Edge features: the displacement x_sender -
x_receiver divided by the connectivity radius R [E, 2] and its norm [E, 1].
The particle type enters the model through a learned embedding.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mpm import geometry


class Stats(NamedTuple):
  """Normalisation statistics per learned step, each [2] (m/step, m/step^2).

  Numpy arrays on the host (``gnsjax.data.load_stats``,
  ``gnsjax.data.stride_stats``), jax arrays inside the model.
  """
  vel_mean: jax.Array
  vel_std: jax.Array
  acc_mean: jax.Array
  acc_std: jax.Array


def fold_noise(stats: Stats, noise_std: float) -> Stats:
  """Statistics whose stds include the training noise: sqrt(std^2 + noise^2).

  As in DeepMind's, geoelements' and LagrangeBench's GNS: the noisy inputs
  the model sees in training, and the corrections it must learn, spread by
  the noise as well as by the data.
  """
  grow = lambda std: (std**2 + noise_std**2)**0.5
  return stats._replace(vel_std=grow(stats.vel_std),
                        acc_std=grow(stats.acc_std))


def unfold_noise(stats: Stats, noise_std: float) -> Stats:
  """The inverse of ``fold_noise``: sqrt(max(std^2 - noise^2, 0))."""
  shrink = lambda std: np.sqrt(np.maximum(np.square(std) - noise_std**2, 0.0))
  return stats._replace(vel_std=shrink(stats.vel_std),
                        acc_std=shrink(stats.acc_std))


def solid_features(position: jax.Array, solids: geometry.SDFGrid,
                   solid_range: float) -> jax.Array:
  """[N, 3]: phi / S clipped to [-1, 1], and the outward normal [N, 2]
  weighted by clip(1 - phi / S, 0, 1), at positions [N, 2] (m), where S =
  ``solid_range`` is the range over which the solids are seen (m)."""
  phi, normal = geometry.sample_sdf(solids, position)
  near = jnp.clip(1.0 - phi / solid_range, 0.0, 1.0)
  return jnp.concatenate([jnp.clip(phi / solid_range, -1.0, 1.0)[:, None],
                          normal * near[:, None]], -1)


def velocities(positions: jax.Array) -> jax.Array:
  """Per-frame velocities [C - 1, N, 2] of positions [C, N, 2]."""
  return positions[1:] - positions[:-1]


def node_features(positions: jax.Array, stats: Stats,
                  solids: geometry.SDFGrid, solid_range: float) -> jax.Array:
  """Node features [N, 2 (C - 1) + 3].

  Args:
    positions: [C, N, 2] input frames (m).
    stats: normalisation statistics.
    solids: the scene's signed distance field.
    solid_range: the range S over which the solids are seen (m): the model's
      ``solid_range``, by default the connectivity radius R.
  """
  v = (velocities(positions) - stats.vel_mean[None, None]) / stats.vel_std[
      None, None]
  v = jnp.transpose(v, (1, 0, 2)).reshape(positions.shape[1], -1)
  return jnp.concatenate(
      [v, solid_features(positions[-1], solids, solid_range)], -1)


def num_node_features(input_frames: int) -> int:
  """F of ``node_features`` for C = ``input_frames``."""
  return 2 * (input_frames - 1) + 3


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


def gate_acceleration(positions: jax.Array, output: jax.Array,
                      stats: Stats) -> jax.Array:
  """Normalised acceleration [N, 2] of a gated model's ``output`` [N, 3]
  (normalised acceleration a, then the gate's logit z): the acceleration
  that makes the next velocity g (v + a), g = sigmoid(z), v the last input
  velocity (``models.EncodeProcessDecode.velocity_gate``)."""
  acc = output[:, :2] * stats.acc_std[None] + stats.acc_mean[None]
  velocity = positions[-1] - positions[-2]
  gate = jax.nn.sigmoid(output[:, 2:])
  gated = gate * (velocity + acc) - velocity
  return (gated - stats.acc_mean[None]) / stats.acc_std[None]


def integrate(positions: jax.Array, normalized_acc: jax.Array,
              stats: Stats) -> jax.Array:
  """Next positions [N, 2] by semi-implicit Euler with dt = 1 learned step.

  v_{t+1} = (x_t - x_{t-1}) + a,  x_{t+1} = x_t + v_{t+1}.
  """
  acc = normalized_acc * stats.acc_std[None] + stats.acc_mean[None]
  velocity = positions[-1] - positions[-2] + acc
  return positions[-1] + velocity
