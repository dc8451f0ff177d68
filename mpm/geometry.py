"""Solid geometry: the ramp, the obstacles on it, and their signed distances.

Signed distance functions (SDFs) are negative inside a solid and positive in
free space, in metres. They are written in ``jax.numpy`` so that the boundary
conditions and boundary particles built from them are differentiable with
respect to an obstacle's position and size (inverse design).

Obstacles stand on the ramp: the base centre sits at (x, ramp(x)) and the shape
is oriented along the local surface (u along the tangent, v along the outward
normal), so "height" is always the protrusion above the surface. Each shape
also extends ``embed`` below its base, into the ramp, so that no gap opens
between a straight base and the curved surface.
"""

import math
from typing import NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from mpm import _pytree
from mpm import scene as scene_lib

# Particle type ids (DeepMind's GNS convention: 3 = kinematic, 6 = sand).
SAND_TYPE = 6
RAMP_TYPE = 3
OBSTACLE_TYPE = 4
KINEMATIC_TYPES = (RAMP_TYPE, OBSTACLE_TYPE)

_SHAPE_IDS = {"semicircle": 0, "rectangle": 1, "triangle": 2}


@_pytree.pytree_dataclass
class RampParams:
  """The ramp profile as arrays.

  Attributes:
    coefficients: [K] polynomial coefficients c_k of y = sum c_k x^k (m).
    points: [P, 2] polyline vertices (m), sorted by x.
    kind: "polynomial" or "polyline" (static).
  """
  coefficients: jax.Array
  points: jax.Array
  kind: str = _pytree.static_field(default="polynomial")


@_pytree.pytree_dataclass
class ObstacleParams:
  """One obstacle: traced placement and size, static shape.

  Attributes:
    x: [] horizontal position of the base centre (m).
    size: [2] (radius, 0) for a semicircle; (width, height) for a rectangle;
      (base, height) for a triangle (m).
    shape: "semicircle", "rectangle" or "triangle" (static).
  """
  x: jax.Array
  size: jax.Array
  shape: str = _pytree.static_field(default="semicircle")


def ramp_params(ramp: scene_lib.Ramp) -> RampParams:
  if ramp.kind == "polyline":
    return RampParams(jnp.zeros((1,)), jnp.asarray(ramp.points, jnp.float32),
                      "polyline")
  return RampParams(jnp.asarray(ramp.coefficients, jnp.float32),
                    jnp.zeros((2, 2)), "polynomial")


def obstacle_params(obstacle: scene_lib.Obstacle) -> ObstacleParams:
  keys = scene_lib.OBSTACLE_SHAPES[obstacle.shape]
  size = [getattr(obstacle, k) for k in keys] + [0.0] * (2 - len(keys))
  return ObstacleParams(jnp.asarray(obstacle.x, jnp.float32),
                        jnp.asarray(size, jnp.float32), obstacle.shape)


def ramp_height(ramp: RampParams, x: jax.Array) -> jax.Array:
  """Ramp height y(x) [m]; ``x`` of any shape."""
  if ramp.kind == "polyline":
    return jnp.interp(x, ramp.points[:, 0], ramp.points[:, 1])
  y = jnp.zeros_like(x)
  for c in ramp.coefficients[::-1]:  # Horner
    y = y * x + c
  return y


def ramp_slope(ramp: RampParams, x: jax.Array) -> jax.Array:
  """dy/dx of the ramp; ``x`` of any shape."""
  _, slope = jax.jvp(lambda z: ramp_height(ramp, z), (x,), (jnp.ones_like(x),))
  return slope


def ramp_sdf(ramp: RampParams, p: jax.Array) -> jax.Array:
  """Signed distance [m] to the ramp surface for points ``p`` [..., 2].

  First-order accurate: the vertical gap scaled by the local slope, exact for
  straight ramps and within O(curvature * distance^2) near curved ones.
  """
  x, y = p[..., 0], p[..., 1]
  return (y - ramp_height(ramp, x)) * jax.lax.rsqrt(1 + ramp_slope(ramp, x)**2)


def _lift(a: jax.Array, ndim: int) -> jax.Array:
  """Adds leading axes to ``a`` up to ``ndim`` (explicit rank promotion)."""
  return a.reshape((1,) * (ndim - a.ndim) + a.shape)


def _safe_norm(v: jax.Array, axis: int = -1) -> jax.Array:
  sq = jnp.sum(v * v, axis=axis)
  return jnp.sqrt(jnp.where(sq > 0, sq, 1.0)) * (sq > 0)


