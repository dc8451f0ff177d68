"""Rollouts of the learned simulator under ``lax.scan``.

The neighbour list is updated inside the scan at every step, with a static
capacity. If it overflows at step k, steps k and later of that chunk are
discarded; the host reallocates a larger list from the last good positions and
resumes from step k. The result therefore equals a rollout that had enough
capacity from the start (tested). Rollouts run in chunks of a fixed number of
steps, so one compiled program serves any length.

Shapes: C input frames, N nodes (moving particles, then static boundary
particles), T steps.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from gnsjax import graph
from gnsjax import simulator
from mpm import io as mpm_io


@functools.partial(jax.jit, static_argnames=("predictor", "spec", "length"))
def _scan(predictor, params, window, types, moving, nbrs, context, spec,
          length):
  """``length`` steps from ``window`` [C, N, 2]; returns positions [L, N, 2],
  overflow flags [L] and the last neighbour list."""
  n = window.shape[1]

  def body(carry, _):
    w, nb = carry
    nb = graph.update(spec, w[-1], nb)
    senders, receivers = graph.edges(nb, n)
    nxt = simulator.step(predictor, params, w, types, moving, senders,
                         receivers, context, spec.radius)
    w = jnp.concatenate([w[1:], nxt[None]], 0)
    return (w, nb), (nxt, nb.did_buffer_overflow)

  (_, nbrs), (positions, overflow) = jax.lax.scan(
      body, (window, nbrs), None, length=length)
  return positions, overflow, nbrs


def rollout(predictor, params, window: np.ndarray, types: np.ndarray,
            moving: np.ndarray, n_steps: int, context: simulator.Context,
            spec: graph.GraphSpec, chunk: int = 50, nbrs=None,
            on_reallocate=None) -> np.ndarray:
  """Predicts ``n_steps`` frames after ``window``.

  Args:
    predictor, params: the simulator (``simulator.ModelPredictor(model)``
      and its parameters, or any predictor).
    window: [C, N, 2] input frames (m); static nodes repeat their position.
    types: int32 [N]; moving: bool [N].
    n_steps: T.
    context: statistics and bounds; spec: graph settings.
    chunk: steps per compiled scan.
    nbrs: an initial neighbour list (default: allocated from ``window``).
    on_reallocate: called with the step at which a reallocation happened.

  Returns:
    float32 [T, N, 2] predicted positions.
  """
  window = np.asarray(window, np.float32)
  if nbrs is None:
    nbrs = graph.allocate(spec, jnp.asarray(window[-1]))
  out = []
  done = 0
  while done < n_steps:
    positions, overflow, new_nbrs = _scan(
        predictor, params, jnp.asarray(window), jnp.asarray(types),
        jnp.asarray(moving), nbrs, context, spec, chunk)
    positions, overflow = np.asarray(positions), np.asarray(overflow)
    good = int(np.argmax(overflow)) if overflow.any() else chunk
    good = min(good, n_steps - done)
    if good:
      out.append(positions[:good])
      window = np.concatenate([window, positions[:good]])[-window.shape[0]:]
      done += good
    if overflow.any() and done < n_steps and good < chunk:
      if on_reallocate is not None:
        on_reallocate(done)
      nbrs = graph.allocate(spec, jnp.asarray(window[-1]))
    else:
      nbrs = new_nbrs
  return np.concatenate(out)[:n_steps]


def trajectory_nodes(t: mpm_io.Trajectory, input_frames: int):
  """(window [C, N, 2], types [N], moving [N]) of a stored trajectory's
  start: its sand then all its boundary particles."""
  sand = t.positions[:input_frames]
  boundary = np.broadcast_to(t.boundary_positions[None],
                             (input_frames,) + t.boundary_positions.shape)
  window = np.concatenate([sand, boundary], 1)
  types = np.concatenate([t.particle_type, t.boundary_type]).astype(np.int32)
  moving = np.arange(len(types)) < t.positions.shape[1]
  return window, types, moving


def rollout_trajectory(model, params, t: mpm_io.Trajectory, problem,
                       n_steps: int, input_frames: int) -> np.ndarray:
  """Predicted sand positions [n_steps, Ns, 2] from a trajectory's first
  ``input_frames`` frames."""
  window, types, moving = trajectory_nodes(t, input_frames)
  pred = rollout(simulator.ModelPredictor(model), params, window, types,
                 moving, n_steps, problem.context, problem.spec)
  return pred[:, :t.positions.shape[1]]
