"""The MLS-MPM time step and rollouts: pure functions, no ``jit`` inside.

Shapes: N particles (padding particles have zero volume), T frames. One frame
of ``frame_dt`` is ``n_substeps`` equal substeps of ``params.dt``; the substep
count is static (it sets the loop), everything physical is traced, so material
and geometry can change, and be differentiated, without recompiling.
"""

import jax
import jax.numpy as jnp

from mpm import _pytree
from mpm import boundary
from mpm import constitutive
from mpm import transfer

# Nodes with less mass than this fraction of a particle's count as empty. They
# move nothing measurably (a particle's weight on them is below it), but the
# derivative -p / m^2 of their velocity overflows float32 below m ~ 5e-20 kg
# and turns a zero cotangent into NaN (0 * inf) in the backward pass.
_MIN_NODE_MASS = 1e-10


@_pytree.pytree_dataclass
class MPMState:
  """Particle state.

  Attributes:
    x: [N, 2] positions (m).
    v: [N, 2] velocities (m/s).
    C: [N, 2, 2] APIC affine velocity field (1/s).
    F: [N, 2, 2] elastic deformation gradient.
    volume_correction: [N] log volume gained by separation (Tampubolon 2017).
    volume: [N] initial particle volume (m^2 per metre of depth); 0 marks a
      padding particle, which has no mass and does not move.
    volume_fraction: [N] the grains' share phi of the sand's volume, with
      the compressible mu(I) only; None otherwise (the other rheologies'
      programs are unchanged).
  """
  x: jax.Array
  v: jax.Array
  C: jax.Array
  F: jax.Array
  volume_correction: jax.Array
  volume: jax.Array
  volume_fraction: jax.Array | None = None


@_pytree.pytree_dataclass
class SimParams:
  """Physical parameters, all traced (differentiable, no recompilation).

  Attributes:
    density: [] kg/m^3.
    youngs_modulus: [] Pa.
    poisson_ratio: [].
    friction_angle: [] internal friction angle (rad).
    boundary_friction: [] Coulomb coefficient of ramp and obstacles.
    wall_friction: [] Coulomb coefficient of the domain's walls.
    gravity: [2] m/s^2.
    dt: [] substep (s).
    domain: [2] width and height of the domain (m).
    mu_i: the mu(I) rheology's parameters, or None for Drucker-Prager at
      ``friction_angle`` (which rheology is part of the program's
      structure; its parameters are traced).
  """
  density: jax.Array
  youngs_modulus: jax.Array
  poisson_ratio: jax.Array
  friction_angle: jax.Array
  boundary_friction: jax.Array
  wall_friction: jax.Array
  gravity: jax.Array
  dt: jax.Array
  domain: jax.Array
  mu_i: constitutive.MuI | None = None


def init_state(x: jax.Array, volume: jax.Array,
               volume_fraction: float | None = None) -> MPMState:
  """Sand at rest at positions ``x`` [N, 2] with volumes ``volume`` [N]
  (and, for the compressible mu(I), the volume fraction phi of all)."""
  n = x.shape[0]
  eye = jnp.broadcast_to(jnp.eye(2, dtype=x.dtype), (n, 2, 2))
  phi = (None if volume_fraction is None else
         jnp.full_like(volume, volume_fraction))
  return MPMState(x=x, v=jnp.zeros_like(x), C=jnp.zeros_like(eye), F=eye,
                  volume_correction=jnp.zeros_like(volume), volume=volume,
                  volume_fraction=phi)