def obstacle_frame(ramp: RampParams, obstacle: ObstacleParams):
  """Base centre [2], unit tangent [2] and unit outward normal [2]."""
  h = ramp_height(ramp, obstacle.x)
  s = ramp_slope(ramp, obstacle.x)
  inv = jax.lax.rsqrt(1 + s * s)
  base = jnp.stack([obstacle.x, h])
  tangent = jnp.stack([inv, s * inv])
  normal = jnp.stack([-s * inv, inv])
  return base, tangent, normal


def obstacle_polygon(obstacle: ObstacleParams) -> jax.Array:
  """Convex outline [V, 2] (counter-clockwise) in the local (u, v) frame.

  Rectangles and triangles only; the part below v = 0 is the embedded base.
  """
  a, height = obstacle.size[0], obstacle.size[1]
  half = a / 2
  embed = half  # deep enough to bridge the ramp's curvature under the base
  if obstacle.shape == "rectangle":
    corners = [(-half, -embed), (half, -embed), (half, height), (-half, height)]
  elif obstacle.shape == "triangle":
    corners = [(-half, -embed), (half, -embed), (half, 0.0), (0.0, height),
               (-half, 0.0)]
  else:
    raise ValueError(f"obstacle_polygon: shape {obstacle.shape!r} has no "
                     "polygon; allowed: 'rectangle', 'triangle'")
  return jnp.stack([jnp.stack([jnp.asarray(u), jnp.asarray(v)])
                    for u, v in corners])


def _convex_polygon_sdf(poly: jax.Array, q: jax.Array) -> jax.Array:
  """SDF of a counter-clockwise convex polygon [V, 2] at points q [..., 2]."""
  a = poly
  b = jnp.roll(poly, -1, axis=0)
  e = b - a                                              # [V, 2]
  w = q[..., None, :] - _lift(a, q.ndim + 1)             # [..., V, 2]
  e = _lift(e, w.ndim)
  t = jnp.clip(jnp.sum(w * e, -1) / jnp.sum(e * e, -1), 0.0, 1.0)
  dist = jnp.min(_safe_norm(w - t[..., None] * e), axis=-1)
  cross = e[..., 0] * w[..., 1] - e[..., 1] * w[..., 0]  # > 0: left of edge
  inside = jnp.all(cross > 0, axis=-1)
  return jnp.where(inside, -dist, dist)


def obstacle_sdf(ramp: RampParams, obstacle: ObstacleParams,
                 p: jax.Array) -> jax.Array:
  """Signed distance [m] to one obstacle for points ``p`` [..., 2]."""
  base, tangent, normal = obstacle_frame(ramp, obstacle)
  d = p - _lift(base, p.ndim)
  if obstacle.shape == "semicircle":
    # The lower half of the disk is inside the ramp: a disk is a semicircle.
    return _safe_norm(d) - obstacle.size[0]
  q = jnp.stack([d @ tangent, d @ normal], axis=-1)
  return _convex_polygon_sdf(obstacle_polygon(obstacle), q)


def solid_sdf(ramp: RampParams, obstacles: tuple[ObstacleParams, ...],
              p: jax.Array) -> jax.Array:
  """Signed distance [m] to the union of ramp and obstacles, p [..., 2]."""
  phi = ramp_sdf(ramp, p)
  for obstacle in obstacles:
    phi = jnp.minimum(phi, obstacle_sdf(ramp, obstacle, p))
  return phi


def domain_sdf(width: float, height: float, p: jax.Array) -> jax.Array:
  """Signed distance [m] to the domain's box walls (negative outside the
  box [0, width] x [0, height]) for points ``p`` [..., 2]."""
  x, y = p[..., 0], p[..., 1]
  return jnp.minimum(jnp.minimum(x, width - x), jnp.minimum(y, height - y))


def scene_sdf(ramp: RampParams, obstacles: tuple[ObstacleParams, ...],
              width: float, height: float, p: jax.Array) -> jax.Array:
  """Signed distance [m] to everything sand must stay out of: ramp,
  obstacles and the outside of the domain, for points ``p`` [..., 2]."""
  return jnp.minimum(solid_sdf(ramp, obstacles, p),
                     domain_sdf(width, height, p))


@_pytree.pytree_dataclass
class SDFGrid:
  """A scene's signed distance and outward normal sampled on a grid.

  Node (i, j) sits at (i * spacing, j * spacing), covering the domain
  [0, width] x [0, height]; values between nodes are bilinear. One shape per
  domain and spacing, whatever the obstacles, so scenes batch and one
  compiled program serves them all.

  Attributes:
    values: [Gx, Gy, 3] (phi (m), n_x, n_y) at the nodes; phi is
      ``scene_sdf``, n its unit gradient (outward from the solids).
    spacing: node spacing (m) (static).
  """
  values: jax.Array
  spacing: float = _pytree.static_field(default=0.005)


