"""Tests for `mpm.scene` (and the scene sampler, `mpm.sampler`)."""

import copy
import json
import math
import os
import tempfile

from absl.testing import absltest
from absl.testing import parameterized
import numpy as np

import mpm
from mpm import sampler
from mpm import scene as scene_lib

W, H = scene_lib.Domain.width, scene_lib.Domain.height
RAMP = scene_lib.Ramp()


def _base():
  """A valid scene dictionary: the paper's defaults plus one obstacle."""
  d = scene_lib.Scene().to_dict()
  d["obstacles"] = [{"shape": "semicircle", "x": 0.8, "radius": 0.05}]
  return d


def _with(**changes):
  """_base() with nested changes given as 'a.b' -> value (None deletes)."""
  d = _base()
  for path, value in changes.items():
    *parents, leaf = path.split("__")
    target = d
    for p in parents:
      target = target[int(p)] if isinstance(target, list) else target[p]
    if value is None:
      del target[leaf]
    else:
      target[leaf] = value
  return d


def _semicircle(x, r=0.05):
  return {"shape": "semicircle", "x": x, "radius": r}


def _invalid_cases():
  ramp_at_08 = float(RAMP.height(0.8))
  return [
      # Obstacles: outside the domain, off the ramp, overlapping, sizes.
      dict(testcase_name="obstacle_left_of_domain",
           d=_with(obstacles=[_semicircle(0.03)]),
           key="obstacles[0].x", allowed="allowed: [0.05, 1.6]"),
      dict(testcase_name="obstacle_right_of_domain",
           d=_with(obstacles=[_semicircle(W - 0.01)]),
           key="obstacles[0].x", allowed="allowed: [0.05, 1.6]"),
      dict(testcase_name="obstacle_x_outside_domain",
           d=_with(obstacles=[_semicircle(2.0)]),
           key="obstacles[0].x", allowed=f"allowed: (0, {W:g})"),
      dict(testcase_name="obstacle_x_negative",
           d=_with(obstacles=[_semicircle(-0.2)]),
           key="obstacles[0].x", allowed=f"allowed: (0, {W:g})"),
      dict(testcase_name="obstacle_off_the_ramp_above",
           d=_with(ramp={"kind": "polynomial", "coefficients": [H - 0.02]}),
           key="obstacles[0].x", allowed=f"within [0, {H - 0.05:.3f}] m"),
      dict(testcase_name="obstacle_off_the_ramp_below",
           d=_with(ramp={"kind": "polyline",
                         "points": [[0.0, 0.3], [1.0, -0.2], [W, -0.2]]},
                   granular={"box": [1.25, 0.5, 1.46, 1.19], "spacing": 0.005}),
           key="obstacles[0].x", allowed=f"within [0, {H - 0.05:.3f}] m"),
      dict(testcase_name="overlapping_obstacles",
           d=_with(obstacles=[_semicircle(0.8), {"shape": "rectangle",
                                                 "x": 0.85, "width": 0.04,
                                                 "height": 0.05}]),
           key="obstacles[1].x",
           allowed=f"at least {0.05 + np.hypot(0.02, 0.05):.3f} m apart"),
      dict(testcase_name="zero_radius",
           d=_with(obstacles=[_semicircle(0.8, 0.0)]),
           key="obstacles[0].radius", allowed=f"allowed: (0, {H / 2:g}]"),
      dict(testcase_name="negative_height",
           d=_with(obstacles=[{"shape": "triangle", "x": 0.8, "base": 0.04,
                               "height": -0.05}]),
           key="obstacles[0].height", allowed=f"allowed: (0, {H / 2:g}]"),
      dict(testcase_name="huge_width",
           d=_with(obstacles=[{"shape": "rectangle", "x": 0.8, "width": 0.7,
                               "height": 0.05}]),
           key="obstacles[0].width", allowed=f"allowed: (0, {H / 2:g}]"),
      dict(testcase_name="missing_size",
           d=_with(obstacles=[{"shape": "rectangle", "x": 0.8,
                               "width": 0.04}]),
           key="obstacles[0].height", allowed="['width', 'height']"),
      dict(testcase_name="missing_x",
           d=_with(obstacles=[{"shape": "semicircle", "radius": 0.04}]),
           key="obstacles[0].x", allowed=f"allowed: (0, {W:g})"),
      dict(testcase_name="unknown_shape",
           d=_with(obstacles=[{"shape": "hexagon", "x": 0.8,
                               "radius": 0.05}]),
           key="obstacles[0].shape",
           allowed="allowed: ['semicircle', 'rectangle', 'triangle']"),
      dict(testcase_name="size_key_of_another_shape",
           d=_with(obstacles=[{"shape": "rectangle", "x": 0.8, "width": 0.04,
                               "height": 0.05, "radius": 0.1}]),
           key="obstacles[0]", allowed="['shape', 'x', 'width', 'height']"),
      # Ramp.
      dict(testcase_name="bad_ramp_kind", d=_with(ramp={"kind": "spline"}),
           key="ramp.kind", allowed="allowed: 'polynomial', 'polyline'"),
      dict(testcase_name="polyline_not_spanning",
           d=_with(ramp={"kind": "polyline",
                         "points": [[0.0, 0.5], [1.0, 0.1]]}),
           key="ramp.points", allowed=f"cover [0, {W:g}]"),
      dict(testcase_name="polyline_not_increasing",
           d=_with(ramp={"kind": "polyline",
                         "points": [[0.0, 0.5], [1.0, 0.1], [0.9, 0.1],
                                    [W, 0.0]]}),
           key="ramp.points", allowed="strictly increasing"),
      dict(testcase_name="empty_coefficients",
           d=_with(ramp={"kind": "polynomial", "coefficients": []}),
           key="ramp.coefficients", allowed="non-empty list"),
      # Granular block.
      dict(testcase_name="box_inside_ramp",
           d=_with(granular={"box": [0.0, 0.0, 0.1, 0.05], "spacing": 0.005,
                             "num_particles": 10}),
           key="granular.box", allowed="allowed: a box"),
      dict(testcase_name="box_inside_obstacle",
           d=_with(obstacles=[_semicircle(0.8, 0.1)],
                   granular={"box": [0.78, ramp_at_08 + 0.01, 0.82,
                                     ramp_at_08 + 0.05],
                             "spacing": 0.005, "num_particles": 10}),
           key="granular.box", allowed="allowed: a box"),
      dict(testcase_name="box_without_room",
           d=_with(granular={"box": [0.0, 0.0, 0.1, 0.12], "spacing": 0.005,
                             "num_particles": 10000}),
           key="granular.box", allowed="allowed: a box"),
      dict(testcase_name="box_outside_domain",
           d=_with(granular={"box": [1.25, 0.5, 1.7, 1.0],
                             "spacing": 0.005}),
           key="granular.box", allowed=f"x_max <= {W:g}"),
      dict(testcase_name="box_inverted",
           d=_with(granular={"box": [1.3, 0.5, 1.25, 1.0],
                             "spacing": 0.005}),
           key="granular.box", allowed="x_min < x_max"),
      dict(testcase_name="zero_spacing", d=_with(granular__spacing=0),
           key="granular.spacing", allowed="allowed: (0, "),
      dict(testcase_name="spacing_above_dx", d=_with(granular__spacing=0.02),
           key="granular.spacing", allowed="allowed: spacing <= dx"),
      dict(testcase_name="zero_particles", d=_with(granular__num_particles=0),
           key="granular.num_particles", allowed="allowed: >= 1"),
      # Domain, material, solver, time.
      dict(testcase_name="zero_width", d=_with(domain__width=0),
           key="domain.width", allowed="allowed: (0, inf]"),
      dict(testcase_name="negative_height_domain", d=_with(domain__height=-1),
           key="domain.height", allowed="allowed: (0, inf]"),
      dict(testcase_name="zero_density", d=_with(material__density=0),
           key="material.density", allowed="allowed: (0, inf]"),
      dict(testcase_name="zero_youngs_modulus",
           d=_with(material__youngs_modulus=0),
           key="material.youngs_modulus", allowed="allowed: (0, 1e+09]"),
      dict(testcase_name="poisson_ratio_half",
           d=_with(material__poisson_ratio=0.5),
           key="material.poisson_ratio", allowed="allowed: [0, 0.5)"),
      dict(testcase_name="friction_angle_90",
           d=_with(material__friction_angle_deg=90),
           key="material.friction_angle_deg", allowed="allowed: [0, 80]"),
      dict(testcase_name="friction_angle_not_a_number",
           d=_with(material__friction_angle_deg="35"),
           key="material.friction_angle_deg", allowed="expected a number"),
      # The mu(I) rheology.
      dict(testcase_name="unknown_rheology",
           d=_with(material__rheology="bingham"), key="material.rheology",
           allowed="allowed: one of ['drucker_prager', 'mu_i', "
           "'mu_i_regularized', 'mu_i_compressible']"),
      dict(testcase_name="mu_i_key_without_mu_i",
           d=_with(material__mu_2=0.9), key="material",
           allowed="allowed: a rheology of ['mu_i', 'mu_i_regularized', "
           "'mu_i_compressible']"),
      dict(testcase_name="regularization_key_with_plain_mu_i",
           d=_with(material__rheology="mu_i", material__alpha_reg=1.0),
           key="material", allowed="allowed: a rheology of "
           "['mu_i_regularized']"),
      # The paper's sand (mu_s = sin 35 deg, mu_2 = mu_s + 0.26): mu(I) is
      # ill-posed at every I, so there is nothing to regularise below.
      dict(testcase_name="regularized_without_a_well_posed_range",
           d=_with(material__rheology="mu_i_regularized"), key="material",
           allowed="allowed: mu_s <= 0.52 at this mu_2 - mu_s"),
      dict(testcase_name="regularized_branch_ill_posed",
           d=_with(material__rheology="mu_i_regularized",
                   material__mu_s=0.38, material__alpha_reg=9.0),
           key="material.alpha_reg", allowed="allowed: a smaller"),
      # The compressible mu(I).
      dict(testcase_name="compressible_key_with_plain_mu_i",
           d=_with(material__rheology="mu_i", material__dilatancy=1.0),
           key="material", allowed="allowed: a rheology of "
           "['mu_i_compressible']"),
      dict(testcase_name="phi_min_not_below_phi_max",
           d=_with(material__rheology="mu_i_compressible",
                   material__phi_min=0.6, material__phi_max=0.55),
           key="material.phi_min", allowed="allowed: 0 < phi_min < phi_max"),
      dict(testcase_name="phi_max_of_one",
           d=_with(material__rheology="mu_i_compressible",
                   material__phi_max=1.0),
           key="material.phi_max", allowed="allowed: (0, 1)"),
      dict(testcase_name="phi_0_of_zero",
           d=_with(material__rheology="mu_i_compressible",
                   material__phi_0=0.0),
           key="material.phi_0", allowed="allowed: (0, 1)"),
      dict(testcase_name="negative_dilatancy",
           d=_with(material__rheology="mu_i_compressible",
                   material__dilatancy=-1.0),
           key="material.dilatancy", allowed="allowed: [0, 100]"),
      dict(testcase_name="mu_2_not_above_mu_s",
           d=_with(material__rheology="mu_i", material__mu_s=0.6,
                   material__mu_2=0.6), key="material.mu_2",
           allowed="allowed: mu_2 > mu_s"),
      dict(testcase_name="zero_mu_s",
           d=_with(material__rheology="mu_i", material__mu_s=0),
           key="material.mu_s", allowed="allowed: (0, 10]"),
      dict(testcase_name="zero_grain_diameter",
           d=_with(material__rheology="mu_i", material__grain_diameter=0),
           key="material.grain_diameter", allowed="allowed: (0, 0.1]"),
      dict(testcase_name="negative_I_0",
           d=_with(material__rheology="mu_i", material__I_0=-0.1),
           key="material.I_0", allowed="allowed: (0, 10]"),
      dict(testcase_name="grains_lighter_than_the_bulk",
           d=_with(material__rheology="mu_i", material__grain_density=1000),
           key="material.grain_density", allowed="allowed: >= the bulk"),
      dict(testcase_name="negative_boundary_friction",
           d=_with(boundary_friction=-0.1),
           key="boundary_friction", allowed="allowed: [0, 10]"),
      dict(testcase_name="negative_wall_friction", d=_with(wall_friction=-1),
           key="wall_friction", allowed="allowed: [0, 10]"),
      dict(testcase_name="zero_dx", d=_with(solver__dx=0),
           key="solver.dx", allowed="allowed: (0, "),
      dict(testcase_name="cfl_above_one", d=_with(solver__cfl=1.5),
           key="solver.cfl", allowed="allowed: (0, 1]"),
      dict(testcase_name="zero_frames", d=_with(num_frames=0),
           key="num_frames", allowed="allowed: >= 1"),
      dict(testcase_name="fractional_frames", d=_with(num_frames=2.5),
           key="num_frames", allowed="integer >= 1"),
      dict(testcase_name="zero_frame_dt", d=_with(frame_dt=0),
           key="frame_dt", allowed="allowed: (0, 1]"),
      dict(testcase_name="empty_name", d=_with(name=""),
           key="name", allowed="non-empty string"),
      # Unknown keys, top level and nested.
      dict(testcase_name="unknown_top_level_key", d=_with(gravity=9.81),
           key="scene", allowed="allowed keys are ['domain'"),
      dict(testcase_name="unknown_domain_key", d=_with(domain__depth=1),
           key="domain", allowed="allowed keys are ['width', 'height']"),
      dict(testcase_name="unknown_ramp_key", d=_with(ramp__degree=4),
           key="ramp", allowed="allowed keys are ['kind', 'coefficients']"),
      dict(testcase_name="unknown_obstacle_key",
           d=_with(obstacles=[dict(_semicircle(0.8), colour="red")]),
           key="obstacles[0]", allowed="allowed keys are ['shape', 'x', "
           "'radius']"),
      dict(testcase_name="unknown_granular_key", d=_with(granular__seed=1),
           key="granular", allowed="allowed keys are ['box', 'spacing', "
           "'num_particles']"),
      dict(testcase_name="unknown_material_key",
           d=_with(material__cohesion=1.0),
           key="material", allowed="allowed keys are ['density'"),
      dict(testcase_name="unknown_solver_key", d=_with(solver__substeps=10),
           key="solver", allowed="allowed keys are ['dx', 'cfl']"),
      dict(testcase_name="obstacles_not_a_list",
           d=_with(obstacles=_semicircle(0.8)),
           key="obstacles", allowed="expected a list"),
  ]


