"""Inverse design: an obstacle's placement by gradients through GNS and MPM.

A ``Placement`` names the designed obstacle of a scene, its free parameters
(``x``, and optionally ``size``) and their allowed ranges. Both simulators
become pure, differentiable functions of those parameters, returning the
sand's positions [T, N, 2] (frame 0 the initial state):

- ``GNSRollout``: the obstacle's boundary particles are a differentiable
  function of its parameters, placed on the ramp surface by
  ``mpm.geometry.obstacle_outline``; ramp particles it covers are parked out
  of reach (``gnsjax.graph.parking_positions``), so the node count stays
  static while it moves. The learned simulator rolls out under ``lax.scan``.
- ``MPMRollout``: the obstacle's signed distance function sets the grid's
  boundary field (``mpm.boundary.make_field``); the field lists every node the
  obstacle can reach anywhere in its range, so one compiled program serves
  every placement.

Each step (GNS) or frame (MPM) is rematerialised in the backward pass
(``jax.checkpoint``): memory grows with the carried state per step, not with
the activations. Model and physical parameters are closed over as constants
of the gradient; only the placement is differentiated.

``optimise`` runs optax's Adam on a placement, projected back onto the
allowed ranges after every update.
"""

import dataclasses
import math
import time
from typing import Any, Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import optax

import mpm
from gnsjax import graph
from gnsjax import simulator
from mpm import boundary
from mpm import geometry
from mpm import sampler
from mpm import scene as scene_lib
from mpm import solver
from mpm import transfer

# The paper's (Table 1) range of obstacle positions along the ramp (m).
X_RANGE = sampler.OBSTACLE_X_RANGE
FREE_PARAMETERS = ("x", "size")

Params = dict[str, jax.Array]


@dataclasses.dataclass(frozen=True)
class Placement:
  """The designed obstacle of a scene and its free parameters.

  Attributes:
    scene: the scene; obstacle ``index`` is designed, the others stay.
    index: which obstacle.
    free: the parameters optimised: ("x",) or ("x", "size").
    x_range: allowed base positions (m); the paper's [0.5, 1.3] by
      default.
  """
  scene: scene_lib.Scene
  index: int = 0
  free: tuple[str, ...] = ("x",)
  x_range: tuple[float, float] = X_RANGE

  def __post_init__(self):
    n = len(self.scene.obstacles)
    if not 0 <= self.index < n:
      raise ValueError(f"index = {self.index}: the scene has {n} obstacle(s); "
                       f"allowed: 0..{n - 1} (add the obstacle to design to "
                       "the scene)")
    unknown = set(self.free) - set(FREE_PARAMETERS)
    if not self.free or unknown or "x" not in self.free:
      raise ValueError(f"free = {self.free}: allowed: ('x',) or ('x', "
                       "'size')")
    lo, hi = self.x_range
    if not 0 <= lo < hi <= self.scene.domain.width:
      raise ValueError(f"x_range = {self.x_range}: must lie within the "
                       f"domain [0, {self.scene.domain.width:g}] m with "
                       "x_min < x_max")
    self.check(self.initial())

  @property
  def obstacle(self) -> scene_lib.Obstacle:
    return self.scene.obstacles[self.index]

  @property
  def size_keys(self) -> tuple[str, ...]:
    return scene_lib.OBSTACLE_SHAPES[self.obstacle.shape]

  def size_range(self) -> np.ndarray:
    """[2, 2] (low, high) of the size vector (Table 1; unused entries 0)."""
    ranges = [sampler.SIZE_RANGES[self.obstacle.shape][k]
              for k in self.size_keys]
    ranges += [(0.0, 0.0)] * (2 - len(ranges))
    return np.asarray(ranges, np.float32)

  def initial(self) -> Params:
    """The scene's values of the free parameters."""
    o = geometry.obstacle_params(self.obstacle)
    return {"x": o.x, "size": o.size} if "size" in self.free else {"x": o.x}

  def obstacle_params(self, params: Params) -> geometry.ObstacleParams:
    """The designed obstacle with ``params`` (traced)."""
    o = geometry.obstacle_params(self.obstacle)
    return o.replace(x=jnp.asarray(params["x"], o.x.dtype),
                     size=jnp.asarray(params.get("size", o.size),
                                      o.size.dtype))

  def obstacles(self, params: Params) -> tuple[geometry.ObstacleParams, ...]:
    """All the scene's obstacles, the designed one at ``params``."""
    return tuple(self.obstacle_params(params) if i == self.index else
                 geometry.obstacle_params(o)
                 for i, o in enumerate(self.scene.obstacles))

  def project(self, params: Params) -> Params:
    """``params`` clipped onto the allowed ranges."""
    out = {"x": jnp.clip(params["x"], *self.x_range)}
    if "size" in params:
      r = self.size_range()
      out["size"] = jnp.clip(params["size"], r[:, 0], r[:, 1])
    return out

  def scene_at(self, params: Params) -> scene_lib.Scene:
    """The scene with the obstacle at ``params`` (validated: off the ramp,
    outside the domain or overlapping another obstacle raise ValueError)."""
    self.check(params)
    d = self.scene.to_dict()
    o = dict(d["obstacles"][self.index], x=float(params["x"]))
    if "size" in params:
      o.update({k: float(v) for k, v in zip(self.size_keys, params["size"])})
    d["obstacles"][self.index] = o
    return scene_lib.Scene.from_dict(d)

  def check(self, params: Params) -> None:
    """Raises ValueError when ``params`` lie outside the allowed ranges."""
    x = float(params["x"])
    lo, hi = self.x_range
    if not lo <= x <= hi:
      raise ValueError(f"obstacle x = {x:g} m is outside the allowed range "
                       f"[{lo:g}, {hi:g}] m")
    if "size" in params:
      r = self.size_range()
      size = np.asarray(params["size"], np.float32)
      if np.any(size < r[:, 0] - 1e-7) or np.any(size > r[:, 1] + 1e-7):
        raise ValueError(
            f"obstacle size {dict(zip(self.size_keys, size.tolist()))} is "
            f"outside the allowed ranges "
            f"{dict(zip(self.size_keys, r.tolist()))} m")


