"""Both simulators as pure, differentiable functions of a placement.

Each simulator is described by a frozen pytree dataclass: its arrays are
leaves (traced under ``jit``), its settings (``num_frames``, the placement,
the grid or graph spec, the model) static metadata, so they are part of
every compiled program's cache key: a rollout with other settings is another
object, and another program. A pure function of that description returns the
sand's positions [T, N, 2] (m; frame 0 the initial state):

- ``gns_positions(GNSRollout, ...)``: the obstacle's boundary particles are
  ``mpm.geometry.boundary_nodes`` of its parameters; ramp particles it covers
  are parked out of reach (``gnsjax.graph.parking_positions``), so the node
  count stays static while it moves. The learned simulator rolls out under
  ``lax.scan``.
- ``mpm_positions(MPMRollout, ...)``: the obstacle's signed distance function
  sets the grid's boundary field (``mpm.boundary.make_field``); the field
  lists every node the obstacle can reach anywhere in its range, so one
  compiled program serves every placement.

Each step (GNS) or frame (MPM) is rematerialised in the backward pass
(``jax.checkpoint``): memory grows with the carried state per step, not with
the activations. Model and physical parameters are constants of the
gradient; only the placement is differentiated.

``GNSDriver`` and ``MPMDriver`` are the host-side boundary (``gns_driver``
loads a trained model's): they jit those functions (module-level programs,
every input an argument), check MPM frames (``mpm.check_frames``) and grow
an overflowing neighbour list. A gradient that is not finite is an error
(``FloatingPointError``) that names the scene and the first frame from which
it is not finite: found by bisection over truncated rollouts, so it costs
only when it fails.
"""

import dataclasses
import functools
import math
from typing import Callable

from flax import struct
import jax
import jax.numpy as jnp
import numpy as np

import mpm
from gnsjax import graph
from gnsjax import rollout as rollout_lib
from gnsjax import run as run_lib
from gnsjax import simulator
from gnsjax.design import placement as placement_lib
from mpm import boundary
from mpm import geometry
from mpm import solver
from mpm import transfer

Params = placement_lib.Params
Objective = Callable[[jax.Array], jax.Array]

# -------------------------------------------------- non-finite gradients ---


def all_finite(tree) -> bool:
  """Whether every leaf of ``tree`` (e.g. a gradient) is finite (host)."""
  return all(np.all(np.isfinite(np.asarray(g))) for g in jax.tree.leaves(tree))


def _first_bad(finite_at: Callable[[int], bool], n: int) -> int:
  """The k in [1, n] where ``finite_at`` turns False, by bisection; assumes
  finite_at(0) and not finite_at(n)."""
  lo, hi = 0, n
  while hi - lo > 1:
    mid = (lo + hi) // 2
    if finite_at(mid):
      lo = mid
    else:
      hi = mid
  return hi


def _gradient_error(scene: mpm.Scene, objective: Objective, grad: Params,
                    frame: int) -> FloatingPointError:
  keys = [k for k, g in grad.items() if not all_finite(g)]
  name = getattr(objective, "__name__", None) or repr(objective)
  return FloatingPointError(
      f"scene {scene.name}: the gradient of {name} w.r.t. {', '.join(keys)} "
      f"is not finite from frame {frame} (the rollout cut after frame "
      f"{frame - 1} gives a finite one)")


# ------------------------------------------------------------------- GNS ---


def mpm_window(scene: mpm.Scene, input_frames: int,
               frame_stride: int = 1) -> np.ndarray:
  """The MPM's frames 0, k, ..., (C - 1) k of ``scene``: float32 [C, Ns, 2]
  (m), the inputs of a learned simulator of stride k.

  The obstacle does not reach the sand before the avalanche is released, so
  one window serves every placement. Runs the MPM (seconds): compute it once
  and pass it to ``GNSRollout.create``.
  """
  frames = (input_frames - 1) * frame_stride + 1
  result = mpm.simulate(dataclasses.replace(scene, num_frames=frames))
  return result.positions[::frame_stride].astype(np.float32)