def _build(d):
  """Parses a scene and generates its particles (both can reject a scene)."""
  scene = mpm.Scene.from_dict(d)
  mpm.granular_particles(scene)
  return scene


class ValidationTest(parameterized.TestCase):

  def test_base_is_valid(self):
    scene = _build(_base())
    self.assertLen(scene.obstacles, 1)

  @parameterized.named_parameters(*_invalid_cases())
  def test_invalid(self, d, key, allowed):
    with self.assertRaises(ValueError) as cm:
      _build(d)
    msg = str(cm.exception)
    # The message starts with the offending key and states what is allowed.
    self.assertTrue(msg.startswith(key) and msg[len(key)] in " :",
                    f"message does not start with {key!r}: {msg}")
    self.assertIn(allowed, msg)

  def test_too_stiff_names_the_substeps(self):
    # 1e12 Pa at the paper's discretisation: c_p ~ 30 km/s, ~18,500
    # substeps per frame, 11 million for 600 frames.
    with self.assertRaisesRegex(
        mpm.InputError, r"youngs_modulus = 1e\+12 .*allowed: \(0, 1e\+09\] "
        r"Pa: .* 18,49\d substeps per frame, 11,0\d\d,\d{3} in all"):
      mpm.Scene.from_dict({"material": {"youngs_modulus": 1e12}})
    self.assertEqual(mpm.Scene.from_dict(
        {"material": {"youngs_modulus": 1e9}}).material.youngs_modulus, 1e9)

  def test_invalid_json(self):
    with self.assertRaisesRegex(ValueError, "not valid JSON"):
      mpm.Scene.from_json("{")

  def test_defaults_are_the_paper_scene(self):
    self.assertEqual(mpm.Scene.from_dict({}), mpm.Scene())
    self.assertEqual(mpm.Scene.from_json("{}"), mpm.Scene())
    # Without solver.dx the grid is twice the particle spacing.
    scene = mpm.Scene.from_dict({"granular": {"box": [1.2, 0.6, 1.4, 1.0],
                                              "spacing": 0.004}})
    self.assertAlmostEqual(scene.dx, 0.008, delta=1e-12)
    self.assertIsNone(scene.granular.num_particles)


