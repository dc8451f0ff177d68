"""The learned simulator on one window: graph, features, model, loss, step.

Pure functions of arrays; the caller jits them. Shapes: C input frames,
N nodes (padded), E edges (capacity of the neighbour list), Gx x Gy nodes of
the scene's signed distance grid.
"""

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp

from gnsjax import features
from gnsjax import models
from gnsjax import noise as noise_lib
from mpm import geometry


class Context(NamedTuple):
  """What the model needs besides the window (traced arrays).

  Attributes:
    stats: normalisation statistics per learned step (noise folded in if
      the run was trained so).
  """
  stats: features.Stats


class Graph(NamedTuple):
  """One window as the model sees it (a pytree; jraph's GraphsTuple holds
  latents, this holds the physical inputs they are encoded from).

  Attributes:
    positions: [C, N, 2] input frames (m); static nodes repeat their position.
    particle_type: int32 [N].
    moving: bool [N], the nodes the model advances (sand).
    senders, receivers: int32 [E] edges of the last frame; padding entries
      point one past the last node.
    solids: the scene's signed distance field (values [Gx, Gy, 3]).
  """
  positions: jax.Array
  particle_type: jax.Array
  moving: jax.Array
  senders: jax.Array
  receivers: jax.Array
  solids: geometry.SDFGrid


def predict(model: models.EncodeProcessDecode, params, graph: Graph,
            context: Context, radius: float) -> jax.Array:
  """Normalised accelerations [N, 2] of a window (a gated model's gate
  applied)."""
  node_f = features.node_features(graph.positions, context.stats,
                                  graph.solids, model.seen_solid_range(radius))
  edge_f = features.edge_features(graph.positions[-1], graph.senders,
                                  graph.receivers, radius)
  out = model.apply(params, node_f, graph.particle_type, edge_f,
                    graph.senders, graph.receivers)
  if model.velocity_gate:
    return features.gate_acceleration(graph.positions, out, context.stats)
  return out


@dataclasses.dataclass(frozen=True)
class ModelPredictor:
  """Predictor of normalised accelerations by the learned model.

  A predictor is a hashable callable ``(params, graph, context, radius) ->
  [N, 2]``; rollouts take it as a static argument, so the same machinery runs
  the model, or an oracle in tests.
  """
  model: models.EncodeProcessDecode

  def __call__(self, params, graph, context, radius):
    return predict(self.model, params, graph, context, radius)


class Projection(NamedTuple):
  """How the solid constraint acted in one step.

  Attributes:
    count: [] int32, moving nodes pushed out of a solid.
    depth: [] float32, the deepest of them before the push (m, >= 0).
  """
  count: jax.Array
  depth: jax.Array


# Pushes per learned step: where two solids meet (an obstacle on the ramp),
# the push out of one can enter the other, and near a polygon's corner the
# grid's interpolated normal blends two faces; a few more pushes from where
# the last one landed reach the free space (measured: one push left sand
# inside there, see the corner tests).
PUSHES = 4


def constrain(previous: jax.Array, proposed: jax.Array, moving: jax.Array,
              solids: geometry.SDFGrid, pushes: int = PUSHES):
  """Keeps sand out of solids: the MPM's push-out, for a learned step.

  A moving node whose proposed position is inside a solid (phi < 0: ramp,
  obstacle, outside the domain) moves back to the surface along the outward
  normal, and the inward normal part of its last displacement is removed
  (its previous position slides along the normal, so the next step's input
  velocity has none); repeated ``pushes`` times from where the last push
  landed. Differentiable; nodes outside solids are untouched.

  Args:
    previous: [N, 2] positions before the step (m).
    proposed: [N, 2] positions the model predicts (m).
    moving: bool [N]; static nodes are never moved.
    solids: the scene's signed distance field.
    pushes: pushes per step (static), at least 1.

  Returns:
    (positions [N, 2], previous [N, 2], Projection of the first push).
  """
  positions = proposed
  info = None
  for _ in range(pushes):
    phi, normal = geometry.sample_sdf(solids, positions)
    inside = moving & (phi < 0)
    normal = normal * inside[:, None]
    if info is None:
      info = Projection(jnp.sum(inside).astype(jnp.int32),
                        jnp.max(jnp.where(inside, -phi, 0.0), initial=0.0))
    positions = geometry.push_out(positions, phi, normal)
    v_n = jnp.sum((positions - previous) * normal, -1)
    previous = previous + jnp.minimum(v_n, 0.0)[:, None] * normal
  return positions, previous, info


def step(predictor, params, graph: Graph, context: Context, radius: float,
         project: bool = True):
  """One learned step.

  Args:
    predictor, params: the simulator.
    graph: the window.
    context: statistics and bounds.
    radius: connectivity radius R (m).
    project: apply ``constrain`` (static).

  Returns:
    (next positions [N, 2], last input frame [N, 2] (changed by the
    constraint), Projection). Static nodes stay where they are.
  """
  acc = predictor(params, graph, context, radius)
  last = graph.positions[-1]
  nxt = features.integrate(graph.positions, acc, context.stats)
  nxt = jnp.where(graph.moving[:, None], nxt, last)
  if not project:
    return nxt, last, Projection(jnp.zeros((), jnp.int32), jnp.zeros(()))
  return constrain(last, nxt, graph.moving, graph.solids)


def add_noise(key: jax.Array, window: jax.Array, moving: jax.Array,
              noise_std: float, solids: geometry.SDFGrid | None = None
              ) -> tuple[jax.Array, jax.Array]:
  """Noisy inputs [C, N, 2] and the adjusted target [N, 2] of a window.

  The target moves with the last input frame's noise (the model undoes the
  velocity noise, not the position's). Noise that carries a particle at a
  wall into the solid carries its target there too, so the model learns
  that sand may sit inside a solid. With ``solids`` the adjusted target is
  pushed back out to the surface (``constrain``'s push): the model learns
  to step out of a solid it finds itself in.

  Args:
    window: [C + 1, N, 2], the inputs then the target.
    moving: bool [N]; only moving particles get noise.
    solids: the scene's signed distance field, or None (targets unchanged).
  """
  inputs, target = window[:-1], window[-1]
  n = noise_lib.random_walk(key, inputs.shape, noise_std)
  n = n * moving[None, :, None]
  return inputs + n, shift_target(target, n[-1], moving, solids)


def shift_target(target: jax.Array, offset: jax.Array, moving: jax.Array,
                 solids: geometry.SDFGrid | None = None) -> jax.Array:
  """A true frame [N, 2] moved by the last input frame's noise ``offset``
  [N, 2] (``add_noise``), and with ``solids`` pushed back out to their
  surface. Pushforward's target is the true frame P steps on moved so:
  the noise shifts every later frame, as in LagrangeBench."""
  target = target + offset
  if solids is not None:
    target, _, _ = constrain(target, target, moving, solids)
  return target


def loss(model, params, graph: Graph, target: jax.Array, context: Context,
         radius: float) -> jax.Array:
  """MSE of normalised acceleration over the moving particles [].

  Args:
    graph: the window's (noisy) inputs; target: [N, 2] next positions (m).
  """
  acc = predict(model, params, graph, context, radius)
  want = features.target_acceleration(graph.positions, target, context.stats)
  err = jnp.sum((acc - want)**2, -1) * graph.moving
  return jnp.sum(err) / jnp.maximum(jnp.sum(graph.moving), 1) / 2
