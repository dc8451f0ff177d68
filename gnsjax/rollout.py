"""Rollouts of the learned simulator under ``lax.scan``.

The neighbour list is updated inside the scan at every step, with a static
capacity. If it overflows at step k, steps k and later of that chunk are
discarded; the host reallocates a larger list from the last good positions and
resumes from step k. The result therefore equals a rollout that had enough
capacity from the start (tested). Rollouts run in chunks of a fixed number of
steps, so one compiled program serves any length.

``rollout_batch`` runs B scenes at once: each is padded to the largest node
count with padding nodes parked on ``graph.parking_positions`` (not moving,
so they keep still and get only their self-edge), and the scan body vmaps the
list update and the step over the scenes. Both share the chunk, overflow and
resume loop (``_run_chunks``) and the scan (``_scan``); a batched overflow in
any scene rewinds all of them to the same step.

Shapes: C input frames, N nodes (moving particles, then static boundary
particles), T steps, B scenes (batched rollouts carry frames as [C, B, N, 2]).
"""

import functools
from typing import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from gnsjax import graph
from gnsjax import simulator
from mpm import io as mpm_io

# Type id of the padding nodes of a batched rollout (any valid id: they do not
# move and have no edge but their own, so it never reaches a real node).
_PADDING_TYPE = 0


@functools.partial(jax.jit,
                   static_argnames=("predictor", "spec", "length", "batched"))
def _scan(predictor, params, window, types, moving, nbrs, context, spec,
          length, batched=False):
  """``length`` steps from ``window`` [C, N, 2] (batched: [C, B, N, 2]).

  Returns positions [L, N, 2] (batched: [L, B, N, 2]), overflow flags [L]
  (batched: of any scene) and the last neighbour list. ``types`` and
  ``moving`` are [N] (batched: [B, N]); ``nbrs`` comes from
  ``graph.allocate`` (batched: ``graph.allocate_batch``).
  """
  n = window.shape[-2]

  def advance(w, nb, ty, mv):
    senders, receivers = graph.edges(nb, n)
    return simulator.step(predictor, params, w, ty, mv, senders, receivers,
                          context, spec.radius)

  if batched:
    update = functools.partial(graph.update_batch, spec)
    # Frames stay time-major, so the scene axis of the window is 1.
    advance = jax.vmap(advance, in_axes=(1, 0, 0, 0))
  else:
    update = functools.partial(graph.update, spec)

  def body(carry, _):
    w, nb = carry
    nb = update(w[-1], nb)
    nxt = advance(w, nb, types, moving)
    w = jnp.concatenate([w[1:], nxt[None]], 0)
    return (w, nb), (nxt, jnp.any(nb.did_buffer_overflow))

  (_, nbrs), (positions, overflow) = jax.lax.scan(
      body, (window, nbrs), None, length=length)
  return positions, overflow, nbrs


def _run_chunks(scan: Callable, allocate: Callable, window: np.ndarray, nbrs,
                n_steps: int, chunk: int, on_reallocate=None) -> np.ndarray:
  """The host loop of a rollout: chunks of scans, rewound on overflow.

  Args:
    scan: (window, nbrs) -> (positions [chunk, ...], overflow [chunk], nbrs),
      ``_scan`` with everything else bound.
    allocate: last frame -> a neighbour list sized for it.
    window: [C, ...] float32 input frames, time first.
    nbrs: the initial neighbour list.
    n_steps: T; chunk: steps per scan.
    on_reallocate: called with the step at which a reallocation happened.

  Returns:
    float32 [T, ...] positions.
  """
  out = [np.zeros((0,) + window.shape[1:], np.float32)]
  done = 0
  rewound = False
  while done < n_steps:
    positions, overflow, new_nbrs = scan(jnp.asarray(window), nbrs)
    positions, overflow = np.asarray(positions), np.asarray(overflow)
    good = int(np.argmax(overflow)) if overflow.any() else chunk
    good = min(good, n_steps - done)
    if good:
      out.append(positions[:good])
      window = np.concatenate([window, positions[:good]])[-window.shape[0]:]
      done += good
    if overflow.any() and done < n_steps and good < chunk:
      # A list allocated for these very positions holds their edges, so a
      # second overflow before any progress would loop forever.
      if rewound and not good:
        raise RuntimeError(f"neighbour list overflowed at step {done} right "
                           "after its reallocation")
      if on_reallocate is not None:
        on_reallocate(done)
      nbrs = allocate(jnp.asarray(window[-1]))
      rewound = True
    else:
      nbrs = new_nbrs
      rewound = False
  return np.concatenate(out)[:n_steps]


