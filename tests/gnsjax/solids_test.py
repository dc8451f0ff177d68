"""How the learned simulator sees and respects the solids: the SDF grid and
its features against brute-force distances, and the solid constraint
(`gnsjax.simulator.constrain`)."""

import functools

from absl.testing import absltest
import jax
import jax.numpy as jnp
import numpy as np

import mpm
from gnsjax import features
from gnsjax import simulator
from mpm import geometry

# A small domain, a straight ramp (its SDF is exact, so the brute force is
# too) and one obstacle of each shape.
WIDTH, HEIGHT = 0.4, 0.3
SCENE = mpm.Scene.from_dict({
    "name": "solids", "domain": {"width": WIDTH, "height": HEIGHT},
    "ramp": {"kind": "polyline", "points": [[0.0, 0.05], [WIDTH, 0.15]]},
    "obstacles": [
        {"shape": "semicircle", "x": 0.1, "radius": 0.03},
        {"shape": "rectangle", "x": 0.2, "width": 0.04, "height": 0.03},
        {"shape": "triangle", "x": 0.3, "base": 0.05, "height": 0.04}],
    "granular": {"box": [0.25, 0.2, 0.35, 0.28], "spacing": 0.01}})
SPACING = 0.005       # the SDF grid's (R / 6 for R = 0.03 m)
RADIUS = 0.03
RAMP_NORMAL = np.array([-0.1, 0.4]) / np.hypot(0.1, 0.4)
# Half a grid cell: about what one learned step penetrates.
DEPTH = SPACING / 2


# Jitted: op by op, each call compiles a dozen tiny programs.
_FRAME = jax.jit(geometry.obstacle_frame)
_OUTLINE = jax.jit(geometry.obstacle_outline)
_SAMPLE_SDF = jax.jit(geometry.sample_sdf)
_SOLID_FEATURES = jax.jit(features.solid_features, static_argnums=2)


def ramp_y(x):
  return 0.05 + 0.25 * np.asarray(x)


@functools.lru_cache(maxsize=None)
def grid() -> geometry.SDFGrid:
  return geometry.scene_sdf_grid(SCENE, SPACING)


def params():
  return (geometry.ramp_params(SCENE.ramp),
          tuple(geometry.obstacle_params(o) for o in SCENE.obstacles))


@functools.lru_cache(maxsize=None)
def exact_sdf():
  ramp, obstacles = params()
  return jax.jit(lambda p: geometry.scene_sdf(ramp, obstacles, WIDTH, HEIGHT,
                                              p))


def frame(index):
  ramp, obstacles = params()
  return tuple(np.asarray(a) for a in _FRAME(ramp, obstacles[index]))


def outline(index, s):
  ramp, obstacles = params()
  return np.asarray(_OUTLINE(ramp, obstacles[index],
                             np.asarray(s, np.float32)))


def flat_face_points(rng, n, depth):
  """[M, 2] points within ``depth`` of the flat faces (ramp, rectangle and
  triangle sides), at least 1 cm from any corner, and their signed distances
  [M] (positive outside)."""
  points, normals = [], []
  # The ramp between the obstacles.
  for lo, hi in [(0.01, 0.06), (0.145, 0.165), (0.235, 0.265), (0.34, 0.39)]:
    x = rng.uniform(lo, hi, n)
    points.append(np.stack([x, ramp_y(x)], -1))
    normals.append(np.broadcast_to(RAMP_NORMAL, (n, 2)))
  # Rectangle (outline: right side, top, left side) and triangle sides, in
  # the obstacles' (tangent, normal) frames.
  _, t, nrm = frame(1)
  for (lo, hi), normal in [((0.1, 0.2), t), ((0.4, 0.6), nrm),
                           ((0.8, 0.9), -t)]:
    points.append(outline(1, rng.uniform(lo, hi, n)))
    normals.append(np.broadcast_to(normal, (n, 2)))
  _, t, nrm = frame(2)
  for (lo, hi), sign in [((0.2, 0.3), 1.0), ((0.7, 0.8), -1.0)]:
    normal = sign * 0.04 * t + 0.025 * nrm      # (height, base / 2)
    points.append(outline(2, rng.uniform(lo, hi, n)))
    normals.append(np.broadcast_to(normal / np.linalg.norm(normal), (n, 2)))
  points, normals = np.concatenate(points), np.concatenate(normals)
  offset = rng.uniform(-depth, depth, len(points))
  return (points + offset[:, None] * normals).astype(np.float32), offset


