"""Boundary conditions on grid nodes: Coulomb friction with separation.

Solids (ramp and obstacles) and the domain's walls act on grid velocities
through signed distances phi (negative inside). At a node, a velocity with an
inward normal part v_n < 0 loses it, and its tangential part shrinks by
mu |v_n| (stopping when that exceeds it); a velocity leaving the surface is
left alone, so sand can separate. The condition acts fully on nodes on or
inside a solid (phi <= 0), not at all from one cell outside (phi >= dx), and
linearly between, so moving a surface (an obstacle's x) changes the result
smoothly. Full strength at phi <= 0 matters: a node that only partly removes
a stuck velocity lets a sustained load (sand resting on a slope or a floor)
leak through it and creep.

The domain's walls get the same weighting, with each wall's own distance.

Only nodes within reach of sand get a condition: the ``BoundaryField`` lists
them (a band along the surfaces, not the whole grid), so this costs in
proportion to the length of the boundary.

The grid condition alone lets a particle drift up to about a cell into sharp
obstacle corners, so each particle is also pushed back out along the signed
distance interpolated from the nodes (``project_particles``).
"""

import jax
import jax.numpy as jnp
import numpy as np

from mpm import _pytree
from mpm import geometry
from mpm import transfer

# Nodes deeper than this in a solid [cells] are never reached by sand: a
# particle that penetrates half a cell has stencil nodes 2 cells deep.
_DEPTH_CELLS = 3.0


@_pytree.pytree_dataclass
class BoundaryField:
  """Boundary data of the B nodes that need it.

  Attributes:
    index: int32 [B] flat node indices; unique, except padding entries, which
      all point at node 0 (no particle reaches it) with zero weights.
    solid_normal: [B, 2] outward unit normal of the nearest solid.
    solid_weight: [B] how fully the solid condition acts, in [0, 1].
    wall_normal: [B, 2] inward normals (+-1, 0) and (0, +-1) of the box walls.
    wall_weight: [B, 2] weights of the x-wall and the y-wall conditions.
    phi: [G] signed distance (m) to the solids at every node.
  """
  index: jax.Array
  solid_normal: jax.Array
  solid_weight: jax.Array
  wall_normal: jax.Array
  wall_weight: jax.Array
  phi: jax.Array


def _weight(dist, dx):
  """Full on and beyond a surface (dist <= 0), zero from one cell outside."""
  return jnp.clip(1.0 - dist / dx, 0.0, 1.0)


def _wall_distances(p, width, height):
  """Signed distance to the nearer x-wall and y-wall, and the inward signs."""
  x, y = p[..., 0], p[..., 1]
  dist_x = jnp.minimum(x, width - x)
  dist_y = jnp.minimum(y, height - y)
  sign_x = jnp.where(x < width - x, 1.0, -1.0)
  sign_y = jnp.where(y < height - y, 1.0, -1.0)
  return dist_x, dist_y, sign_x, sign_y


def select_nodes(spec: transfer.GridSpec, width: float, height: float,
                 ramp: geometry.RampParams,
                 obstacles: tuple[geometry.ObstacleParams, ...],
                 margin_cells: float = 1.0) -> np.ndarray:
  """Indices int32 [B] of the nodes that can need a boundary condition.

  Host-side (not jittable): nodes whose condition weight is non-zero, within
  ``margin_cells`` extra cells so that small moves of an obstacle stay
  covered, and not buried deeper than sand can reach. The first two columns
  of nodes are never listed: no particle stencil reaches them (positions are
  clamped to the domain), so node 0 can serve as the target of padding
  entries.
  """
  p = jnp.asarray(spec.node_positions(), jnp.float32)
  phi = np.asarray(geometry._solid_sdf(ramp, obstacles, p)) / spec.dx  # pylint: disable=protected-access
  dist_x, dist_y, _, _ = map(np.asarray, _wall_distances(p, width, height))
  near = ((phi < 1.0 + margin_cells) |
          (dist_x / spec.dx < 1.0 + margin_cells) |
          (dist_y / spec.dx < 1.0 + margin_cells))
  reachable = phi > -_DEPTH_CELLS - margin_cells
  touched = np.arange(spec.n_nodes) >= 2 * spec.shape[1]
  return np.flatnonzero(near & reachable & touched).astype(np.int32)