class RoundTripTest(parameterized.TestCase):

  def test_mu_i_defaults_and_the_paper_files_unchanged(self):
    dp = mpm.Scene.from_dict(_base())
    self.assertEqual(dp.material.rheology, "drucker_prager")
    self.assertNotIn("rheology", dp.to_dict()["material"])
    self.assertNotIn("mu_s", dp.to_dict()["material"])
    d = _with(material__rheology="mu_i", material__friction_angle_deg=30)
    m = mpm.Scene.from_dict(d).material
    self.assertAlmostEqual(m.mu_s, math.sin(math.radians(30)))
    self.assertAlmostEqual(m.mu_2, m.mu_s + 0.26)
    self.assertEqual((m.I_0, m.grain_diameter, m.grain_density),
                     (0.279, 0.0005, 2650.0))
    self.assertIsNone(m.phi_0)
    d = _with(material__rheology="mu_i_compressible")
    m = mpm.Scene.from_dict(d).material
    self.assertEqual((m.phi_max, m.phi_min, m.dilatancy), (0.6, 0.4, 4.09))
    # The sand starts at the critical state at rest, phi_eq(0).
    self.assertEqual(m.phi_0, 0.6)
    self.assertIn("phi_max", mpm.Scene.from_dict(d).to_dict()["material"])

  @parameterized.named_parameters(
      ("default", {}),
      ("obstacles_of_every_shape", {
          "obstacles": [_semicircle(0.5, 0.03),
                        {"shape": "rectangle", "x": 0.8, "width": 0.04,
                         "height": 0.06},
                        {"shape": "triangle", "x": 1.1, "base": 0.05,
                         "height": 0.04}]}),
      ("polyline_and_full_box", {
          "name": "incline", "domain": {"width": 0.4, "height": 0.3},
          "ramp": {"kind": "polyline", "points": [[0, 0.2], [0.4, 0.05]]},
          "granular": {"box": [0.05, 0.1, 0.15, 0.25], "spacing": 0.01},
          "material": {"density": 1500, "youngs_modulus": 1e6,
                       "poisson_ratio": 0.25, "friction_angle_deg": 42},
          "boundary_friction": 0.3, "wall_friction": 0.1,
          "solver": {"dx": 0.02, "cfl": 0.3}, "num_frames": 7,
          "frame_dt": 0.01}),
      ("mu_i", {"material": {"rheology": "mu_i", "mu_s": 0.5, "mu_2": 0.7,
                             "I_0": 0.3, "grain_diameter": 0.001,
                             "grain_density": 2500}}),
      ("mu_i_regularized", {"material": {"rheology": "mu_i_regularized",
                                         "mu_s": 0.38, "alpha_reg": 1.5}}),
      ("mu_i_compressible", {"material": {
          "rheology": "mu_i_compressible", "phi_max": 0.62, "phi_min": 0.5,
          "dilatancy": 2.0, "phi_0": 0.55}}),
  )
  def test_dict_and_json(self, d):
    scene = mpm.Scene.from_dict(d)
    self.assertEqual(mpm.Scene.from_dict(scene.to_dict()), scene)
    self.assertEqual(mpm.Scene.from_json(scene.to_json()), scene)
    # The dictionary is plain JSON, and parsing it again is a fixed point.
    self.assertEqual(json.loads(scene.to_json()), scene.to_dict())
    self.assertEqual(mpm.Scene.from_dict(scene.to_dict()).to_dict(),
                     scene.to_dict())

  def test_file(self):
    scene = mpm.Scene.from_dict(_base())
    with tempfile.TemporaryDirectory() as tmp:
      path = os.path.join(tmp, "scene.json")
      with open(path, "w") as f:
        f.write(scene.to_json(indent=2))
      self.assertEqual(mpm.Scene.load(path), scene)

  def test_sampled_scenes(self):
    for seed in range(5):
      scene = mpm.sample_scene(seed, shapes=("semicircle", "rectangle",
                                             "triangle"))
      self.assertEqual(mpm.Scene.from_dict(copy.deepcopy(scene.to_dict())),
                       scene)