def semicircle_points(rng, n, depth):
  """[n, 2] points within ``depth`` inside or outside the semicircle's arc,
  away from the ramp, and their signed distances [n]."""
  base, _, _ = frame(0)
  arc = outline(0, rng.uniform(0.15, 0.85, n))
  radial = (arc - base) / np.linalg.norm(arc - base, axis=-1, keepdims=True)
  offset = rng.uniform(-depth, depth, n)
  return (arc + offset[:, None] * radial).astype(np.float32), offset


def surface_samples(step=2e-4):
  """[S, 2] dense points on the boundary of the free space: the ramp, each
  obstacle's exposed outline and the domain's walls."""
  x = np.arange(0.0, WIDTH + step, step)
  parts = [np.stack([x, ramp_y(x)], -1)]
  for i, o in enumerate(SCENE.obstacles):
    n = geometry.outline_size(o, step / 4)
    parts.append(outline(i, np.linspace(0.0, 1.0, n)))
  y = np.arange(0.0, HEIGHT + step, step)
  parts += [np.stack([x, np.zeros_like(x)], -1),
            np.stack([x, np.full_like(x, HEIGHT)], -1),
            np.stack([np.zeros_like(y), y], -1),
            np.stack([np.full_like(y, WIDTH), y], -1)]
  return np.concatenate(parts)


def in_free_space(p):
  """bool [N]: above the ramp, in the box and outside every obstacle, by
  plain geometry (not the SDFs)."""
  free = ((p[:, 1] > ramp_y(p[:, 0])) & (p[:, 0] > 0) & (p[:, 0] < WIDTH) &
          (p[:, 1] > 0) & (p[:, 1] < HEIGHT))
  for i, o in enumerate(SCENE.obstacles):
    base, t, nrm = frame(i)
    u, v = (p - base) @ t, (p - base) @ nrm
    if o.shape == "semicircle":
      inside = np.hypot(u, v) < o.radius
    elif o.shape == "rectangle":
      inside = (np.abs(u) < o.width / 2) & (v < o.height)
    else:  # above the base, below both sides
      inside = v < o.height * (1 - np.abs(u) / (o.base / 2))
    free &= ~inside
  return free