def with_obstacle(scene: scene_lib.Scene, shape: str, x: float,
                  **sizes: float) -> scene_lib.Scene:
  """``scene`` plus an obstacle (validated; a clear error if off the ramp)."""
  d = scene.to_dict()
  d["obstacles"] = list(d["obstacles"]) + [{"shape": shape, "x": x, **sizes}]
  return scene_lib.Scene.from_dict(d)


# ------------------------------------------------------------------- GNS ---


class GNSRollout:
  """The learned simulator as a function of the placement.

  ``rollout(params)`` returns the sand's positions [T, Ns, 2]: the first C
  frames are the MPM's (the learned simulator needs C input frames; the
  obstacle does not reach the sand before the avalanche is released), the
  rest the learned simulator's.

  Nodes: Ns sand, then Nr ramp particles (those under the designed obstacle
  parked), then the other obstacles' outlines, then the designed obstacle's
  P outline particles (P fixed by its initial size).
  """

  def __init__(self, placement: Placement, model, model_params, problem,
               input_frames: int, num_frames: int | None = None):
    """
    Args:
      placement: what is designed.
      model, model_params: the learned simulator (``gnsjax.models``).
      problem: ``gnsjax.train.Problem`` (statistics, bounds, graph spec).
      input_frames: C.
      num_frames: T (default the scene's).
    """
    scene = placement.scene
    self.placement = placement
    self.num_frames = num_frames or scene.num_frames
    if self.num_frames <= input_frames:
      raise ValueError(f"num_frames = {self.num_frames}: must exceed the "
                       f"{input_frames} input frames")
    self.model_params = model_params
    self.context = problem.context
    self.spec = problem.spec
    self.predictor = simulator.ModelPredictor(model)
    spacing = scene.granular.spacing
    first = mpm.simulate(dataclasses.replace(scene, num_frames=input_frames))
    self.window = first.positions.astype(np.float32)         # [C, Ns, 2]
    self.ramp = geometry.ramp_params(scene.ramp)
    others = [o for i, o in enumerate(scene.obstacles) if i != placement.index]
    ramp_points = geometry.ramp_surface(scene.ramp, scene.domain, spacing)
    fixed = [geometry.obstacle_params(o) for o in others]
    static = geometry.boundary_nodes(
        self.ramp, fixed, ramp_points,
        [geometry.outline_fractions(geometry.outline_size(o, spacing))
         for o in others])
    ramp_points = ramp_points[~np.asarray(static.covered)]
    self.ramp_points = ramp_points.astype(np.float32)        # [Nr, 2]
    self.parking = graph.parking_positions(len(ramp_points), self.spec)
    self.other_outlines = np.concatenate(
        [np.zeros((0, 2), np.float32)] +
        [np.asarray(o) for o in static.outlines]).astype(np.float32)
    self.outline_points = geometry.outline_size(placement.obstacle, spacing)
    ns, nr = self.window.shape[1], len(ramp_points)
    nb = nr + len(self.other_outlines) + self.outline_points
    self.types = np.concatenate([
        np.full(ns, mpm.SAND_TYPE), np.full(nr, mpm.RAMP_TYPE),
        np.full(nb - nr, mpm.OBSTACLE_TYPE)]).astype(np.int32)
    self.moving = np.arange(ns + nb) < ns
    self.nbrs = graph.allocate(self.spec, self._nodes(placement.initial()))
    self._extra_capacity = 0
    self._compiled: dict[Any, Callable] = {}

  @property
  def n_sand(self) -> int:
    return self.window.shape[1]

  def boundary(self, params: Params) -> jax.Array:
    """Boundary node positions [Nb, 2] (m) for the placement ``params``."""
    obstacle = self.placement.obstacle_params(params)
    covered = geometry.obstacle_sdf(self.ramp, obstacle, self.ramp_points) < 0
    ramp = jnp.where(covered[:, None], self.parking, self.ramp_points)
    s = jnp.linspace(0.0, 1.0, self.outline_points)
    outline = geometry.obstacle_outline(self.ramp, obstacle, s)
    return jnp.concatenate([ramp, self.other_outlines, outline])

  def _nodes(self, params: Params) -> jax.Array:
    """Last input frame of every node [N, 2]."""
    return jnp.concatenate([self.window[-1], self.boundary(params)])

  def positions(self, params: Params, model_params, nbrs, remat: bool = True,
                update_graph: bool = True) -> tuple[jax.Array, jax.Array]:
    """Sand positions [T, Ns, 2] and whether the neighbour list overflowed.

    Pure and differentiable in ``params``; ``nbrs`` fixes the edge capacity.
    The rollout is piecewise smooth in ``params``: an edge appears, with a
    message of full size, when two nodes come closer than R. With
    ``update_graph=False`` the edges of ``nbrs`` are kept throughout, a
    smooth function for checking gradients against finite differences.
    """
    c = self.window.shape[0]
    boundary_nodes = self.boundary(params)
    nodes = jnp.concatenate([
        jnp.asarray(self.window),
        jnp.broadcast_to(boundary_nodes[None], (c,) + boundary_nodes.shape)],
                            1)
    n, ns = nodes.shape[1], self.n_sand
    types, moving = jnp.asarray(self.types), jnp.asarray(self.moving)
    # Edges are integers: no gradient flows through the neighbour search.
    if update_graph:
      nbrs = graph.update(self.spec, jax.lax.stop_gradient(nodes[-1]), nbrs)

    def step(carry, _):
      window, nb = carry
      senders, receivers = graph.edges(nb, n)
      nxt = simulator.step(self.predictor, model_params, window, types,
                           moving, senders, receivers, self.context,
                           self.spec.radius)
      # The next step's list is built here, from the new positions: the
      # backward pass reads it from the carry instead of searching again.
      if update_graph:
        nb = graph.update(self.spec, jax.lax.stop_gradient(nxt), nb)
      return (jnp.concatenate([window[1:], nxt[None]]), nb), nxt[:ns]

    if remat:
      step = jax.checkpoint(step)
    (_, nbrs), predicted = jax.lax.scan(step, (nodes, nbrs), None,
                                        length=self.num_frames - c)
    return (jnp.concatenate([jnp.asarray(self.window), predicted]),
            nbrs.did_buffer_overflow)

  def _grow(self):
    """Reallocates the neighbour list with more headroom (recompiles)."""
    n = self.nbrs.reference_position.shape[0]
    self._extra_capacity += max(1, math.ceil(0.25 * self.nbrs.idx.shape[-1] /
                                             n))
    self.nbrs = graph.allocate(
        self.spec, self._nodes(self.placement.initial()),
        extra_capacity=self._extra_capacity)

  def _run(self, kind: str, objective, params: Params):
    """Runs a compiled program, growing the list until nothing overflows."""
    while True:
      key = (kind, objective, self.nbrs.idx.shape, self.nbrs.cell_list_capacity)
      if key not in self._compiled:
        self._compiled[key] = _program(self, kind, objective)
      out = self._compiled[key](params, self.model_params, self.nbrs)
      if not bool(out[-1]):
        return out[:-1]
      self._grow()

  def rollout(self, params: Params) -> np.ndarray:
    """Sand positions [T, Ns, 2] (host)."""
    (positions,) = self._run("forward", None, params)
    return np.asarray(positions)

  def value_and_grad(self, objective: Callable[[jax.Array], jax.Array],
                     params: Params) -> tuple[float, Params, np.ndarray]:
    """(objective, its gradient w.r.t. ``params``, positions [T, Ns, 2])."""
    value, grad, positions = self._run("grad", objective, params)
    return float(value), grad, np.asarray(positions)


