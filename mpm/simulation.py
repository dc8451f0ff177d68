"""Host-side driver: scene -> initial state, substep count, checked rollout.

This is where concrete decisions are made (particle lattice, substep count,
which nodes carry boundary conditions, chunking and checking); the numerics
stay pure in ``mpm.solver``. Shapes: N particles, Nb boundary particles,
T frames, B scenes in a batch.
"""

import dataclasses
import math
import time
from typing import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from mpm import boundary
from mpm import constitutive
from mpm import geometry
from mpm import programs
from mpm import resolution
from mpm import scene as scene_lib
from mpm import solver
from mpm import transfer
from mpm import window

GRAVITY = 9.81  # m/s^2


class SimulationError(RuntimeError):
  """A rollout went non-finite or broke its CFL bound (scene and frame
  named)."""

  def __init__(self, scene_name: str, frame: int, reason: str):
    super().__init__(f"scene {scene_name!r}, frame {frame}: {reason}")
    self.scene_name = scene_name
    self.frame = frame


class SpeedBoundError(SimulationError):
  """A particle passed the speed its substep count was chosen for (the run
  driver retries with more substeps before reporting it)."""


# Substep counts ``simulate_setups`` tries, as multiples of a setup's own,
# before a particle's speed is reported as a blow-up: a short ladder, so
# at most two more programs are compiled.
SUBSTEP_LADDER = (1, 2, 4)


def wave_speed(material: scene_lib.Material) -> float:
  """P-wave speed c_p = sqrt((lambda + 2 mu) / rho) [m/s]."""
  mu, lam = constitutive.lame_parameters(material.youngs_modulus,
                                         material.poisson_ratio)
  return math.sqrt((lam + 2 * mu) / material.density)


def speed_bound(scene: scene_lib.Scene) -> float:
  """Largest speed [m/s] sand can reach in the scene: free fall from the top
  of the domain to the lowest point of the ramp (energy conservation;
  friction only lowers it). It depends on the domain and ramp alone, so
  scenes that share them share a substep count (and a compiled program)."""
  lowest = float(np.min(scene.ramp.height(np.linspace(0, scene.domain.width,
                                                      2001))))
  drop = scene.domain.height - max(lowest, 0.0)
  return math.sqrt(2 * GRAVITY * max(drop, scene.dx))


def substeps_per_frame(scene: scene_lib.Scene, max_speed: float) -> int:
  """Substeps per frame so that dt <= C dx / (c_p + max|v|)."""
  dt_max = scene.solver.cfl * scene.dx / (wave_speed(scene.material) +
                                          max_speed)
  return max(1, int(math.ceil(scene.frame_dt / dt_max - 1e-9)))


def speed_allowed(scene: scene_lib.Scene, n_substeps: int) -> float:
  """The largest speed [m/s] that ``n_substeps`` per frame keep within the
  CFL condition (``substeps_per_frame``'s inverse)."""
  dt = scene.frame_dt / n_substeps
  return scene.solver.cfl * scene.dx / dt - wave_speed(scene.material)


_make_field = jax.jit(boundary.make_field, static_argnums=(0, 2, 3))


@dataclasses.dataclass(frozen=True)
class Setup:
  """Everything a rollout of one scene needs.

  Attributes:
    scene: the scene.
    spec: the background grid (static).
    n_substeps: substeps per frame (static).
    max_speed: the speed bound [m/s] the substep count was chosen for.
    state: initial particle state (N particles).
    params: traced physical parameters.
    field: boundary conditions on grid nodes.
    boundary_positions: float32 [Nb, 2] static boundary particles.
    boundary_types: int32 [Nb].
    n_particles: real particles; the state holds padding beyond them.
  """
  scene: scene_lib.Scene
  spec: transfer.GridSpec
  n_substeps: int
  max_speed: float
  state: solver.MPMState
  params: solver.SimParams
  field: boundary.BoundaryField
  boundary_positions: np.ndarray
  boundary_types: np.ndarray
  n_particles: int