class SDFTest(absltest.TestCase):
  """The grid and the features against distances computed by brute force."""

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    rng = np.random.default_rng(0)
    # Anywhere in the domain, and many near the solids (where sand is).
    near, _ = flat_face_points(rng, 20, 3 * SPACING)
    arc, _ = semicircle_points(rng, 60, 3 * SPACING)
    cls.points = np.concatenate([
        rng.uniform((0, 0), (WIDTH, HEIGHT), (300, 2)), near, arc
    ]).astype(np.float32)
    cls.free = in_free_space(cls.points)
    surface = surface_samples()
    d = np.linalg.norm(cls.points[:, None] - surface[None], axis=-1)
    nearest = np.argmin(d, 1)
    cls.brute = d[np.arange(len(d)), nearest]
    away = cls.points - surface[nearest]
    cls.brute_normal = away / cls.brute[:, None]
    cls.exact = np.asarray(exact_sdf()(jnp.asarray(cls.points)))

  def test_exact_sdf_is_the_brute_force_distance(self):
    self.assertGreater(self.free.sum(), 200)
    self.assertGreater((~self.free).sum(), 50)
    # Inside a solid exactly where plain geometry says so.
    np.testing.assert_array_equal(self.exact > 0, self.free)
    # Samples 2e-4 m apart: the nearest is at most 1e-4 m farther.
    np.testing.assert_allclose(self.exact[self.free], self.brute[self.free],
                               atol=1.01e-4, rtol=0)

  def test_grid_interpolates_the_exact_sdf(self):
    phi, normal = _SAMPLE_SDF(grid(), jnp.asarray(self.points))
    phi, normal = np.asarray(phi), np.asarray(normal)
    # The SDF is 1-Lipschitz: bilinear interpolation is off by at most the
    # distance to a cell's corner, h / sqrt(2).
    bound = SPACING / np.sqrt(2)
    np.testing.assert_array_less(np.abs(phi - self.exact), bound + 1e-6)
    np.testing.assert_array_less(np.abs(phi - self.brute)[self.free],
                                 bound + 1.01e-4)
    # Where the distance is linear over the cell (near flat faces), it is
    # exact, and the normal is the face's.
    rng = np.random.default_rng(1)
    p, offset = flat_face_points(rng, 20, DEPTH)
    phi, normal = _SAMPLE_SDF(grid(), jnp.asarray(p))
    np.testing.assert_allclose(phi, offset, atol=2e-6)
    np.testing.assert_allclose(np.linalg.norm(normal, axis=-1), 1.0,
                               atol=1e-5)
    ramp = slice(0, 80)  # the first four groups of 20: the ramp
    np.testing.assert_allclose(np.asarray(normal)[ramp],
                               np.broadcast_to(RAMP_NORMAL, (80, 2)),
                               atol=1e-5)

  def test_solid_features_are_the_clipped_distance_and_faded_normal(self):
    got = np.asarray(_SOLID_FEATURES(jnp.asarray(self.points), grid(),
                                             RADIUS))
    self.assertEqual(got.shape, (len(self.points), 3))
    free = self.free
    tol = (SPACING / np.sqrt(2) + 1.01e-4) / RADIUS
    np.testing.assert_allclose(
        got[free, 0], np.clip(self.brute[free] / RADIUS, -1, 1), atol=tol)
    np.testing.assert_array_less(got[:, 0], 1.0 + 1e-6)
    np.testing.assert_array_less(-1.0 - 1e-6, got[:, 0])
    np.testing.assert_array_equal(got[self.exact < -RADIUS - SPACING, 0],
                                  -1.0)
    # Beyond R the normal fades out completely.
    far = self.exact > RADIUS + SPACING
    self.assertGreater(far.sum(), 50)
    np.testing.assert_array_equal(got[far, 1:], 0.0)
    # Near a flat face: the face's normal, weighted by 1 - phi / R.
    rng = np.random.default_rng(2)
    p, offset = flat_face_points(rng, 10, DEPTH)
    got = np.asarray(_SOLID_FEATURES(jnp.asarray(p), grid(), RADIUS))
    weight = np.clip(1 - offset / RADIUS, 0, 1)
    np.testing.assert_allclose(got[:, 0], offset / RADIUS, atol=1e-4)
    np.testing.assert_allclose(got[:40, 1:], weight[:40, None] * RAMP_NORMAL,
                               atol=1e-4)
    np.testing.assert_allclose(np.linalg.norm(got[:, 1:], axis=-1), weight,
                               atol=1e-4)

  def test_node_features_end_with_the_solid_features(self):
    c, n = 4, len(self.points)
    positions = np.broadcast_to(self.points, (c, n, 2))
    stats = features.Stats(*(np.full(2, v, np.float32)
                             for v in (0.0, 1.0, 0.0, 1.0)))
    got = jax.jit(features.node_features, static_argnums=3)(
        jnp.asarray(positions), stats, grid(), RADIUS)
    self.assertEqual(got.shape, (n, features.num_node_features(c)))
    np.testing.assert_array_equal(got[:, :2 * (c - 1)], 0.0)
    np.testing.assert_allclose(
        got[:, 2 * (c - 1):],
        _SOLID_FEATURES(jnp.asarray(self.points), grid(), RADIUS))


