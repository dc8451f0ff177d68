"""Rollouts of the learned simulator under ``lax.scan``.

``unroll`` is the one pure engine: ``length`` learned steps from a window,
the neighbour list updated inside the scan at every step with a static
capacity, the solid constraint applied after each step (``project``). Its
callers jit it with explicit static arguments: the host drivers below,
inverse design and multi-step training.

The drivers (``rollout``, ``rollout_batch``) run ``unroll`` in chunks of a
fixed number of steps, so one compiled program serves any length. If the
neighbour list overflows at step k, steps k and later of that chunk are
discarded; the host reallocates a larger list from the last good positions
and resumes from step k. Capacities are rounded up to a ladder of sizes
(``graph.rounded_up``), so the compiled programs are few. The result therefore
equals a rollout that had enough capacity from the start (tested).

``rollout_batch`` runs B scenes at once: each is padded to the largest node
count with padding nodes parked on ``graph.parking_positions`` (not moving,
so they keep still and get only their self-edge), and the scan body vmaps the
list update and the step over the scenes; a batched overflow in any scene
rewinds all of them to the same step.

Shapes: C input frames, N nodes (moving particles, then any static boundary
particles), T learned steps, B scenes (batched rollouts carry frames as
[C, B, N, 2]). One learned step spans ``frame_stride`` stored frames.
"""

import functools
from typing import Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from gnsjax import data
from gnsjax import graph
from gnsjax import simulator
from mpm import geometry
from mpm import io as mpm_io
from mpm import simulation

# Type id of the padding nodes of a batched rollout (any valid id: they do not
# move and have no edge but their own, so it never reaches a real node).
_PADDING_TYPE = 0


class SceneNodes(NamedTuple):
  """A scene's start, as a rollout takes it (host arrays).

  Attributes:
    window: float32 [C, N, 2] input frames (m); static nodes repeat their
      position.
    types: int32 [N]; moving: bool [N].
    solids: the scene's signed distance field.

  A pytree: ``unroll`` takes it with device (or traced) arrays too.
  """
  window: np.ndarray
  types: np.ndarray
  moving: np.ndarray
  solids: geometry.SDFGrid


class Rollout(NamedTuple):
  """A rollout's result.

  Attributes:
    positions: float32 [T, N, 2] predicted positions (m).
    pushed: int32 [T] moving nodes the solid constraint pushed out per step.
    depth: float32 [T] the deepest of them before the push (m).
  """
  positions: np.ndarray
  pushed: np.ndarray
  depth: np.ndarray


def unroll(predictor, params, scene: "SceneNodes", nbrs,
           context: simulator.Context, spec: graph.GraphSpec, length: int,
           project: bool = True, batched: bool = False, remat: bool = False,
           update_graph: bool = True):
  """``length`` learned steps from ``window`` (pure; jit it with
  ``predictor``, ``spec``, ``length``, ``project``, ``batched``, ``remat``
  and ``update_graph`` static).

  Differentiable in ``params``, ``window`` and ``solids`` (inverse design);
  the edges are integers, so no gradient flows through the neighbour search.
  The result is piecewise smooth: an edge appears, with a message of full
  size, when two nodes come closer than R.

  Args:
    predictor, params: the simulator (``simulator.ModelPredictor``).
    scene: its start as arrays: window [C, N, 2] input frames (batched:
      [C, B, N, 2]); types int32 [N] and moving bool [N] (batched: [B, N]);
      solids, the SDF grid (batched: values [B, Gx, Gy, 3]).
    nbrs: from ``graph.allocate`` (batched: ``graph.allocate_batch``).
    context: statistics and bounds; spec: graph settings.
    length: L steps.
    project: keep sand out of solids (``simulator.constrain``).
    batched: whether the scene axis B is there.
    remat: rematerialise each step in the backward pass (memory grows with
      the carried state per step, not with the activations).
    update_graph: rebuild the edges every step; without, the edges of
      ``nbrs`` are kept throughout (a smooth function, for checking
      gradients against finite differences).

  Returns:
    (positions [L, (B,) N, 2], carried [L, (B,) N, 2] the last input frame
    of each step as the constraint left it, overflow bool [L] (of any
    scene), the last neighbour list, Projection with [L, (B,)] fields).
  """
  window, types, moving, solids = scene
  n = window.shape[-2]

  def advance(w, nb, ty, mv, so):
    senders, receivers = graph.edges(nb, n)
    g = simulator.Graph(w, ty, mv, senders, receivers, so)
    return simulator.step(predictor, params, g, context, spec.radius,
                          project)

  if batched:
    update = functools.partial(graph.update_batch, spec)
    # Frames stay time-major, so the scene axis of the window is 1.
    advance = jax.vmap(advance, in_axes=(1, 0, 0, 0, 0), out_axes=(0, 0, 0))
  else:
    update = functools.partial(graph.update, spec)

  def body(carry, _):
    w, nb = carry
    if update_graph:
      nb = update(jax.lax.stop_gradient(w[-1]), nb)
    nxt, last, info = advance(w, nb, types, moving, solids)
    w = jnp.concatenate([w[1:-1], last[None], nxt[None]], 0)
    return (w, nb), (nxt, last, jnp.any(nb.did_buffer_overflow), info)

  if remat:
    body = jax.checkpoint(body)
  (_, nbrs), (positions, carried, overflow, info) = jax.lax.scan(
      body, (window, nbrs), None, length=length)
  return positions, carried, overflow, nbrs, info