def _program(sim, kind: str, objective):
  """A jitted program of ``sim.positions``: the forward rollout, or the
  objective's value and gradient; each returns the overflow flag last."""
  if kind == "forward":
    return jax.jit(lambda p, mp, nb: sim.positions(p, mp, nb, remat=False))

  def loss(p, mp, nb):
    positions, overflow = sim.positions(p, mp, nb)
    return objective(positions), (positions, overflow)

  def value_and_grad(p, mp, nb):
    (value, (positions, overflow)), grad = jax.value_and_grad(
        loss, has_aux=True)(p, mp, nb)
    return value, grad, positions, overflow

  return jax.jit(value_and_grad)


# ------------------------------------------------------------------- MPM ---


def covering_nodes(placement: Placement, spec: transfer.GridSpec,
                   bucket: int = 256) -> np.ndarray:
  """Boundary nodes [B] for the obstacle anywhere in its range (and, if its
  size is free, at its largest size), padded to a multiple of ``bucket``.

  Nodes far from the obstacle's current place get zero weight
  (``boundary.make_field``), so extra nodes cost time, not accuracy.
  """
  scene = placement.scene
  ramp = geometry.ramp_params(scene.ramp)
  params = placement.initial()
  if "size" in params:
    params = dict(params, size=jnp.asarray(placement.size_range()[:, 1]))
  lo, hi = placement.x_range
  index = set()
  for x in np.arange(lo, hi + spec.dx / 4, spec.dx / 4):
    obstacles = placement.obstacles(dict(params, x=jnp.float32(x)))
    index.update(boundary.select_nodes(spec, scene.domain.width,
                                       scene.domain.height, ramp,
                                       obstacles).tolist())
  index = np.asarray(sorted(index), np.int32)
  return np.pad(index, (0, -len(index) % bucket))