def grid_shape(width: float, height: float, spacing: float) -> tuple[int, int]:
  """(Gx, Gy) nodes of an ``SDFGrid`` covering the domain."""
  return (int(math.ceil(width / spacing - 1e-9)) + 1,
          int(math.ceil(height / spacing - 1e-9)) + 1)


def sdf_grid(ramp: RampParams, obstacles: tuple[ObstacleParams, ...],
             width: float, height: float, spacing: float) -> SDFGrid:
  """The ``SDFGrid`` of a scene (jittable with width, height and spacing
  static; differentiable in the obstacles' placement and size)."""
  gx, gy = grid_shape(width, height, spacing)
  nodes = jnp.stack(jnp.meshgrid(jnp.arange(gx) * spacing,
                                 jnp.arange(gy) * spacing, indexing="ij"), -1)
  sdf = lambda q: scene_sdf(ramp, obstacles, width, height, q)
  phi, grad = jax.vmap(jax.value_and_grad(sdf))(nodes.reshape(-1, 2))
  normal = grad * jax.lax.rsqrt(jnp.maximum(jnp.sum(grad**2, -1),
                                            1e-12))[:, None]
  values = jnp.concatenate([phi[:, None], normal], -1).reshape(gx, gy, 3)
  return SDFGrid(values, float(spacing))


def sample_sdf(grid: SDFGrid, p: jax.Array) -> tuple[jax.Array, jax.Array]:
  """Bilinear signed distance [...] (m) and unit outward normal [..., 2] at
  points ``p`` [..., 2]. Points off the grid (outside the domain) are
  sampled at the nearest grid point and their distance to it subtracted,
  with the normal pointing back to it: exact for the domain's walls, so a
  particle that jumps far out is still pushed back in. Differentiable in
  ``p`` and in the grid's values."""
  gx, gy = grid.values.shape[:2]
  extent = _lift(jnp.asarray([(gx - 1) * grid.spacing,
                              (gy - 1) * grid.spacing], p.dtype), p.ndim)
  inside = jnp.clip(p, 0.0, extent)
  out = p - inside
  out_sq = jnp.sum(out * out, -1)
  out_dist = jnp.sqrt(jnp.where(out_sq > 0, out_sq, 1.0)) * (out_sq > 0)
  phi, normal = _bilinear(grid, inside)
  back = -out / jnp.where(out_dist > 0, out_dist, 1.0)[..., None]
  normal = jnp.where((out_sq > 0)[..., None], back, normal)
  return phi - out_dist, normal


def _bilinear(grid: SDFGrid, p: jax.Array) -> tuple[jax.Array, jax.Array]:
  """``sample_sdf`` for points on the grid."""
  gx, gy = grid.values.shape[:2]
  q = p / grid.spacing
  lo = jnp.floor(q)
  t = q - lo
  i = jnp.clip(lo[..., 0].astype(jnp.int32), 0, gx - 2)
  j = jnp.clip(lo[..., 1].astype(jnp.int32), 0, gy - 2)
  tx = jnp.clip(t[..., 0] + (lo[..., 0] - i), 0.0, 1.0)[..., None]
  ty = jnp.clip(t[..., 1] + (lo[..., 1] - j), 0.0, 1.0)[..., None]
  v = grid.values
  value = ((1 - tx) * (1 - ty) * v[i, j] + tx * (1 - ty) * v[i + 1, j] +
           (1 - tx) * ty * v[i, j + 1] + tx * ty * v[i + 1, j + 1])
  n = value[..., 1:]
  n = n * jax.lax.rsqrt(jnp.maximum(jnp.sum(n * n, -1, keepdims=True), 1e-12))
  return value[..., 0], n


def push_out(x: jax.Array, phi: jax.Array, normal: jax.Array) -> jax.Array:
  """Moves points with phi < 0 back to the surface along ``normal``.

  Shared by the MPM's particle projection and the learned simulator's
  constraint. Differentiable (the push is max(-phi, 0), linear inside).

  Args:
    x: [N, 2] positions (m); phi: [N] signed distances there (m);
    normal: [N, 2] unit outward normals (zero where unknown: no push).
  """
  return x + jnp.maximum(-phi, 0.0)[:, None] * normal


_sdf_grid = jax.jit(sdf_grid, static_argnums=(2, 3, 4))