class SamplerTest(parameterized.TestCase):

  def test_deterministic_from_seed(self):
    for seed in (0, 1, 17):
      self.assertEqual(mpm.sample_scene(seed), mpm.sample_scene(seed))
    scenes = [mpm.sample_scene(s) for s in range(10)]
    self.assertLen({s.to_json() for s in scenes}, 10)

  def test_table_1_ranges(self):
    counts, shapes, xs = set(), set(), []
    for seed in range(200):
      scene = mpm.sample_scene(seed)
      self.assertEqual(scene.name, f"seed_{seed}")
      n = scene.granular.num_particles
      self.assertBetween(n, *sampler.PARTICLE_RANGE)
      self.assertBetween(len(scene.obstacles), *sampler.OBSTACLE_COUNT_RANGE)
      counts.add(len(scene.obstacles))
      for o in scene.obstacles:
        self.assertIn(o.shape, sampler.TRAIN_SHAPES)
        shapes.add(o.shape)
        self.assertBetween(o.x, *sampler.OBSTACLE_X_RANGE)
        xs.append(o.x)
        for key, (lo, hi) in sampler.SIZE_RANGES[o.shape].items():
          self.assertBetween(getattr(o, key), lo, hi)
      # Sampled obstacles never overlap.
      for i, a in enumerate(scene.obstacles):
        for b in scene.obstacles[:i]:
          self.assertGreaterEqual(abs(a.x - b.x), a.reach + b.reach)
    # Table 1 (700-1000 particles, 0-2 obstacles of the two training shapes).
    self.assertEqual(sampler.PARTICLE_RANGE, (700, 1000))
    self.assertEqual(sampler.OBSTACLE_COUNT_RANGE, (0, 2))
    self.assertEqual(sampler.OBSTACLE_X_RANGE, (0.5, 1.3))
    self.assertEqual(sampler.SIZE_RANGES["semicircle"]["radius"], (0.02, 0.05))
    self.assertEqual(sampler.SIZE_RANGES["rectangle"]["width"], (0.02, 0.06))
    self.assertEqual(sampler.SIZE_RANGES["rectangle"]["height"], (0.03, 0.07))
    # 200 draws cover every count, both shapes and most of the x range.
    self.assertEqual(counts, {0, 1, 2})
    self.assertEqual(shapes, set(sampler.TRAIN_SHAPES))
    self.assertLess(min(xs), 0.6)
    self.assertGreater(max(xs), 1.2)

  def test_fixed_choices(self):
    scene = mpm.sample_scene(3, num_particles=800, num_obstacles=2,
                             shapes=("triangle",), obstacle_x=(0.6, 1.2),
                             name="fixed", num_frames=10)
    self.assertEqual(scene.name, "fixed")
    self.assertEqual(scene.num_frames, 10)
    self.assertEqual(scene.granular.num_particles, 800)
    self.assertEqual([o.shape for o in scene.obstacles], ["triangle"] * 2)
    self.assertEqual([o.x for o in scene.obstacles], [0.6, 1.2])
    for o in scene.obstacles:
      self.assertBetween(o.base, *sampler.SIZE_RANGES["triangle"]["base"])
      self.assertBetween(o.height, *sampler.SIZE_RANGES["triangle"]["height"])

  def test_sampled_scene_has_its_particles(self):
    scene = mpm.sample_scene(5, num_obstacles=2)
    x = mpm.granular_particles(scene)
    self.assertEqual(x.shape, (scene.granular.num_particles, 2))
    # On the lattice, inside the box, clear of the ramp.
    x0, y0, x1, y1 = scene.granular.box
    self.assertTrue(np.all((x[:, 0] > x0) & (x[:, 0] < x1) &
                           (x[:, 1] > y0) & (x[:, 1] < y1)))
    self.assertTrue(np.all(x[:, 1] > scene.ramp.height(x[:, 0])))

  def test_rejects_inconsistent_arguments(self):
    with self.assertRaisesRegex(ValueError, "obstacle_x"):
      mpm.sample_scene(0, num_obstacles=2, obstacle_x=(0.7,))
    with self.assertRaisesRegex(ValueError, "shape"):
      sampler.sample_obstacle(np.random.default_rng(0), "hexagon")


if __name__ == "__main__":
  absltest.main()