def substep(state: MPMState, params: SimParams, field: boundary.BoundaryField,
            spec: transfer.GridSpec, window_at: jax.Array | None = None
            ) -> tuple[MPMState, jax.Array]:
  """Advances by one substep ``params.dt``.

  Args:
    window_at: None, or int32 [2]: ``spec`` is then a window of the grid
      at that node and ``field`` is ``boundary.window``'s (the grid gets one
      extra node, where the field's entries outside the window point).

  Returns:
    The new state and the largest particle speed squared [] (m^2/s^2).
  """
  dt = params.dt
  mu, lam = constitutive.lame_parameters(params.youngs_modulus,
                                         params.poisson_ratio)
  alpha = constitutive.friction_coefficient(params.friction_angle)
  active = (state.volume > 0).astype(state.x.dtype)
  mass = params.density * state.volume

  st = transfer.stencil(state.x, spec, window_at)
  tau = constitutive.kirchhoff_stress(state.F, mu, lam)
  # MLS-MPM: the stress enters as an affine momentum, -dt V 4/dx^2 tau.
  affine = ((-dt * 4.0 / spec.dx**2) * state.volume[:, None, None] * tau +
            mass[:, None, None] * state.C)
  grid = transfer.p2g(st, mass, mass[:, None] * state.v, affine,
                      spec.n_nodes + (window_at is not None))

  grid_v = transfer.grid_velocity(grid, _MIN_NODE_MASS * jnp.max(mass))
  grid_v = grid_v + dt * params.gravity[None, :]
  grid_v = boundary.apply(field, grid_v, params.boundary_friction,
                          params.wall_friction)

  # One gather of velocity and signed distance (a gather costs per index).
  gathered = transfer.gather(
      st, jnp.concatenate([grid_v, field.phi[:, None]], -1))  # [N, S, 3]
  v, C = transfer.g2p_gathered(st, gathered[..., :2], spec.dx)
  v = v * active[:, None]
  C = C * active[:, None, None]
  x = boundary.project_particles(field, st, state.x + dt * v, state.x, spec.dx,
                                 gathered[..., 2])
  if spec.periodic_x:
    x = jnp.stack([jnp.mod(x[:, 0], params.domain[0]),
                   jnp.clip(x[:, 1], 0.0, params.domain[1])], -1)
  else:
    x = jnp.clip(x, 0.0, params.domain[None, :])
  F = state.F + dt * jnp.sum(C[..., :, :, None] * state.F[..., None, :, :], -2)
  phi = state.volume_fraction
  if phi is not None:
    # The volume follows the same velocity gradient as F.
    phi = constitutive.advect_volume_fraction(phi, C, dt)
  if params.mu_i is None:
    F, vc = constitutive.project(F, state.volume_correction, mu, lam, alpha)
  else:
    F, vc = constitutive.project_mu_i(F, state.volume_correction, mu, lam,
                                      params.mu_i, dt, phi)
  max_speed_sq = jnp.max(jnp.sum(v * v, -1))
  return state.replace(x=x, v=v, C=C, F=F, volume_correction=vc,
                       volume_fraction=phi), max_speed_sq


def advance(state: MPMState, params: SimParams, field: boundary.BoundaryField,
            spec: transfer.GridSpec, n_substeps: int):
  """Advances by one frame of ``n_substeps`` substeps.

  Returns:
    The new state and the largest particle speed [] (m/s) during the frame.
  """
  def body(_, carry):
    s, vmax_sq = carry
    s, v_sq = substep(s, params, field, spec)
    return s, jnp.maximum(vmax_sq, v_sq)

  state, vmax_sq = jax.lax.fori_loop(
      0, n_substeps, body, (state, jnp.zeros((), state.x.dtype)))
  return state, jnp.sqrt(vmax_sq)


def window_start(state: MPMState, spec: transfer.GridSpec,
                 size: tuple[int, int]) -> jax.Array:
  """int32 [2]: the grid node where a window of ``size`` nodes centred on
  the sand's bounding box starts, kept inside the grid."""
  active = (state.volume > 0)[:, None]
  x = jax.lax.stop_gradient(state.x)
  lo = jnp.min(jnp.where(active, x, jnp.inf), 0)
  hi = jnp.max(jnp.where(active, x, -jnp.inf), 0)
  origin = jnp.asarray(spec.origin, x.dtype)
  centre = ((lo + hi) / 2 - origin) / spec.dx
  start = jnp.round(centre - jnp.asarray(size, x.dtype) / 2).astype(jnp.int32)
  return jnp.clip(start, 0, jnp.asarray(spec.shape) - jnp.asarray(size))