def _check_scene(window, types, moving, where: str):
  """(window [C, N, 2] float32, types [N] int32, moving [N] bool) of one
  scene, or a ValueError naming ``where`` and the problem."""
  window = np.asarray(window, np.float32)
  types = np.asarray(types)
  moving = np.asarray(moving)
  if window.ndim != 3 or window.shape[-1] != 2 or not all(window.shape):
    raise ValueError(f"{where}: window must be [C, N, 2] with C, N >= 1; got "
                     f"shape {window.shape}")
  n = window.shape[1]
  if types.shape != (n,):
    raise ValueError(f"{where}: types must be [N] = [{n}]; got shape "
                     f"{types.shape}")
  if moving.shape != (n,):
    raise ValueError(f"{where}: moving must be [N] = [{n}]; got shape "
                     f"{moving.shape}")
  return window, types.astype(np.int32), moving.astype(bool)


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

  Raises:
    ValueError: when the shapes of window, types and moving disagree.
  """
  window, types, moving = _check_scene(window, types, moving, "rollout")
  allocate = functools.partial(graph.allocate, spec)
  if nbrs is None:
    nbrs = allocate(jnp.asarray(window[-1]))
  scan = functools.partial(
      _scan, predictor, params, types=jnp.asarray(types),
      moving=jnp.asarray(moving), context=context, spec=spec, length=chunk)
  return _run_chunks(lambda w, nb: scan(window=w, nbrs=nb), allocate, window,
                     nbrs, n_steps, chunk, on_reallocate)


def rollout_batch(predictor, params, windows: Sequence[np.ndarray],
                  types: Sequence[np.ndarray], moving: Sequence[np.ndarray],
                  n_steps: int, context: simulator.Context,
                  spec: graph.GraphSpec, chunk: int = 50, on_reallocate=None,
                  nbrs=None) -> list[np.ndarray]:
  """Predicts ``n_steps`` frames after each of B scenes' windows, at once.

  Every scene is padded to N = max N_b nodes, with padding nodes on
  ``graph.parking_positions`` that do not move and get only their self-edge,
  so each scene's result equals its own ``rollout`` (to float rounding;
  tested). An overflow of any scene's neighbour list rewinds all scenes to
  the step before it and reallocates every list.

  Args:
    predictor, params: the simulator, shared by all scenes.
    windows: B arrays [C, N_b, 2] of input frames (m), one C for all.
    types: B int32 arrays [N_b]; moving: B bool arrays [N_b].
    n_steps: T.
    context: statistics and bounds; spec: graph settings. At most
      ``spec.max_padding`` padding nodes fit one scene.
    chunk: steps per compiled scan.
    on_reallocate: called with the step at which a reallocation happened.
    nbrs: an initial batched list from ``graph.allocate_batch`` of [B, N, 2]
      padded positions (default: allocated from the windows).

  Returns:
    B float32 arrays [T, N_b, 2] of predicted positions, padding removed.

  Raises:
    ValueError: when the lists differ in length or are empty, or a scene's
      shapes are wrong or its C differs from the first scene's.
  """
  if not len(windows) == len(types) == len(moving):
    raise ValueError("rollout_batch: windows, types and moving must be lists "
                     f"of one length (one entry per scene); got {len(windows)}"
                     f", {len(types)} and {len(moving)}")
  if not windows:
    raise ValueError("rollout_batch: no scenes")
  scenes = [_check_scene(w, t, m, f"rollout_batch: scene {b}")
            for b, (w, t, m) in enumerate(zip(windows, types, moving))]
  c = scenes[0][0].shape[0]
  for b, (w, _, _) in enumerate(scenes):
    if w.shape[0] != c:
      raise ValueError(f"rollout_batch: scene {b} has {w.shape[0]} input "
                       f"frames; scene 0 has {c}")
  sizes = [len(t) for _, t, _ in scenes]
  n = max(sizes)
  padded_w, padded_t, padded_m = [], [], []
  for w, t, m in scenes:
    k = n - len(t)
    park = graph.parking_positions(k, spec)
    padded_w.append(np.concatenate(
        [w, np.broadcast_to(park[None], (c, k, 2))], 1))
    padded_t.append(np.concatenate([t, np.full(k, _PADDING_TYPE, np.int32)]))
    padded_m.append(np.concatenate([m, np.zeros(k, bool)]))
  window = np.stack(padded_w, 1)                          # [C, B, N, 2]
  allocate = functools.partial(graph.allocate_batch, spec)
  if nbrs is None:
    nbrs = allocate(jnp.asarray(window[-1]))
  scan = functools.partial(
      _scan, predictor, params, types=jnp.asarray(np.stack(padded_t)),
      moving=jnp.asarray(np.stack(padded_m)), context=context, spec=spec,
      length=chunk, batched=True)
  out = _run_chunks(lambda w, nb: scan(window=w, nbrs=nb), allocate, window,
                    nbrs, n_steps, chunk, on_reallocate)
  return [np.ascontiguousarray(out[:, b, :size])
          for b, size in enumerate(sizes)]


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