@struct.dataclass
class GNSRollout:
  """The learned simulator as a function of the placement (a pytree).

  Nodes: Ns sand; if the model takes boundary particles, then Nr ramp
  particles (those under the designed obstacle parked), the other
  obstacles' No outline particles, and the designed obstacle's P outline
  particles (P fixed by its initial size). The solids the model sees (its
  SDF features and the solid constraint) are the scene's SDF grid at the
  placement, so the rollout is differentiable in it either way.

  Attributes:
    window: float32 [C, Ns, 2] the input frames (m), ``mpm_window``'s.
    ramp: the ramp (traced arrays, static kind).
    ramp_points: float32 [Nr, 2] ramp particles no other obstacle covers (m).
    parking: float32 [Nr, 2] where ramp particles under the designed
      obstacle go (m).
    other_outlines: float32 [No, 2] the other obstacles' outlines (m).
    fractions: float32 [P] outline fractions of the designed obstacle.
    types: int32 [N] particle types; moving: bool [N], the sand.
    context: the model's statistics and bounds (traced).
    placement: what is designed (static).
    predictor: ``simulator.ModelPredictor`` of the model (static).
    spec: the radius graph (static).
    num_frames: stored frames the rollout covers, the C inputs included
      (static); the learned steps are every ``frame_stride``-th of them.
    frame_stride: stored frames per learned step (static).
    boundary: whether boundary particles are nodes (static).
    sdf_spacing: the SDF grid's node spacing (m) (static).
  """
  window: jax.Array
  ramp: geometry.RampParams
  ramp_points: jax.Array
  parking: jax.Array
  other_outlines: jax.Array
  fractions: jax.Array
  types: jax.Array
  moving: jax.Array
  context: simulator.Context
  placement: placement_lib.Placement = struct.field(pytree_node=False)
  predictor: simulator.ModelPredictor = struct.field(pytree_node=False)
  spec: graph.GraphSpec = struct.field(pytree_node=False)
  num_frames: int = struct.field(pytree_node=False)
  frame_stride: int = struct.field(pytree_node=False, default=1)
  boundary: bool = struct.field(pytree_node=False, default=True)
  sdf_spacing: float = struct.field(pytree_node=False, default=0.005)

  @classmethod
  def create(cls, placement: placement_lib.Placement, model, problem,
             window: np.ndarray, num_frames: int | None = None
             ) -> "GNSRollout":
    """The rollout of ``placement`` (host; runs no simulation).

    Args:
      placement: what is designed.
      model: the learned simulator (``gnsjax.models``).
      problem: ``gnsjax.run.Problem`` (statistics, bounds, graph spec,
        stride, node choice).
      window: [C, Ns, 2] input frames (m), from ``mpm_window``.
      num_frames: stored frames T (default the scene's); the rollout needs
        at least one learned step.
    """
    if not isinstance(placement, placement_lib.Placement):
      raise ValueError("the GNS designs one obstacle (a Placement); several "
                       "obstacles run on the MPM only")
    scene = placement.scene
    window = np.asarray(window, np.float32)
    num_frames = num_frames or scene.num_frames
    k = problem.frame_stride
    if not len(rollout_lib.predicted_frame_indices(num_frames,
                                                   window.shape[0], k)):
      raise ValueError(f"num_frames = {num_frames}: must exceed the "
                       f"{window.shape[0]} input frames at stride {k} "
                       f"(frame {(window.shape[0] - 1) * k})")
    ns = window.shape[1]
    if problem.boundary_particles:
      # What stays put is the scene's own boundary without the designed
      # obstacle: the ramp it leaves uncovered and the other outlines.
      fixed, fixed_types = mpm.boundary_particles(placement.fixed_scene())
      ramp_points = fixed[fixed_types == mpm.RAMP_TYPE]
      others = fixed[fixed_types == mpm.OBSTACLE_TYPE]
      fractions = geometry.outline_fractions(geometry.outline_size(
          placement.obstacle, scene.granular.spacing))
    else:
      ramp_points = others = np.zeros((0, 2), np.float32)
      fractions = np.zeros((0,), np.float32)
    nr, nb = len(ramp_points), len(ramp_points) + len(others) + len(
        fractions)
    types = np.concatenate([
        np.full(ns, mpm.SAND_TYPE), np.full(nr, mpm.RAMP_TYPE),
        np.full(nb - nr, mpm.OBSTACLE_TYPE)]).astype(np.int32)
    return cls(
        window=window, ramp=geometry.ramp_params(scene.ramp),
        ramp_points=ramp_points,
        parking=graph.parking_positions(nr, problem.spec).astype(np.float32),
        other_outlines=others, fractions=fractions, types=types,
        moving=np.arange(ns + nb) < ns, context=problem.context,
        placement=placement, predictor=simulator.ModelPredictor(model),
        spec=problem.spec, num_frames=num_frames, frame_stride=k,
        boundary=problem.boundary_particles, sdf_spacing=problem.sdf_spacing)

  @property
  def n_sand(self) -> int:
    return self.window.shape[1]

  @property
  def n_steps(self) -> int:
    """Learned steps after the input frames."""
    return len(rollout_lib.predicted_frame_indices(
        self.num_frames, self.window.shape[0], self.frame_stride))