def _spills(state: MPMState, spec: transfer.GridSpec, size: tuple[int, int],
            window_at: jax.Array) -> jax.Array:
  """[] bool: a particle's stencil reaches past the window's nodes."""
  xg = (state.x - jnp.asarray([spec.origin], state.x.dtype)) / spec.dx
  base = jnp.floor(xg - 0.5).astype(jnp.int32) - window_at[None, :]
  out = (base < 0) | (base > jnp.asarray(size)[None, :] - 3)
  return jnp.any(out.any(-1) & (state.volume > 0))


def advance_windowed(state: MPMState, params: SimParams,
                     field: boundary.BoundaryField, spec: transfer.GridSpec,
                     size: tuple[int, int], n_substeps: int,
                     capacity: int | None = None):
  """``advance`` on a window of ``size`` nodes (static) of the grid, centred
  on the sand at the frame's start: the grid work follows the sand.

  While every particle's stencil stays in the window the result is
  ``advance``'s, bit for bit (nodes outside it get no mass, and the
  boundary conditions there act on nothing).

  Returns:
    The new state, the largest speed [] (m/s) and whether a stencil left
    the window [] bool (then the frame is not the whole grid's: the caller
    runs it again on a larger window).
  """
  window_at = window_start(state, spec, size)
  window_spec = transfer.GridSpec(spec.dx, tuple(size), spec.origin)
  window_field = boundary.window(field, spec, size, window_at, capacity)

  def body(_, carry):
    s, vmax_sq, spilled = carry
    spilled = spilled | _spills(s, spec, size, window_at)
    s, v_sq = substep(s, params, window_field, window_spec, window_at)
    return s, jnp.maximum(vmax_sq, v_sq), spilled

  state, vmax_sq, spilled = jax.lax.fori_loop(
      0, n_substeps, body,
      (state, jnp.zeros((), state.x.dtype), jnp.zeros((), bool)))
  return state, jnp.sqrt(vmax_sq), spilled


def rollout_windowed(state: MPMState, params: SimParams,
                     field: boundary.BoundaryField, spec: transfer.GridSpec,
                     size: tuple[int, int], n_frames: int, n_substeps: int,
                     capacity: int | None = None):
  """``rollout`` with each frame on a window of ``size`` grid nodes that
  follows the sand (``advance_windowed``), its boundary conditions on
  ``capacity`` entries (``boundary.window``; None: all of the grid's).

  Returns:
    As ``rollout``, and spilled [T] bool: a stencil left the window during
    the frame (that frame and the later ones are not the whole grid's).
  """
  def frame(s, _):
    s, vmax, spilled = advance_windowed(s, params, field, spec, size,
                                        n_substeps, capacity)
    return s, (s.x, vmax, jnp.all(jnp.isfinite(s.x)), spilled)

  state, (positions, max_speed, finite, spilled) = jax.lax.scan(
      frame, state, None, length=n_frames)
  return state, positions, max_speed, finite, spilled


def rollout(state: MPMState, params: SimParams, field: boundary.BoundaryField,
            spec: transfer.GridSpec, n_frames: int, n_substeps: int,
            remat: bool = False):
  """Simulates ``n_frames`` frames under ``lax.scan``.

  Args:
    remat: recompute each frame's substeps in the backward pass instead of
      storing them (``jax.checkpoint``), so that memory for gradients grows
      with frames, not substeps.

  Returns:
    final_state; positions [T, N, 2] after each frame; max_speed [T] (m/s);
    finite [T] bool, whether every position was finite after the frame.
  """
  def frame(s, _):
    s, vmax = advance(s, params, field, spec, n_substeps)
    return s, (s.x, vmax, jnp.all(jnp.isfinite(s.x)))

  if remat:
    frame = jax.checkpoint(frame)
  state, (positions, max_speed, finite) = jax.lax.scan(
      frame, state, None, length=n_frames)
  return state, positions, max_speed, finite