_unroll = jax.jit(unroll, static_argnames=("predictor", "spec", "length",
                                           "project", "batched"))


def _run_chunks(scan: Callable, allocate: Callable, window: np.ndarray, nbrs,
                n_steps: int, chunk: int, on_reallocate=None):
  """The host loop of a rollout: chunks of scans, rewound on overflow.

  Args:
    scan: (window, nbrs) -> ``unroll``'s outputs, everything else bound.
    allocate: last frame -> a neighbour list sized for it; a reallocation
      rounds it up (``graph.rounded_up``), never below the list it replaces,
      so a process compiles few programs however many scenes it rolls out.
    window: [C, ...] float32 input frames, time first.
    nbrs: the initial neighbour list.
    n_steps: T; chunk: steps per scan.
    on_reallocate: called with the step at which a reallocation happened.

  Returns:
    (positions float32 [T, ...], pushed int32 [T, ...], depth [T, ...]).
  """
  out, pushed, depth = [], [], []
  done = 0
  rewound = False
  while done < n_steps:
    positions, carried, overflow, new_nbrs, info = scan(jnp.asarray(window),
                                                        nbrs)
    positions, carried, overflow = map(np.asarray,
                                       (positions, carried, overflow))
    good = int(np.argmax(overflow)) if overflow.any() else chunk
    good = min(good, n_steps - done)
    if good:
      out.append(positions[:good])
      pushed.append(np.asarray(info.count)[:good])
      depth.append(np.asarray(info.depth)[:good])
      # The carried window: constrained earlier frames, then the last output.
      window = np.concatenate([window[:-1], carried[:good],
                               positions[good - 1:good]])[-window.shape[0]:]
      done += good
    if overflow.any() and done < n_steps and good < chunk:
      # A list allocated for these very positions holds their edges, so a
      # second overflow before any progress would loop forever.
      if rewound and not good:
        raise RuntimeError(f"neighbour list overflowed at step {done} right "
                           "after its reallocation")
      if on_reallocate is not None:
        on_reallocate(done)
      nbrs = graph.rounded_up(allocate(jnp.asarray(window[-1])),
                              at_least=nbrs)
      rewound = True
    else:
      nbrs = new_nbrs
      rewound = False
  return (np.concatenate(out)[:n_steps], np.concatenate(pushed)[:n_steps],
          np.concatenate(depth)[:n_steps])


def _check_scene(scene: SceneNodes, where: str) -> SceneNodes:
  """The scene with host arrays of the right dtypes, or a ValueError naming
  ``where`` and the problem."""
  window = np.asarray(scene.window, np.float32)
  types = np.asarray(scene.types)
  moving = np.asarray(scene.moving)
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
  values = np.asarray(scene.solids.values, np.float32)
  if values.ndim != 3 or values.shape[-1] != 3:
    raise ValueError(f"{where}: solids.values must be [Gx, Gy, 3]; got "
                     f"shape {values.shape}")
  return SceneNodes(window, types.astype(np.int32), moving.astype(bool),
                    scene.solids.replace(values=values))


def rollout(predictor, params, scene: SceneNodes, n_steps: int,
            context: simulator.Context, spec: graph.GraphSpec,
            project: bool = True, chunk: int = 50, nbrs=None,
            on_reallocate=None) -> Rollout:
  """Predicts ``n_steps`` learned steps after a scene's window.

  Args:
    predictor, params: the simulator (``simulator.ModelPredictor(model)``
      and its parameters, or any predictor).
    scene: the start (``trajectory_nodes``).
    n_steps: T.
    context: statistics and bounds; spec: graph settings.
    project: keep sand out of solids after each step.
    chunk: steps per compiled scan.
    nbrs: an initial neighbour list (default: allocated from the window).
    on_reallocate: called with the step at which a reallocation happened.

  Raises:
    ValueError: when the scene's shapes disagree.
  """
  window, types, moving, solids = _check_scene(scene, "rollout")
  allocate = functools.partial(graph.allocate, spec)
  if nbrs is None:
    nbrs = graph.rounded_up(allocate(jnp.asarray(window[-1])))
  types, moving = jnp.asarray(types), jnp.asarray(moving)
  solids = jax.tree.map(jnp.asarray, solids)

  def scan(w, nb):
    return _unroll(predictor, params, SceneNodes(w, types, moving, solids),
                   nb, context, spec=spec, length=chunk, project=project)

  return Rollout(*_run_chunks(scan, allocate, window, nbrs, n_steps, chunk,
                              on_reallocate))