class MPMRollout:
  """The MPM as a function of the placement.

  ``positions(params)`` returns the sand's positions [T, N, 2] from the
  scene's initial lattice (the lattice of the initial placement, kept for
  every placement), its finite flags [T - 1] and largest speeds [T - 1]
  (m/s) per frame.
  """

  def __init__(self, placement: Placement, num_frames: int | None = None):
    scene = placement.scene
    self.placement = placement
    self.num_frames = num_frames or scene.num_frames
    self.setup = mpm.setup(scene)
    self.index = jnp.asarray(covering_nodes(placement, self.setup.spec))
    self.ramp = geometry.ramp_params(scene.ramp)
    self._compiled: dict[Any, Callable] = {}

  def positions(self, params: Params, remat: bool = True):
    s, scene = self.setup, self.placement.scene
    field = boundary.make_field(s.spec, self.index, scene.domain.width,
                                scene.domain.height, self.ramp,
                                self.placement.obstacles(params))
    _, x, max_speed, finite = solver.rollout(
        s.state, s.params, field, s.spec, self.num_frames - 1, s.n_substeps,
        remat=remat)
    x = jnp.concatenate([s.state.x[None], x])[:, :s.n_particles]
    return x, finite, max_speed

  def _check(self, params, finite, max_speed):
    name = f"{self.placement.scene.name} (obstacle x = {float(params['x']):g})"
    mpm.check_frames(name, 1, np.asarray(finite), np.asarray(max_speed),
                     self.setup.max_speed)

  def rollout(self, params: Params) -> np.ndarray:
    """Sand positions [T, N, 2] (host); raises SimulationError on blow-up."""
    if "forward" not in self._compiled:
      self._compiled["forward"] = jax.jit(
          lambda p: self.positions(p, remat=False))
    x, finite, max_speed = self._compiled["forward"](params)
    self._check(params, finite, max_speed)
    return np.asarray(x)

  def value_and_grad(self, objective: Callable[[jax.Array], jax.Array],
                     params: Params) -> tuple[float, Params, np.ndarray]:
    """(objective, its gradient w.r.t. ``params``, positions [T, N, 2])."""
    if objective not in self._compiled:
      def loss(p):
        x, finite, max_speed = self.positions(p)
        return objective(x), (x, finite, max_speed)
      self._compiled[objective] = jax.jit(jax.value_and_grad(loss,
                                                             has_aux=True))
    (value, (x, finite, max_speed)), grad = self._compiled[objective](params)
    self._check(params, finite, max_speed)
    return float(value), grad, np.asarray(x)