def sim_params(scene: scene_lib.Scene, dt: float) -> solver.SimParams:
  m = scene.material
  f32 = lambda v: jnp.asarray(v, jnp.float32)
  return solver.SimParams(
      density=f32(m.density), youngs_modulus=f32(m.youngs_modulus),
      poisson_ratio=f32(m.poisson_ratio),
      friction_angle=f32(math.radians(m.friction_angle_deg)),
      boundary_friction=f32(scene.boundary_friction),
      wall_friction=f32(scene.wall_friction), gravity=f32([0.0, -GRAVITY]),
      dt=f32(dt), domain=f32([scene.domain.width, scene.domain.height]),
      mu_i=None if m.rheology == "drucker_prager" else _mu_i(m))


def _mu_i(m: scene_lib.Material) -> constitutive.MuI:
  """``MuI`` of the material's keys (``scene.RHEOLOGIES``; phi_0 is the
  state's), and the regularised rheology's threshold I_N."""
  f32 = {k: jnp.asarray(getattr(m, k), jnp.float32)
         for k in scene_lib.RHEOLOGIES[m.rheology] if k != "phi_0"}
  if m.rheology == "mu_i_regularized":
    f32["I_N"] = jnp.asarray(constitutive.regularization_threshold(
        m.mu_s, m.mu_2, m.I_0), jnp.float32)
  return constitutive.MuI(**f32)