def gns_boundary(sim: GNSRollout, params: Params) -> jax.Array:
  """Boundary node positions [Nb, 2] (m) for the placement ``params``."""
  if not sim.boundary:
    return jnp.zeros((0, 2), sim.window.dtype)
  nodes = geometry.boundary_nodes(
      sim.ramp, (sim.placement.obstacle_params(params),), sim.ramp_points,
      (sim.fractions,), sim.parking)
  return jnp.concatenate([nodes.ramp, sim.other_outlines, nodes.outlines[0]])


def gns_nodes(sim: GNSRollout, params: Params) -> jax.Array:
  """The last input frame of every node [N, 2] (m)."""
  return jnp.concatenate([sim.window[-1], gns_boundary(sim, params)])


def gns_solids(sim: GNSRollout, params: Params) -> geometry.SDFGrid:
  """The scene's SDF grid at the placement ``params`` (differentiable)."""
  domain = sim.placement.scene.domain
  return geometry.sdf_grid(sim.ramp, sim.placement.obstacles(params),
                           domain.width, domain.height, sim.sdf_spacing)


def gns_positions(sim: GNSRollout, params: Params, model_params, nbrs,
                  remat: bool = True, update_graph: bool = True
                  ) -> tuple[jax.Array, jax.Array]:
  """Sand positions [C + L, Ns, 2] and whether the neighbour list
  overflowed; frame i > C - 1 is stored frame i k.

  Pure and differentiable in ``params``: ``rollout.unroll`` (with the solid
  constraint) from the window, with the boundary nodes and SDF grid of the
  placement. With ``update_graph=False`` the edges of ``nbrs`` are kept
  throughout, a smooth function for checking gradients against finite
  differences.

  Args:
    sim: the rollout (traced arrays; static settings).
    params: the placement (traced).
    model_params: the model's weights (traced).
    nbrs: a neighbour list of the N nodes; its capacities are static.
    remat: rematerialise each step in the backward pass (static).
    update_graph: rebuild the edges every step (static).
  """
  c = sim.window.shape[0]
  boundary_nodes = gns_boundary(sim, params)
  nodes = jnp.concatenate([
      sim.window,
      jnp.broadcast_to(boundary_nodes[None], (c,) + boundary_nodes.shape)], 1)
  scene = rollout_lib.SceneNodes(nodes, sim.types, sim.moving,
                                 gns_solids(sim, params))
  positions, _, overflow, _, _ = rollout_lib.unroll(
      sim.predictor, model_params, scene, nbrs, sim.context, sim.spec,
      sim.n_steps, project=True, remat=remat, update_graph=update_graph)
  return (jnp.concatenate([sim.window, positions[:, :sim.n_sand]]),
          jnp.any(overflow))


@jax.jit
def _gns_forward(sim, params, model_params, nbrs):
  return gns_positions(sim, params, model_params, nbrs, remat=False)


@functools.partial(jax.jit, static_argnames="objective")
def _gns_value_and_grad(sim, params, model_params, nbrs, objective):
  def loss(p):
    positions, overflow = gns_positions(sim, p, model_params, nbrs)
    return objective(positions), (positions, overflow)

  (value, (positions, overflow)), grad = jax.value_and_grad(
      loss, has_aux=True)(params)
  return value, grad, positions, overflow