# -------------------------------------------------------------- optimise ---


def optimise(simulation, objective: Callable[[jax.Array], jax.Array],
             params: Params, *, steps: int, learning_rate: float,
             log: Callable[[dict], None] | None = None) -> list[dict]:
  """Projected Adam on the placement.

  Args:
    simulation: a ``GNSRollout`` or ``MPMRollout``.
    objective: positions [T, N, 2] -> [] to minimise.
    params: the starting placement (inside the allowed ranges).
    steps: gradient evaluations.
    learning_rate: Adam's step size (m per iteration, roughly).
    log: called with each iteration's record.

  Returns:
    One record per iteration: iteration, the placement, the objective and
    its gradient there, seconds taken. The best placement is the record
    with the lowest objective.
  """
  placement = simulation.placement
  placement.check(params)
  opt = optax.adam(learning_rate)
  state = opt.init(params)
  history = []
  for i in range(steps):
    start = time.perf_counter()
    value, grad, _ = simulation.value_and_grad(objective, params)
    record = {"iteration": i, **_plain(params, ""), "objective": value,
              **_plain(grad, "grad_"),
              "seconds": time.perf_counter() - start}
    history.append(record)
    if log is not None:
      log(record)
    if not all(np.all(np.isfinite(np.asarray(g))) for g in grad.values()):
      raise FloatingPointError(f"iteration {i}: the gradient at {params} is "
                               "not finite")
    updates, state = opt.update(grad, state, params)
    params = placement.project(optax.apply_updates(params, updates))
  return history


def _plain(params: Params, prefix: str) -> dict[str, Any]:
  """Host floats (size as one entry per component) for records."""
  out = {}
  for k, v in params.items():
    v = np.asarray(v, np.float64)
    if v.ndim == 0:
      out[prefix + k] = float(v)
    else:
      out.update({f"{prefix}{k}{i}": float(a) for i, a in enumerate(v)})
  return out


def central_difference(fn: Callable[[Params], float], params: Params,
                       h: float) -> Params:
  """Central differences of a scalar function of a placement, per entry."""
  out = {}
  for k, v in params.items():
    v = np.asarray(v, np.float32)
    flat = np.zeros(v.size, np.float64)
    for i in range(v.size):
      e = np.zeros(v.size, np.float32)
      e[i] = h
      e = e.reshape(v.shape)
      plus = fn(dict(params, **{k: jnp.asarray(v + e)}))
      minus = fn(dict(params, **{k: jnp.asarray(v - e)}))
      flat[i] = (plus - minus) / (2 * h)
    out[k] = flat.reshape(v.shape)
  return out


def sweep(simulation, objective_plain: Callable[[np.ndarray], float],
          objective_smooth: Callable[[jax.Array], jax.Array],
          params: Params, xs: Sequence[float]) -> list[dict]:
  """Forward rollouts over x (the brute-force baseline): each x's plain and
  smooth objective and seconds (the first includes compilation)."""
  rows = []
  for x in xs:
    p = dict(params, x=jnp.float32(x))
    start = time.perf_counter()
    positions = simulation.rollout(p)
    seconds = time.perf_counter() - start
    rows.append({"x": float(x), "plain": objective_plain(positions),
                 "smooth": float(objective_smooth(jnp.asarray(positions))),
                 "seconds": seconds})
  return rows