class ConstrainTest(absltest.TestCase):
  """``simulator.constrain``: sand pushed out, the rest untouched."""

  def _constrain(self, previous, proposed, moving, pushes=1):
    out = jax.jit(simulator.constrain, static_argnums=4)(
        jnp.asarray(previous), jnp.asarray(proposed), jnp.asarray(moving),
        grid(), pushes)
    return tuple(np.asarray(a) for a in out[:2]) + (out[2],)

  def _random_window(self, seed, proposed):
    rng = np.random.default_rng(seed)
    velocity = rng.normal(0.0, 2e-3, proposed.shape)
    moving = rng.random(len(proposed)) < 0.8
    return (proposed - velocity).astype(np.float32), moving

  def _check(self, proposed, seed, tolerance):
    previous, moving = self._random_window(seed, proposed)
    positions, carried, info = self._constrain(previous, proposed, moving)
    phi, normal = map(np.asarray, _SAMPLE_SDF(grid(), proposed))
    inside = moving & (phi < 0)
    self.assertGreater(inside.sum(), 50)
    self.assertGreater((moving & ~inside).sum(), 50)
    self.assertGreater((~moving & (phi < 0)).sum(), 20)
    # No moving node is left inside.
    after, _ = _SAMPLE_SDF(grid(), jnp.asarray(positions))
    np.testing.assert_array_less(-np.asarray(tolerance)[moving],
                                 np.asarray(after)[moving])
    # Nodes outside the solids and static nodes are exactly left alone.
    alone = ~inside
    np.testing.assert_array_equal(positions[alone], proposed[alone])
    np.testing.assert_array_equal(carried[alone], previous[alone])
    # Pushed along the normal, by the depth.
    np.testing.assert_allclose(
        positions[inside],
        proposed[inside] - phi[inside, None] * normal[inside], atol=1e-7)
    # The inward normal velocity is gone, the rest of it kept.
    v_old = positions - previous
    v_new = positions - carried
    n = normal[inside]
    vn_old = np.sum(v_old[inside] * n, -1)
    vn_new = np.sum(v_new[inside] * n, -1)
    self.assertGreater((vn_old < 0).sum(), 10)
    self.assertGreater((vn_old > 0).sum(), 10)
    np.testing.assert_allclose(vn_new, np.maximum(vn_old, 0), atol=1e-7)
    tangent = np.stack([-n[:, 1], n[:, 0]], -1)
    np.testing.assert_allclose(np.sum(v_new[inside] * tangent, -1),
                               np.sum(v_old[inside] * tangent, -1), atol=1e-7)
    np.testing.assert_array_equal(carried[inside][vn_old >= 0],
                                  previous[inside][vn_old >= 0])
    # What it reports.
    self.assertEqual(int(info.count), int(inside.sum()))
    np.testing.assert_allclose(float(info.depth), -phi[inside].min(),
                               atol=1e-7)

  def test_flat_faces(self):
    proposed, _ = flat_face_points(np.random.default_rng(3), 40, DEPTH)
    self._check(proposed, 4, np.full(len(proposed), 1e-5))

  def test_semicircle(self):
    # Bilinear interpolation of a curved distance is off by up to
    # h^2 kappa / 8, with the curvature kappa = 1 / (r - depth) inside: once
    # where the push is measured and once where it lands.
    r = SCENE.obstacles[0].radius
    proposed, _ = semicircle_points(np.random.default_rng(5), 400, DEPTH)
    self._check(proposed, 6,
                np.full(len(proposed), SPACING**2 / (4 * (r - DEPTH))))

  def test_nothing_to_do_outside_the_solids(self):
    proposed, offset = flat_face_points(np.random.default_rng(7), 20, DEPTH)
    proposed = proposed[offset > 1e-4]
    previous, moving = self._random_window(8, proposed)
    positions, carried, info = self._constrain(previous, proposed, moving)
    np.testing.assert_array_equal(positions, proposed)
    np.testing.assert_array_equal(carried, previous)
    self.assertEqual(int(info.count), 0)
    self.assertEqual(float(info.depth), 0.0)

  def test_repeated_pushes_reach_the_free_space_at_corners(self):
    # One push along the normal does not reach the free space where two
    # solids meet (an obstacle on the ramp: the push out of one enters the
    # other) or near a polygon's corner (the grid's normal blends two
    # faces); pushing again from where the last push landed does.
    rng = np.random.default_rng(9)
    p = rng.uniform((0.0, 0.0), (WIDTH, 0.25), (20000, 2)).astype(np.float32)
    p = p[np.abs(np.asarray(exact_sdf()(jnp.asarray(p)))) < SPACING]
    moving = np.ones(len(p), bool)

    def deepest(pushes):
      positions, _, _ = self._constrain(p, p, moving, pushes)
      return -float(np.min(_SAMPLE_SDF(grid(), positions)[0]))

    self.assertGreater(deepest(1), SPACING / 4)
    self.assertLess(deepest(simulator.PUSHES), SPACING / 20)

  def test_one_push_is_enough_away_from_corners(self):
    # On flat faces the default pushes change nothing after the first.
    proposed, _ = flat_face_points(np.random.default_rng(3), 40, DEPTH)
    previous, moving = self._random_window(4, proposed)
    once = self._constrain(previous, proposed, moving, 1)
    again = self._constrain(previous, proposed, moving, simulator.PUSHES)
    for a, b in zip(once[:2], again[:2]):
      np.testing.assert_allclose(a, b, atol=1e-6)
    self.assertEqual(int(once[2].count), int(again[2].count))

  def test_sand_outside_the_domain_is_pushed_back(self):
    # Off the grid, sample_sdf subtracts the distance to it (clamping alone
    # left phi = 0 at the walls: sand that had left was not seen inside).
    p = np.array([[-0.01, 0.2], [0.2, HEIGHT + 0.01], [WIDTH + 0.01, 0.25],
                  [WIDTH + 0.02, HEIGHT + 0.02]], np.float32)
    phi, _ = _SAMPLE_SDF(grid(), jnp.asarray(p))
    np.testing.assert_allclose(phi, [-0.01, -0.01, -0.01, -0.02 * np.sqrt(2)],
                               atol=1e-6)
    positions, _, info = self._constrain(p, p, np.ones(len(p), bool))
    self.assertEqual(int(info.count), len(p))
    np.testing.assert_allclose(
        positions, [[0.0, 0.2], [0.2, HEIGHT], [WIDTH, 0.25], [WIDTH, HEIGHT]],
        atol=1e-6)
    np.testing.assert_array_less(-1e-5, np.asarray(
        geometry.domain_sdf(WIDTH, HEIGHT, jnp.asarray(positions))))

  def test_gradient_through_the_sdf_grid_matches_differences(self):
    # d/dx of a weighted sum of the constrained positions and carried
    # frames, with respect to the semicircle's and the rectangle's x, through
    # ``geometry.sdf_grid`` (float64: differences of 1e-6 m are exact to
    # ~1e-8). Points near the semicircle's top and the rectangle's uphill
    # side (a face that moves with x; its top only slides along itself): the
    # grid there is a smooth function of the obstacles' placement.
    rng = np.random.default_rng(10)
    base, _, nrm = frame(0)
    top_circle = base + 0.03 * nrm + rng.uniform(-0.004, 0.004, (20, 2))
    side = outline(1, rng.uniform(0.12, 0.18, 20)) + rng.uniform(
        -0.002, 0.002, (20, 2))
    proposed = np.concatenate([top_circle, side])
    previous = proposed - rng.normal(0.0, 2e-3, proposed.shape)
    moving = np.ones(len(proposed), bool)
    weights = rng.normal(size=(2,) + proposed.shape)
    with jax.enable_x64(True):
      ramp, obstacles = params()
      ramp = jax.tree.map(lambda a: np.asarray(a, np.float64), ramp)
      obstacles = [jax.tree.map(lambda a: np.asarray(a, np.float64), o)
                   for o in obstacles]

      def objective(xs):
        placed = (obstacles[0].replace(x=xs[0]),
                  obstacles[1].replace(x=xs[1]), obstacles[2])
        solids = geometry.sdf_grid(ramp, placed, WIDTH, HEIGHT, SPACING)
        positions, carried, _ = simulator.constrain(
            jnp.asarray(previous), jnp.asarray(proposed),
            jnp.asarray(moving), solids)
        return (jnp.sum(weights[0] * positions) +
                jnp.sum(weights[1] * carried))

      xs = np.array([0.1, 0.2], np.float64)
      f = jax.jit(objective)
      pushed = jax.jit(lambda: simulator.constrain(
          jnp.asarray(previous), jnp.asarray(proposed), jnp.asarray(moving),
          geometry.sdf_grid(ramp, obstacles, WIDTH, HEIGHT, SPACING))[2])()
      self.assertGreater(int(pushed.count), 10)
      grad = np.asarray(jax.jit(jax.grad(objective))(xs))
      h = 1e-6
      fd = [(float(f(xs + e)) - float(f(xs - e))) / (2 * h)
            for e in h * np.eye(2)]
    self.assertTrue(np.all(np.abs(grad) > 1e-3), grad)
    np.testing.assert_allclose(grad, fd, rtol=1e-5)