def _bucket(n: int, multiple: int) -> int:
  return -(-n // multiple) * multiple


def setup(scene: scene_lib.Scene, x0: np.ndarray | None = None, *,
          particle_bucket: int = 64, node_bucket: int = 256) -> Setup:
  """Builds the initial state and discretisation of ``scene``.

  Particle and boundary-node counts are padded up to multiples of
  ``particle_bucket`` and ``node_bucket`` (1: no padding), so that scenes of
  similar size share compiled programs. Padding particles have zero volume
  (no mass; they never move); padding nodes point at node 0, which no
  particle reaches.

  Args:
    x0: optional initial positions [N, 2]; default the scene's lattice.
  """
  if x0 is None:
    x0 = geometry.granular_particles(scene)
  x0 = np.asarray(x0, np.float32)
  inside = ((x0 >= 0) & (x0 <= [scene.domain.width, scene.domain.height]))
  if x0.ndim != 2 or x0.shape[1] != 2 or len(x0) == 0 or not inside.all():
    raise ValueError(f"x0: expected [N >= 1, 2] positions inside the domain "
                     f"[0, {scene.domain.width:g}] x [0, "
                     f"{scene.domain.height:g}], got shape {x0.shape}")
  n = len(x0)
  spec = transfer.GridSpec.covering(scene.domain.width, scene.domain.height,
                                    scene.dx)
  vmax = speed_bound(scene)
  n_substeps = substeps_per_frame(scene, vmax)
  ramp = geometry.ramp_params(scene.ramp)
  obstacles = tuple(geometry.obstacle_params(o) for o in scene.obstacles)
  index = boundary.select_nodes(spec, scene.domain.width, scene.domain.height,
                                ramp, obstacles)
  index = np.pad(index, (0, _bucket(len(index), node_bucket) - len(index)))
  field = _make_field(spec, jnp.asarray(index), scene.domain.width,
                      scene.domain.height, ramp, obstacles)
  padded = _bucket(n, particle_bucket)
  volume = np.zeros(padded, np.float32)
  volume[:n] = scene.granular.spacing**2
  x0 = np.concatenate([x0, np.repeat(x0[:1], padded - n, 0)])
  state = solver.init_state(jnp.asarray(x0), jnp.asarray(volume),
                            scene.material.phi_0)
  bpos, btype = geometry.boundary_particles(scene)
  return Setup(scene, spec, n_substeps, vmax, state,
               sim_params(scene, scene.frame_dt / n_substeps), field, bpos,
               btype, n)


@dataclasses.dataclass(frozen=True)
class SimulationResult:
  """One simulated trajectory.

  Attributes:
    positions: float32 [T, N, 2]; frame 0 is the initial state.
    boundary_positions: float32 [Nb, 2]; boundary_types: int32 [Nb].
    max_speed: float32 [T] largest speed during each frame (m/s).
    wall_time_s: seconds simulating, compilation excluded.
    compile_time_s: seconds compiling (0 when the program was cached).
    n_substeps: substeps per frame.
    rest_frame: the last frame stepped when the run stopped at rest
      (``simulate_setups``' ``rest_speed``): later frames repeat it. None
      when every frame was stepped.
    resolution: the spacing ``simulate``'s ``front_tolerance`` picked and
      why (``mpm.resolution.Resolution``), or None.
  """
  scene: scene_lib.Scene
  positions: np.ndarray
  boundary_positions: np.ndarray
  boundary_types: np.ndarray
  max_speed: np.ndarray
  wall_time_s: float
  compile_time_s: float
  n_substeps: int
  rest_frame: int | None = None
  resolution: "resolution.Resolution | None" = None


def chunking(num_frames: int, chunk_frames: int) -> tuple[int, int]:
  """(number of chunks, frames per chunk) covering num_frames - 1 steps."""
  steps = max(num_frames - 1, 1)
  n_chunks = -(-steps // chunk_frames)
  return n_chunks, -(-steps // n_chunks)


def check_frames(scene_name: str, first_frame: int, finite: np.ndarray,
                 max_speed: np.ndarray, bound: float) -> None:
  """Raises SimulationError at the first frame that is non-finite or too fast.

  Host-side (call it on a rollout's outputs, outside ``jit``): the driver
  checks every chunk before running the next, inverse design every rollout.

  Args:
    scene_name: named in the error.
    first_frame: the frame number of ``finite[0]``.
    finite: bool [F], whether each frame's positions are finite.
    max_speed: [F] largest particle speed during each frame (m/s).
    bound: the speed (m/s) the substep count was chosen for
      (``Setup.max_speed``).

  Raises:
    SimulationError: naming the scene and the first bad frame.
  """
  for k in range(len(finite)):
    if not finite[k]:
      raise SimulationError(scene_name, first_frame + k,
                            "positions are not finite (numerical blow-up)")
    if not max_speed[k] <= bound:
      raise SpeedBoundError(
          scene_name, first_frame + k,
          f"particle speed {max_speed[k]:.3f} m/s exceeds {bound:.3f} m/s, "
          "the bound the substep count was chosen for (CFL violated)")


def pad_setup(s: Setup, n_particles: int, n_nodes: int) -> Setup:
  """Pads a setup to ``n_particles`` particles and ``n_nodes`` boundary nodes.

  Padding particles have zero volume (no mass, never move) and sit on the
  first particle; padding nodes point at node 0, which no particle reaches,
  with zero weights.
  """
  k = n_particles - s.state.x.shape[0]
  kb = n_nodes - s.field.index.shape[0]
  if k < 0 or kb < 0:
    raise ValueError(f"pad_setup: cannot pad {s.state.x.shape[0]} particles "
                     f"and {s.field.index.shape[0]} nodes down to "
                     f"{n_particles} and {n_nodes}")
  edge = lambda a, n: jnp.concatenate([a, jnp.repeat(a[:1], n, 0)])
  zeros = lambda a, n: jnp.concatenate([a, jnp.zeros((n,) + a.shape[1:],
                                                     a.dtype)])
  st, f = s.state, s.field
  state = solver.MPMState(
      x=edge(st.x, k), v=zeros(st.v, k), C=zeros(st.C, k), F=edge(st.F, k),
      volume_correction=zeros(st.volume_correction, k),
      volume=zeros(st.volume, k), volume_fraction=None if
      st.volume_fraction is None else edge(st.volume_fraction, k))
  field = boundary.BoundaryField(
      index=zeros(f.index, kb), solid_normal=edge(f.solid_normal, kb),
      solid_weight=zeros(f.solid_weight, kb),
      wall_normal=edge(f.wall_normal, kb), wall_weight=zeros(f.wall_weight, kb),
      phi=f.phi)
  return dataclasses.replace(s, state=state, field=field)


def _stacked(setups: Sequence[Setup], batched: bool):
  """(state, params, field) of the setups padded to one size, stacked on a
  leading batch axis if ``batched`` (else the one setup's)."""
  n = max(s.state.x.shape[0] for s in setups)
  nb = max(s.field.index.shape[0] for s in setups)
  padded = [pad_setup(s, n, nb) for s in setups]
  if not batched:
    return padded[0].state, padded[0].params, padded[0].field
  stack = lambda *a: jnp.stack(a)
  return tuple(jax.tree.map(stack, *[getattr(s, k) for s in padded])
               for k in ("state", "params", "field"))


def simulate_setups(setups: Sequence[Setup], *, chunk_frames: int = 50,
                    progress: Callable[[int], None] | None = None,
                    rest_speed: float | None = None,
                    rest_frames: int = 40,
                    grid_window: bool = True) -> list[SimulationResult]:
  """Simulates scenes that share grid, frame count and substep count.

  One scene runs as one program; several are padded to one particle and
  boundary-node count and run as one vmapped program (the throughput path on
  accelerators). Every chunk of frames is checked before the next one runs.

  A chunk in which a particle passes the speed the substep count was
  chosen for is run again from its start with twice, then four times the
  substeps (``SUBSTEP_LADDER``), each checked against the speed it allows;
  the rest of the run keeps the raised count. Only a chunk that fails at the
  top of the ladder, or goes non-finite within its bound, is an error.

  Args:
    setups: from :func:`setup`, all with equal ``spec``, ``n_substeps`` and
      ``scene.num_frames``, ``scene.frame_dt``.
    chunk_frames: frames per compiled call (checking granularity).
    progress: called with the number of frames finished after each chunk.
    rest_speed: if given (m/s), the run stops stepping once no particle
      of any scene has moved faster than this on average over the last
      ``rest_frames`` frames (its displacement over them, so that a
      deposit's elastic ringing does not count as motion; checked after
      each chunk): the frames after repeat the last one stepped
      (``SimulationResult.rest_frame``), so a deposit's last frames cost
      nothing. None steps every frame.
    rest_frames: the window (frames) of that average.
    grid_window: on a large grid, the grid work follows the sand: each
      frame updates only a window of the grid around it
      (``solver.rollout_windowed``), its size chosen per chunk from the
      sand's extent and reach (``mpm.window``; small grids run whole); a
      chunk in which a particle's stencil leaves the window runs again on a
      larger one. The positions are the whole grid's within float32
      rounding (bit for bit where XLA compiles the same arithmetic).
      False: every substep updates the whole grid.

  Returns:
    Per setup, its result; ``n_substeps`` is the largest count used.

  Raises:
    SimulationError: at the first bad frame of any scene.
  """
  first = setups[0]
  for s in setups[1:]:
    if (s.spec, s.n_substeps, s.scene.num_frames, s.scene.frame_dt) != (
        first.spec, first.n_substeps, first.scene.num_frames,
        first.scene.frame_dt):
      raise ValueError(
          "simulate_setups: scenes in one batch need the same grid "
          "(domain, dx), substeps per frame, num_frames and frame_dt; "
          f"{s.scene.name!r} differs from {first.scene.name!r}")
  batched = len(setups) > 1
  state, params, field = _stacked(setups, batched)
  n_chunks, frames = chunking(first.scene.num_frames, chunk_frames)
  pick = lambda a, b: a[b] if batched else a
  compile_time = 0.0
  boundary_index = np.asarray(field.index) if grid_window else None
  capacities = {}              # window size -> its boundary capacity

  def rung(k, size):
    """(compiled chunk, params, per-setup speed bounds) at ladder rung k,
    on a grid window of ``size`` nodes (None: the whole grid)."""
    nonlocal compile_time
    n = first.n_substeps * SUBSTEP_LADDER[k]
    if k == 0:
      rung_params, bounds = params, [s.max_speed for s in setups]
    else:
      dt = [s.scene.frame_dt / n for s in setups]
      rung_params = params.replace(
          dt=jnp.asarray(dt if batched else dt[0], jnp.float32))
      bounds = [speed_allowed(s.scene, n) for s in setups]
    fn = programs.chunk_program(batched, windowed=size is not None)
    if size is None:
      statics = (first.spec, frames, n)
    else:
      if size not in capacities:
        capacities[size] = window.boundary_capacity(boundary_index,
                                                    first.spec, size)
      statics = (first.spec, size, frames, n, capacities[size])
    compiled, seconds = programs.compiled(fn, state, rung_params, field,
                                          *statics)
    compile_time += seconds
    return compiled, rung_params, bounds

  level = 0
  positions = [np.asarray(state.x)[..., None, :, :]]
  speeds = [np.zeros(state.x.shape[:-2] + (1,), np.float32)]
  wall_time = 0.0
  rest_frame = None
  axis = 1 if batched else 0   # the frame axis of the positions
  extent = window.extent(state).reshape(-1, 2).max(0)
  growth = np.zeros(2)         # how much the sand spread in the last chunk
  size_before = None
  for chunk in range(n_chunks):
    size = None
    if grid_window:
      reach = max(s.max_speed for s in setups) * SUBSTEP_LADDER[level] * (
          first.scene.frame_dt) + growth
      size = window.chunk_window(first.spec, extent, reach, size_before,
                                 first_chunk=chunk == 0)
    while True:
      compiled, rung_params, bounds = rung(level, size)
      start = time.perf_counter()
      out = jax.block_until_ready(compiled(state, rung_params, field))
      wall_time += time.perf_counter() - start
      new_state, x, vmax, finite = out[:4]
      x, vmax, finite = np.asarray(x), np.asarray(vmax), np.asarray(finite)
      # The last chunk may run past the final frame; those frames are
      # dropped unchecked.
      keep = min(frames, first.scene.num_frames - 1 - chunk * frames)
      if size is not None and np.asarray(out[4])[..., :keep].any():
        size = window.larger(first.spec, size)  # the chunk again, larger
        continue
      try:
        for b, s in enumerate(setups):
          check_frames(s.scene.name, 1 + chunk * frames,
                       pick(finite, b)[:keep], pick(vmax, b)[:keep],
                       bounds[b])
        break
      except SpeedBoundError:
        if level == len(SUBSTEP_LADDER) - 1:
          raise
        level += 1   # the chunk again, from its start, with more substeps
    state, size_before = new_state, size
    grown = window.extent(state).reshape(-1, 2).max(0)
    growth, extent = np.maximum(grown - extent, 0.0), grown
    positions.append(x)
    speeds.append(vmax)
    if progress is not None:
      progress(min((chunk + 1) * frames, first.scene.num_frames - 1))
    left = first.scene.num_frames - 1 - (chunk + 1) * frames
    if rest_speed is not None and left > 0:
      done = np.concatenate(positions, axis)
      moved = (np.abs(np.take(done, -1, axis) -
                      np.take(done, -1 - rest_frames, axis)).max()
               if done.shape[axis] > rest_frames else np.inf)
      if moved < rest_speed * rest_frames * first.scene.frame_dt:
        rest_frame = (chunk + 1) * frames
        positions.append(np.repeat(x[..., -1:, :, :], left, axis=-3))
        speeds.append(np.zeros(vmax.shape[:-1] + (left,), vmax.dtype))
        if progress is not None:
          progress(first.scene.num_frames - 1)
        break

  positions = np.concatenate(positions, 1 if batched else 0)
  speeds = np.concatenate(speeds, -1)
  return [SimulationResult(
      scene=s.scene,
      positions=pick(positions, b)[:s.scene.num_frames, :s.n_particles],
      boundary_positions=s.boundary_positions,
      boundary_types=s.boundary_types,
      max_speed=pick(speeds, b)[:s.scene.num_frames],
      wall_time_s=wall_time / len(setups), compile_time_s=compile_time,
      n_substeps=s.n_substeps * SUBSTEP_LADDER[level],
      rest_frame=rest_frame) for b, s in enumerate(setups)]


def _check_fits(scenes: Sequence[scene_lib.Scene], chunk_frames: int):
  """Refuses scenes (one program) that cannot fit the first device."""
  from mpm import budget  # pylint: disable=g-import-not-at-top (it imports this module)
  memory, source = budget.machine_memory_bytes(jax.devices()[0])
  largest = max(scenes, key=lambda s: budget.estimate(s).memory_bytes)
  budget.check_fits(largest, scenes=len(scenes), chunk_frames=chunk_frames,
                    memory_bytes=memory, memory_source=source)


def simulate(scene: scene_lib.Scene, *,
             front_tolerance: float | None = None,
             **kwargs) -> SimulationResult:
  """Simulates ``scene.num_frames`` frames of one scene.

  Args:
    front_tolerance: None, or the largest front error the caller accepts
      (a fraction of the runout distance): the scene then runs at the
      cheapest particle spacing the speed/accuracy study measured to meet
      it (``mpm.resolution.choose``); the result's ``scene`` is the scene
      at that spacing and its ``resolution`` says which and why.
    **kwargs: those of :func:`simulate_setups`.

  Raises:
    InputError: before any work, if the scene cannot fit the device's
      memory (``mpm.budget.check_fits``: the estimate and what would fit),
      or no measured spacing meets ``front_tolerance`` (the message names
      the smallest tolerance that can be met).
  """
  chosen = None
  if front_tolerance is not None:
    chosen = resolution.choose(scene, front_tolerance)
    scene = resolution.at_spacing(scene, chosen.spacing)
  _check_fits([scene], kwargs.get("chunk_frames", 50))
  result = simulate_setups([setup(scene)], **kwargs)[0]
  return dataclasses.replace(result, resolution=chosen)


# Scenes whose particle counts differ by at most this factor share a
# vmapped program (``simulate_batch``): padding a scene to a bucket's
# largest costs at most this much more than its own size.
BUCKET_RATIO = 1.25


def size_buckets(counts: Sequence[int],
                 ratio: float = BUCKET_RATIO) -> list[list[int]]:
  """Indices of ``counts`` grouped so that in each group the largest is at
  most ``ratio`` times the smallest (greedy over the sorted counts, which
  gives the fewest such groups)."""
  order = sorted(range(len(counts)), key=lambda i: counts[i])
  groups: list[list[int]] = []
  for i in order:
    if groups and counts[i] <= ratio * counts[groups[-1][0]]:
      groups[-1].append(i)
    else:
      groups.append([i])
  return groups


def default_max_batch() -> int | None:
  """Scenes per vmapped program when the caller does not say: one on the
  CPU, no limit elsewhere. On the CPU a vmapped batch costs more per scene
  than one scene at a time since the substep's per-particle stencil index
  (2026-11-26: the 14 scenes of the speed/accuracy study in 3 size buckets
  1.11x; docs/performance.md); on an accelerator batching is what keeps
  the device busy."""
  return 1 if jax.default_backend() == "cpu" else None


def size_batches(counts: Sequence[int], ratio: float | None = BUCKET_RATIO,
                 max_batch: int | None = None,
                 caller: str = "size_batches") -> list[list[int]]:
  """Indices of ``counts`` in ``size_buckets`` (``ratio`` None: one group),
  each cut into batches of at most ``max_batch`` (None:
  ``default_max_batch()``): the programs a batch call runs."""
  if max_batch is not None and max_batch < 1:
    raise ValueError(f"{caller}: max_batch = {max_batch}; allowed: >= 1 or "
                     "None")
  groups = (size_buckets(counts, ratio) if ratio is not None else
            [list(range(len(counts)))])
  size = max_batch or default_max_batch() or len(counts)
  return [g[i:i + size] for g in groups for i in range(0, len(g), size)]


def simulate_batch(scenes: Sequence[scene_lib.Scene], *,
                   bucket_ratio: float | None = BUCKET_RATIO,
                   max_batch: int | None = None,
                   **kwargs) -> list[SimulationResult]:
  """Simulates several scenes, as vmapped programs over scenes of similar
  size.

  The scenes are grouped by particle count (``size_buckets``: within a
  group the largest has at most ``bucket_ratio`` times the smallest's
  particles); each group runs as vmapped programs of at most ``max_batch``
  scenes (None: ``default_max_batch()``, one at a time on the CPU), each
  padded to its largest, with the largest substep count any of its scenes
  needs, so every scene keeps its CFL bound. ``bucket_ratio=None``: one
  group. Other keyword arguments are those of :func:`simulate_setups`.

  Returns:
    The results in the order of ``scenes``.

  Raises:
    InputError: before any work, if the batch cannot fit the device's
      memory (``mpm.budget.check_fits``, naming the batch size that fits).
  """
  _check_fits(scenes, kwargs.get("chunk_frames", 50))
  setups = [setup(s) for s in scenes]
  groups = size_batches([s.n_particles for s in setups], bucket_ratio,
                        max_batch, "simulate_batch")
  results: list[SimulationResult | None] = [None] * len(setups)
  for group in groups:
    members = [setups[i] for i in group]
    n_substeps = max(s.n_substeps for s in members)
    members = [dataclasses.replace(
        s, n_substeps=n_substeps,
        params=s.params.replace(dt=jnp.asarray(
            s.scene.frame_dt / n_substeps, jnp.float32))) for s in members]
    for i, result in zip(group, simulate_setups(members, **kwargs)):
      results[i] = result
  return results