class GNSDriver:
  """Runs a ``GNSRollout`` on the host, never truncating its graph.

  Holds the neighbour list (``nbrs``, host state passed to the jitted
  programs as an argument): a rollout that overflows it is repeated with a
  larger one (a recompilation).
  """

  def __init__(self, sim: GNSRollout, model_params, nbrs=None):
    """
    Args:
      sim: the rollout.
      model_params: the model's weights.
      nbrs: a neighbour list of the N nodes (default: allocated for the
        initial placement).
    """
    self.sim = sim
    self.model_params = model_params
    self._extra_capacity = 0
    self.nbrs = nbrs if nbrs is not None else self._allocate()

  @property
  def placement(self) -> placement_lib.Placement:
    return self.sim.placement

  def _allocate(self):
    return graph.allocate(
        self.sim.spec, gns_nodes(self.sim, self.placement.initial()),
        extra_capacity=self._extra_capacity)

  def _grow(self):
    """Reallocates the neighbour list with more headroom."""
    n = self.nbrs.reference_position.shape[0]
    self._extra_capacity += max(1, math.ceil(0.25 * self.nbrs.idx.shape[-1] /
                                             n))
    self.nbrs = self._allocate()

  def _run(self, program, params, *static):
    while True:
      out = program(self.sim, params, self.model_params, self.nbrs, *static)
      if not bool(out[-1]):
        return out[:-1]
      self._grow()

  def rollout(self, params: Params) -> np.ndarray:
    """Sand positions [T, Ns, 2] (host)."""
    (positions,) = self._run(_gns_forward, params)
    return np.asarray(positions)

  def value_and_grad(self, objective: Objective,
                     params: Params) -> tuple[float, Params, np.ndarray]:
    """(objective, its gradient w.r.t. ``params``, positions [T, Ns, 2]).

    ``objective`` is a static argument: pass the same function object
    (e.g. an ``Objective.smooth``) to reuse its compiled program.
    """
    value, grad, positions = self._run(_gns_value_and_grad, params,
                                       objective)
    if not all_finite(grad):
      raise self._gradient_error(objective, params, grad)
    return float(value), grad, np.asarray(positions)

  def _gradient_error(self, objective, params, grad) -> FloatingPointError:
    """The error naming the first stored frame whose learned step makes the
    gradient non-finite (rollouts truncated after s steps, bisected)."""
    c, k = self.sim.window.shape[0], self.sim.frame_stride

    def finite_at(steps):
      sim = self.sim.replace(num_frames=(c - 1 + steps) * k + 1)
      driver = GNSDriver(sim, self.model_params, self.nbrs)
      _, g, _ = driver._run(_gns_value_and_grad, params, objective)
      return all_finite(g)

    steps = _first_bad(finite_at, self.sim.n_steps)
    return _gradient_error(self.placement.scene, objective, grad,
                           (c - 1 + steps) * k)


# ------------------------------------------------------------------- MPM ---


def gns_driver(placement: placement_lib.Placement,
               workdir: str) -> GNSDriver:
  """The trained learned simulator in ``workdir`` (a run directory or a
  shipped model, latest checkpoint) as a function of ``placement``, started
  from the MPM's first input frames of its scene."""
  run = run_lib.load_run(workdir)
  window = mpm_window(placement.scene, run.problem.input_frames,
                      run.problem.frame_stride)
  return GNSDriver(GNSRollout.create(placement, run.model, run.problem,
                                     window), run.params)


def covering_nodes(placement: placement_lib.AnyPlacement,
                   spec: transfer.GridSpec, bucket: int = 256) -> np.ndarray:
  """Boundary nodes [B] for the designed obstacles anywhere in their range
  (and, if their sizes are free, at their largest sizes), padded to a
  multiple of ``bucket``.

  Nodes far from an obstacle's current place get zero weight
  (``boundary.make_field``), so extra nodes cost time, not accuracy.
  """
  scene = placement.scene
  ramp = geometry.ramp_params(scene.ramp)
  index = set()
  for params in placement.covering_params(spec.dx / 4):
    index.update(boundary.select_nodes(spec, scene.domain.width,
                                       scene.domain.height, ramp,
                                       placement.obstacles(params)).tolist())
  index = np.asarray(sorted(index), np.int32)
  return np.pad(index, (0, -len(index) % bucket))