def rollout_batch(predictor, params, scenes: Sequence[SceneNodes],
                  n_steps: int, context: simulator.Context,
                  spec: graph.GraphSpec, project: bool = True,
                  chunk: int = 50, on_reallocate=None,
                  nbrs=None) -> list[Rollout]:
  """Predicts ``n_steps`` learned steps after each of B scenes, at once.

  Every scene is padded to N = max N_b nodes, with padding nodes on
  ``graph.parking_positions`` that do not move and get only their self-edge,
  so each scene's result equals its own ``rollout`` (to float rounding;
  tested). An overflow of any scene's neighbour list rewinds all scenes to
  the step before it and reallocates every list.

  Args:
    predictor, params: the simulator, shared by all scenes.
    scenes: B starts, one C for all, SDF grids of one shape.
    n_steps: T.
    context: statistics and bounds; spec: graph settings. At most
      ``spec.max_padding`` padding nodes fit one scene.
    project: keep sand out of solids after each step.
    chunk: steps per compiled scan.
    on_reallocate: called with the step at which a reallocation happened.
    nbrs: an initial batched list from ``graph.allocate_batch`` of [B, N, 2]
      padded positions (default: allocated from the windows).

  Returns:
    B ``Rollout``s, padding removed.

  Raises:
    ValueError: when there are no scenes, or a scene's shapes are wrong, or
      its C or SDF grid shape differs from the first scene's.
  """
  if not scenes:
    raise ValueError("rollout_batch: no scenes")
  scenes = [_check_scene(sc, f"rollout_batch: scene {b}")
            for b, sc in enumerate(scenes)]
  c = scenes[0].window.shape[0]
  for b, sc in enumerate(scenes):
    if sc.window.shape[0] != c:
      raise ValueError(f"rollout_batch: scene {b} has {sc.window.shape[0]} "
                       f"input frames; scene 0 has {c}")
    if sc.solids.values.shape != scenes[0].solids.values.shape:
      raise ValueError(f"rollout_batch: scene {b}'s SDF grid is "
                       f"{sc.solids.values.shape}; scene 0's is "
                       f"{scenes[0].solids.values.shape} (one domain and "
                       "grid spacing for all)")
  sizes = [len(sc.types) for sc in scenes]
  n = max(sizes)
  padded_w, padded_t, padded_m = [], [], []
  for w, t, m, _ in scenes:
    k = n - len(t)
    park = graph.parking_positions(k, spec)
    padded_w.append(np.concatenate(
        [w, np.broadcast_to(park[None], (c, k, 2))], 1))
    padded_t.append(np.concatenate([t, np.full(k, _PADDING_TYPE, np.int32)]))
    padded_m.append(np.concatenate([m, np.zeros(k, bool)]))
  window = np.stack(padded_w, 1)                          # [C, B, N, 2]
  solids = scenes[0].solids.replace(
      values=jnp.asarray(np.stack([sc.solids.values for sc in scenes])))
  allocate = functools.partial(graph.allocate_batch, spec)
  if nbrs is None:
    nbrs = graph.rounded_up(allocate(jnp.asarray(window[-1])))
  types = jnp.asarray(np.stack(padded_t))
  moving = jnp.asarray(np.stack(padded_m))

  def scan(w, nb):
    return _unroll(predictor, params, SceneNodes(w, types, moving, solids),
                   nb, context, spec=spec, length=chunk, project=project,
                   batched=True)

  positions, pushed, depth = _run_chunks(scan, allocate, window, nbrs,
                                         n_steps, chunk, on_reallocate)
  return [Rollout(np.ascontiguousarray(positions[:, b, :size]),
                  pushed[:, b], depth[:, b])
          for b, size in enumerate(sizes)]