def make_field(spec: transfer.GridSpec, index: jax.Array, width: float,
               height: float, ramp: geometry.RampParams,
               obstacles: tuple[geometry.ObstacleParams, ...]) -> BoundaryField:
  """Boundary data at nodes ``index`` [B]; differentiable in the geometry.

  Entries with index 0 are padding and get zero weights.
  """
  p = (jnp.asarray([spec.origin]) + spec.dx * jnp.stack(
      [index // spec.shape[1], index % spec.shape[1]], -1).astype(jnp.float32))
  sdf = lambda q: geometry.solid_sdf(ramp, obstacles, q)
  phi, grad = jax.vmap(jax.value_and_grad(sdf))(p)
  normal = grad * jax.lax.rsqrt(
      jnp.maximum(jnp.sum(grad**2, -1), 1e-12))[:, None]
  dist_x, dist_y, sign_x, sign_y = _wall_distances(p, width, height)
  real = (index > 0).astype(phi.dtype)
  nodes = jnp.asarray(spec.node_positions(), jnp.float32)
  return BoundaryField(
      index=index,
      solid_normal=normal,
      solid_weight=_weight(phi, spec.dx) * real,
      wall_normal=jnp.stack([sign_x, sign_y], -1),
      wall_weight=jnp.stack([_weight(dist_x, spec.dx),
                             _weight(dist_y, spec.dx)], -1) * real[:, None],
      phi=sdf(nodes))


def coulomb(v, normal, weight, mu):
  """Coulomb friction with separation at surfaces of unit normal ``normal``.

  Args:
    v: [B, 2] node velocities (m/s).
    normal: [B, 2] outward unit normals.
    weight: [B] in [0, 1], how fully the condition acts.
    mu: friction coefficient.

  Returns:
    [B, 2] velocities after the condition.
  """
  # Written with reductions over the size-2 axis on purpose: they split the
  # three conditions into separate loops, while one fused expression of all
  # three makes XLA's CPU emitter re-evaluate shared terms (measured 20x
  # slower).
  v_n = jnp.sum(v * normal, -1)                       # < 0: into the surface
  v_t = v - v_n[:, None] * normal
  t_sq = jnp.sum(v_t * v_t, -1)
  t_norm = jnp.sqrt(jnp.where(t_sq > 0, t_sq, 1.0))
  scale = jnp.maximum(0.0, 1.0 + mu * v_n / t_norm)
  into = v_n < 0                                      # separating: untouched
  projected = jnp.where(into[:, None], scale[:, None] * v_t, v)
  return v + weight[:, None] * (projected - v)


def apply(field: BoundaryField, grid_v: jax.Array, boundary_friction,
          wall_friction) -> jax.Array:
  """Applies solid and wall conditions to node velocities ``grid_v`` [G, 2]."""
  v = grid_v[field.index]
  v = coulomb(v, field.solid_normal, field.solid_weight, boundary_friction)
  zeros = jnp.zeros_like(field.wall_normal[:, :1])
  v = coulomb(v, jnp.concatenate([field.wall_normal[:, :1], zeros], -1),
              field.wall_weight[:, 0], wall_friction)
  v = coulomb(v, jnp.concatenate([zeros, field.wall_normal[:, 1:]], -1),
              field.wall_weight[:, 1], wall_friction)
  return grid_v.at[field.index].set(v)


def project_particles(field: BoundaryField, st: transfer.Stencil,
                      x_new: jax.Array, x_old: jax.Array, dx: float,
                      phi_i: jax.Array | None = None):
  """Pushes particles that moved into a solid back onto its surface.

  The signed distance at the old position and its gradient come from the
  nodes with the particle's own stencil (quadratic B-splines reproduce linear
  fields, and 4/dx^2 sum_i w_i phi_i (x_i - x_p) is the MLS gradient); the
  new position's distance is extrapolated along the step.

  Args:
    field: boundary data (its ``phi``).
    st: stencils of the old positions ``x_old`` [N, 2].
    x_new: [N, 2] positions after advection (m).
    dx: grid spacing (m).
    phi_i: [N, S] ``field.phi`` at the stencils, if the caller gathered it
      (``solver.substep`` packs it with the node velocities); else gathered
      here.

  Returns:
    [N, 2] positions with phi >= 0 (to first order).
  """
  if phi_i is None:
    phi_i = transfer.gather(st, field.phi[:, None])[..., 0]  # [N, S]
  w_phi = st.weight * phi_i
  phi = jnp.sum(w_phi, -1)
  grad = (4.0 / dx**2) * jnp.sum(w_phi[..., None] * st.offset, 1)  # [N, 2]
  phi_new = phi + jnp.sum(grad * (x_new - x_old), -1)
  g_sq = jnp.sum(grad * grad, -1)
  inv = jax.lax.rsqrt(jnp.where(g_sq > 0, g_sq, 1.0)) * (g_sq > 0)
  # phi_new is first-order accurate, so the push divides by |grad| once more.
  return geometry.push_out(x_new, phi_new * inv, grad * inv[:, None])


def window(field: BoundaryField, spec: transfer.GridSpec,
           size: tuple[int, int], window_at: jax.Array,
           capacity: int | None = None) -> BoundaryField:
  """The field on a window of the grid (``solver.advance_windowed``).

  Args:
    field: the whole grid's.
    spec: the whole grid.
    size: (wx, wy) nodes of the window (static).
    window_at: int32 [2], the grid node at the window's node (0, 0).
    capacity: None, or at least the number of the field's entries inside
      any window of ``size`` (static; ``mpm.window.boundary_capacity``):
      the window's field then keeps that many entries, those inside first,
      so that the conditions cost per entry in the window, not in the grid.

  Returns:
    The field indexed in the window: entries outside it (and padding) point
    at node wx * wy, one past the window's nodes, which the grid of a
    windowed substep adds and no particle reaches, with zero weights; phi
    [wx * wy + 1] is the window's slice (the extra node's value unused).
  """
  wx, wy = size
  i = field.index // spec.shape[1] - window_at[0]
  j = field.index % spec.shape[1] - window_at[1]
  inside = (field.index > 0) & (i >= 0) & (i < wx) & (j >= 0) & (j < wy)
  phi = jax.lax.dynamic_slice(field.phi.reshape(spec.shape),
                              (window_at[0], window_at[1]), size).reshape(-1)
  solid_normal, solid_weight = field.solid_normal, field.solid_weight
  wall_normal, wall_weight = field.wall_normal, field.wall_weight
  if capacity is not None:
    # Each node's condition is independent of the others', so a subset of
    # the entries in any order sets every node in the window as all do.
    picked = jnp.nonzero(inside, size=capacity, fill_value=0)[0]
    inside = inside[picked] & (jnp.arange(capacity) < jnp.sum(inside))
    i, j = i[picked], j[picked]
    solid_normal, solid_weight = solid_normal[picked], solid_weight[picked]
    wall_normal, wall_weight = wall_normal[picked], wall_weight[picked]
  keep = inside.astype(solid_weight.dtype)
  return BoundaryField(
      index=jnp.where(inside, i * wy + j, wx * wy).astype(jnp.int32),
      solid_normal=solid_normal,
      solid_weight=solid_weight * keep,
      wall_normal=wall_normal,
      wall_weight=wall_weight * keep[:, None],
      phi=jnp.concatenate([phi, phi[:1]]))