@struct.dataclass
class MPMRollout:
  """The MPM as a function of the placement (a pytree).

  The sand starts on the scene's initial lattice (that of the initial
  placement, kept for every placement).

  Attributes:
    state: the initial particle state (padded; traced).
    physics: the physical parameters and time step (traced).
    index: int32 [B] grid nodes that may carry boundary conditions.
    ramp: the ramp (traced arrays, static kind).
    placement: what is designed (static).
    spec: the background grid (static).
    n_substeps: substeps per frame (static).
    n_particles: real particles; the state holds padding beyond (static).
    max_speed: the speed bound (m/s) the substep count was chosen for
      (static; checked on the host).
    num_frames: T, frames returned, frame 0 the initial state (static).
  """
  state: solver.MPMState
  physics: solver.SimParams
  index: jax.Array
  ramp: geometry.RampParams
  placement: placement_lib.AnyPlacement = struct.field(pytree_node=False)
  spec: transfer.GridSpec = struct.field(pytree_node=False)
  n_substeps: int = struct.field(pytree_node=False)
  n_particles: int = struct.field(pytree_node=False)
  max_speed: float = struct.field(pytree_node=False)
  num_frames: int = struct.field(pytree_node=False)

  @classmethod
  def create(cls, placement: placement_lib.AnyPlacement,
             num_frames: int | None = None) -> "MPMRollout":
    """The rollout of ``placement`` (host: the lattice and node list; runs
    no simulation). ``num_frames``: T (default the scene's)."""
    s = mpm.setup(placement.scene)
    return cls(state=s.state, physics=s.params,
               index=covering_nodes(placement, s.spec),
               ramp=geometry.ramp_params(placement.scene.ramp),
               placement=placement, spec=s.spec, n_substeps=s.n_substeps,
               n_particles=s.n_particles, max_speed=s.max_speed,
               num_frames=num_frames or placement.scene.num_frames)


def mpm_positions(sim: MPMRollout, params: Params, remat: bool = True
                  ) -> tuple[jax.Array, jax.Array, jax.Array]:
  """The MPM's rollout at placement ``params`` (pure, differentiable).

  Args:
    sim: the rollout (traced arrays; static settings).
    params: the placement (traced).
    remat: rematerialise each frame in the backward pass (static).

  Returns:
    positions [T, N, 2] (m), finite flags bool [T - 1] and the largest
    speed [T - 1] (m/s) per frame, for ``mpm.check_frames``.
  """
  domain = sim.placement.scene.domain
  field = boundary.make_field(sim.spec, sim.index, domain.width,
                              domain.height, sim.ramp,
                              sim.placement.obstacles(params))
  _, x, max_speed, finite = solver.rollout(
      sim.state, sim.physics, field, sim.spec, sim.num_frames - 1,
      sim.n_substeps, remat=remat)
  x = jnp.concatenate([sim.state.x[None], x])[:, :sim.n_particles]
  return x, finite, max_speed


@jax.jit
def _mpm_forward(sim, params):
  return mpm_positions(sim, params, remat=False)


@functools.partial(jax.jit, static_argnames="objective")
def _mpm_value_and_grad(sim, params, objective):
  def loss(p):
    x, finite, max_speed = mpm_positions(sim, p)
    return objective(x), (x, finite, max_speed)

  return jax.value_and_grad(loss, has_aux=True)(params)


class MPMDriver:
  """Runs an ``MPMRollout`` on the host, checking every frame."""

  def __init__(self, sim: MPMRollout):
    self.sim = sim

  @property
  def placement(self) -> placement_lib.AnyPlacement:
    return self.sim.placement

  def _check(self, params, finite, max_speed):
    name = (f"{self.placement.scene.name} "
            f"({self.placement.describe(params)})")
    mpm.check_frames(name, 1, np.asarray(finite), np.asarray(max_speed),
                     self.sim.max_speed)

  def rollout(self, params: Params) -> np.ndarray:
    """Sand positions [T, N, 2] (host); raises SimulationError on blow-up."""
    x, finite, max_speed = _mpm_forward(self.sim, params)
    self._check(params, finite, max_speed)
    return np.asarray(x)

  def value_and_grad(self, objective: Objective,
                     params: Params) -> tuple[float, Params, np.ndarray]:
    """(objective, its gradient w.r.t. ``params``, positions [T, N, 2]).

    ``objective`` is a static argument (see ``GNSDriver.value_and_grad``).
    """
    (value, (x, finite, max_speed)), grad = _mpm_value_and_grad(
        self.sim, params, objective)
    self._check(params, finite, max_speed)
    if not all_finite(grad):
      raise self._gradient_error(objective, params, grad)
    return float(value), grad, np.asarray(x)

  def _gradient_error(self, objective, params, grad) -> FloatingPointError:
    """The error naming the first frame that makes the gradient non-finite
    (rollouts truncated after k frames, bisected; a compilation each)."""
    def finite_at(frames):
      sim = self.sim.replace(num_frames=frames + 1)
      return all_finite(_mpm_value_and_grad(sim, params, objective)[1])

    return _gradient_error(self.placement.scene, objective, grad,
                           _first_bad(finite_at, self.sim.num_frames - 1))