def scene_sdf_grid(scene: scene_lib.Scene, spacing: float) -> SDFGrid:
  """The ``SDFGrid`` of a scene at node ``spacing`` (m). Host-side: one
  compiled program per combination of obstacle shapes."""
  if not spacing > 0:
    raise ValueError(f"SDF grid spacing = {spacing}; allowed: > 0 (m)")
  return _sdf_grid(ramp_params(scene.ramp),
                   tuple(obstacle_params(o) for o in scene.obstacles),
                   float(scene.domain.width), float(scene.domain.height),
                   float(spacing))


# ------------------------------------------------------ boundary particles ---


# Host-side helpers evaluate these on many points: one compiled program each
# instead of hundreds of eagerly dispatched ops.
_solid_sdf = jax.jit(solid_sdf)


def outline_size(obstacle: scene_lib.Obstacle, spacing: float) -> int:
  """Number of particles sampling an obstacle's exposed outline."""
  if obstacle.shape == "semicircle":
    length = math.pi * obstacle.radius
  elif obstacle.shape == "rectangle":
    length = 2 * obstacle.height + obstacle.width
  else:
    length = 2 * math.hypot(obstacle.base / 2, obstacle.height)
  return max(2, int(math.ceil(length / spacing)) + 1)


def obstacle_outline(ramp: RampParams, obstacle: ObstacleParams,
                     s: jax.Array) -> jax.Array:
  """World positions [P, 2] along the exposed outline at fractions s [P].

  The exposed outline runs from one end of the base (s = 0), over the top, to
  the other (s = 1); it is a differentiable function of the obstacle's x and
  size. ``outline_fractions(outline_size(...))`` samples it at the particle
  spacing.
  """
  base, tangent, normal = obstacle_frame(ramp, obstacle)
  if obstacle.shape == "semicircle":
    angle = jnp.pi * s
    r = obstacle.size[0]
    local = jnp.stack([r * jnp.cos(angle), r * jnp.sin(angle)], axis=-1)
  else:
    a, height = obstacle.size[0], obstacle.size[1]
    if obstacle.shape == "rectangle":
      path = [(a / 2, 0.0), (a / 2, height), (-a / 2, height), (-a / 2, 0.0)]
    else:
      path = [(a / 2, 0.0), (0.0, height), (-a / 2, 0.0)]
    path = jnp.stack([jnp.stack([jnp.asarray(u), jnp.asarray(v)])
                      for u, v in path])
    seg = _safe_norm(path[1:] - path[:-1])
    cum = jnp.concatenate([jnp.zeros(1), jnp.cumsum(seg)])
    target = s * cum[-1]
    local = jnp.stack([jnp.interp(target, cum, path[:, 0]),
                       jnp.interp(target, cum, path[:, 1])], axis=-1)
  return (base[None] + local[:, :1] * tangent[None] +
          local[:, 1:] * normal[None])