class NoisyTargetTest(absltest.TestCase):
  """``simulator.add_noise`` with the solids: a target the noise carried
  into a solid goes back to its surface; everything else is unchanged."""

  def test_targets_pushed_out_of_solids_and_nothing_else_changes(self):
    # Sand at rest 1 mm outside the flat faces, for C + 1 = 7 frames, and
    # velocity noise of 1 mm per step (the small config's): the walk carries
    # many targets in.
    rng = np.random.default_rng(5)
    surface, _ = flat_face_points(rng, 30, 0.0)
    _, normal = map(np.asarray, _SAMPLE_SDF(grid(), jnp.asarray(surface)))
    rest = (surface + 1e-3 * normal).astype(np.float32)
    window = jnp.asarray(np.broadcast_to(rest, (7,) + rest.shape))
    moving = jnp.asarray(rng.random(len(rest)) < 0.8)
    key = jax.random.key(0)
    add = jax.jit(functools.partial(simulator.add_noise, noise_std=1e-3))
    inputs, target = map(np.asarray, add(key, window, moving))
    inputs_out, target_out = map(np.asarray,
                                 add(key, window, moving, solids=grid()))
    np.testing.assert_array_equal(inputs_out, inputs)
    phi, _ = map(np.asarray, _SAMPLE_SDF(grid(), jnp.asarray(target)))
    moving = np.asarray(moving)
    inside = moving & (phi < 0)
    self.assertGreater(inside.sum(), 20)
    # Without the solids the target moves with the input's noise: inside.
    np.testing.assert_allclose(target, inputs[-1], atol=1e-7)
    after, _ = _SAMPLE_SDF(grid(), jnp.asarray(target_out))
    np.testing.assert_array_less(-1e-5, np.asarray(after)[moving])
    np.testing.assert_array_equal(target_out[~inside], target[~inside])
    # Static sand keeps its (noise-free) place, inside or not.
    np.testing.assert_array_equal(target_out[~moving], rest[~moving])

if __name__ == "__main__":
  absltest.main()