def default_max_batch() -> int | None:
  """Scenes per batched program when the caller does not say: one on the
  CPU, no limit elsewhere. On the CPU a vmapped rollout of the learned
  simulator costs more per scene than one scene alone even without padding
  (14 test scenes of the small model, equal node counts: 1.13-1.2x in
  pairs, 1.2-1.28x in threes, 1.45-1.54x in fives; docs/performance.md):
  its working set outgrows the cache and there is no per-operation
  overhead to share."""
  return simulation.default_max_batch()


def rollout_buckets(predictor, params, scenes: Sequence[SceneNodes],
                    n_steps: int, context: simulator.Context,
                    spec: graph.GraphSpec,
                    bucket_ratio: float = simulation.BUCKET_RATIO,
                    max_batch: int | None = None,
                    **kwargs) -> list[Rollout]:
  """``rollout_batch`` over groups of scenes of similar size.

  Scenes whose node counts are within ``bucket_ratio`` of each other share
  one batched program (``mpm.simulation.size_buckets``, as the MPM's
  ``simulate_batch``), so a small scene is not padded to the largest; a
  group larger than ``max_batch`` runs as several batches (None:
  ``default_max_batch()``, one scene at a time on the CPU). Other keyword
  arguments are ``rollout_batch``'s.

  Returns:
    B ``Rollout``s in the order of ``scenes``.
  """
  out: list[Rollout | None] = [None] * len(scenes)
  for part in simulation.size_batches([len(sc.types) for sc in scenes],
                                      bucket_ratio, max_batch,
                                      "rollout_buckets"):
    results = rollout_batch(predictor, params, [scenes[i] for i in part],
                            n_steps, context, spec, **kwargs)
    for i, result in zip(part, results):
      out[i] = result
  return out


def input_frame_indices(input_frames: int, frame_stride: int) -> np.ndarray:
  """Stored frames [C] a rollout starts from: 0, k, ..., (C - 1) k."""
  return np.arange(input_frames) * frame_stride


def predicted_frame_indices(n_frames: int, input_frames: int,
                            frame_stride: int) -> np.ndarray:
  """Stored frames [T] a rollout from ``input_frame_indices`` predicts:
  (C - 1 + t) k for t = 1 .. T, every one before ``n_frames``."""
  first = (input_frames - 1) * frame_stride
  return np.arange(first + frame_stride, n_frames, frame_stride)


def trajectory_nodes(t: mpm_io.Trajectory, input_frames: int,
                     frame_stride: int = 1, boundary: bool = True,
                     sdf_spacing: float = 0.005, start: int = 0) -> SceneNodes:
  """A window of a stored trajectory: its sand at frames s, s + k, ...,
  s + (C - 1) k (s = ``start``), then (if ``boundary``) its boundary
  particles as static nodes, and its scene's SDF grid at ``sdf_spacing``
  (m)."""
  sand = t.positions[start + input_frame_indices(input_frames, frame_stride)]
  n_sand = t.positions.shape[1]
  if boundary:
    fixed = np.broadcast_to(t.boundary_positions[None],
                            (input_frames,) + t.boundary_positions.shape)
    window = np.concatenate([sand, fixed], 1)
    types = np.concatenate([t.particle_type, t.boundary_type])
  else:
    window, types = sand, t.particle_type
  moving = np.arange(len(types)) < n_sand
  return SceneNodes(window.astype(np.float32), types.astype(np.int32), moving,
                    data.solids_of(t.scene, sdf_spacing))


def rollout_trajectory(model, params, t: mpm_io.Trajectory, problem,
                       n_steps: int | None = None,
                       project: bool = True, start: int = 0) -> Rollout:
  """A stored trajectory rolled out by a trained model from its start, or
  from its frames ``start``, ``start`` + k, ... (``start`` = F - 1 - (C - 1)
  k: from its last frames, the MPM's deposit).

  Args:
    model, params: the network and its parameters.
    t: the trajectory (its (C - 1) k + 1 frames from ``start`` are the
      inputs).
    problem: the run's ``gnsjax.run.Problem`` (stride, features, statistics).
    n_steps: learned steps (default: as many as the trajectory has frames
      for, ``predicted_frame_indices``).
    project: keep sand out of solids.

  Returns:
    The sand's ``Rollout`` (boundary nodes removed); from the start, step t
    is stored frame ``predicted_frame_indices(...)[t]``.
  """
  c, k = problem.input_frames, problem.frame_stride
  if n_steps is None:
    n_steps = len(predicted_frame_indices(len(t.positions) - start, c, k))
  scene = trajectory_nodes(t, c, k, problem.boundary_particles,
                           problem.sdf_spacing, start)
  out = rollout(simulator.ModelPredictor(model), params, scene, n_steps,
                problem.context, problem.spec, project=project)
  return out._replace(positions=out.positions[:, :t.positions.shape[1]])