def outline_fractions(n_points: int, bucket: int = 1) -> np.ndarray:
  """Fractions s float32 [P'] of ``n_points`` evenly spaced outline particles.

  Args:
    n_points: P, from ``outline_size``.
    bucket: pads P up to a multiple of ``bucket`` with s = 1 (repeats of the
      last point, to be sliced off), so that outlines of similar length share
      one compiled program.
  """
  s = np.ones(-(-n_points // bucket) * bucket, np.float32)
  s[:n_points] = np.linspace(0.0, 1.0, n_points)
  return s


class BoundaryNodes(NamedTuple):
  """Boundary particle positions of a ramp and its obstacles (m).

  Attributes:
    ramp: [M, 2] the ramp points; those an obstacle covers are replaced by
      their parking position when one was given, else left in place.
    outlines: one [P_k, 2] per obstacle, its exposed outline.
    covered: bool [M], the ramp points inside an obstacle.
  """
  ramp: jax.Array
  outlines: tuple[jax.Array, ...]
  covered: jax.Array


def boundary_nodes(ramp: RampParams, obstacles: Sequence[ObstacleParams],
                   ramp_points: jax.Array, fractions: Sequence[jax.Array],
                   parking: jax.Array | None = None) -> BoundaryNodes:
  """The boundary particles as a differentiable function of the obstacles.

  Pure (jit it at the call site); the node count depends only on the shapes
  of ``ramp_points`` and ``fractions``, so an obstacle can move under
  ``jax.grad`` while the learned simulator's graph keeps its size. The
  outlines are differentiable in each obstacle's ``x`` and ``size``; the
  cover mask is a comparison (no gradient), and parked ramp points are
  constants.

  Args:
    ramp: the ramp.
    obstacles: K obstacles (traced x and size; static shape).
    ramp_points: [M, 2] ramp surface points (m), e.g. ``ramp_surface``.
    fractions: K arrays [P_k] of outline fractions in [0, 1], e.g.
      ``outline_fractions(outline_size(...))``.
    parking: optional [M, 2] positions for covered ramp points (the learned
      simulator's parking sites, out of every other node's reach).

  Returns:
    The ramp points (covered ones parked), the K outlines and the cover mask.
  """
  ramp_points = jnp.asarray(ramp_points)
  covered = jnp.zeros(ramp_points.shape[:1], bool)
  for obstacle in obstacles:
    covered = covered | (obstacle_sdf(ramp, obstacle, ramp_points) < 0)
  nodes = ramp_points
  if parking is not None:
    nodes = jnp.where(covered[:, None], parking, ramp_points)
  outlines = tuple(obstacle_outline(ramp, o, jnp.asarray(s))
                   for o, s in zip(obstacles, fractions))
  return BoundaryNodes(nodes, outlines, covered)


# One obstacle per call: one compiled program per shape and outline bucket,
# shared by every scene of a dataset.
_boundary_nodes = jax.jit(boundary_nodes)


def ramp_surface(ramp: scene_lib.Ramp, domain: scene_lib.Domain,
                 spacing: float) -> np.ndarray:
  """Points [M, 2] along the ramp inside the domain, ``spacing`` apart (arc)."""
  x = np.linspace(0.0, domain.width, 20_001)
  y = ramp.height(x)
  arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
  s = np.arange(0.0, arc[-1] + 1e-9, spacing)
  points = np.stack([np.interp(s, arc, x), np.interp(s, arc, y)], axis=-1)
  keep = (points[:, 1] >= 0) & (points[:, 1] <= domain.height)
  return points[keep]


def boundary_particles(scene: scene_lib.Scene) -> tuple[np.ndarray, np.ndarray]:
  """Static boundary particles of a scene, for the learned simulator.

  The ramp surface (where no obstacle covers it) and each obstacle's exposed
  outline, sampled at the granular particle spacing: ``boundary_nodes`` with
  the covered ramp points dropped.

  Returns:
    positions: float32 [Nb, 2] (m).
    types: int32 [Nb], ``RAMP_TYPE`` or ``OBSTACLE_TYPE``.
  """
  spacing = scene.granular.spacing
  ramp = ramp_params(scene.ramp)
  surface = ramp_surface(scene.ramp, scene.domain, spacing)
  covered = np.zeros(len(surface), bool)
  outlines = []
  for o in scene.obstacles:
    n = outline_size(o, spacing)
    nodes = _boundary_nodes(ramp, (obstacle_params(o),), surface,
                            (outline_fractions(n, bucket=64),))
    covered |= np.asarray(nodes.covered)
    outlines.append(np.asarray(nodes.outlines[0])[:n])
  surface = surface[~covered]
  types = [np.full(len(surface), RAMP_TYPE, np.int32)] + [
      np.full(len(p), OBSTACLE_TYPE, np.int32) for p in outlines]
  return (np.concatenate([surface] + outlines).astype(np.float32),
          np.concatenate(types))


def granular_particles(scene: scene_lib.Scene) -> np.ndarray:
  """Initial sand positions float32 [N, 2] on the lattice of ``scene.granular``.

  Lattice points in the box whose distance to any solid is at least half a
  spacing. With ``num_particles`` the box is filled from its lowest row
  upwards, the last row from the uphill (larger-x) side.

  Raises:
    ValueError: the box holds fewer free lattice points than asked for.
  """
  g = scene.granular
  x0, y0, x1, y1 = g.box
  xs = x0 + g.spacing * (np.arange(int(np.floor((x1 - x0) / g.spacing + 1e-9)))
                         + 0.5)
  ys = y0 + g.spacing * (np.arange(int(np.floor((y1 - y0) / g.spacing + 1e-9)))
                         + 0.5)
  grid = np.stack(np.meshgrid(xs, ys, indexing="xy"), -1).reshape(-1, 2)
  phi = np.asarray(_solid_sdf(ramp_params(scene.ramp),
                             tuple(obstacle_params(o) for o in scene.obstacles),
                             jnp.asarray(grid)))
  free = grid[phi >= g.spacing / 2]
  wanted = g.num_particles if g.num_particles is not None else max(len(free), 1)
  if len(free) < wanted:
    raise scene_lib.InputError(
        f"granular.box = {list(g.box)}: only {len(free)} lattice points at "
        f"spacing {g.spacing:g} m lie above the ramp and outside obstacles, "
        f"but {wanted} particles are needed; allowed: a box with free space for "
        "num_particles (move it above the ramp or enlarge it)")
  order = np.lexsort((-free[:, 0], free[:, 1]))  # by row, then uphill first
  return free[order[:wanted]].astype(np.float32)
