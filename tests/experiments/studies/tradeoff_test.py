"""Tests for `experiments.studies.tradeoff`, the study behind
`experiments.tradeoff`: scenes redrawn at another spacing, the
resolution-free errors by hand, the settings' refusals, a tiny study end to
end (the MPM at two spacings and the shipped model) and ``run`` on one
scene."""

import math
import os
import tempfile

from absl.testing import absltest
import numpy as np

import mpm
from experiments.studies import tradeoff as study
from gnsjax import metrics
from gnsjax import run as run_lib
from gnsjax import tradeoff

PRETRAINED = "experiments/pretrained/small"


class ScenesTest(absltest.TestCase):

  def test_same_sand_area_and_solids_at_another_spacing(self):
    for s in study.study_scenes(7, num_frames=40):
      for spacing in (0.02, 0.01, 0.0035):
        finer = study.at_spacing(s, spacing)
        n0, n1 = s.granular.num_particles, finer.granular.num_particles
        self.assertAlmostEqual(n1 * spacing**2, n0 * s.granular.spacing**2,
                               delta=spacing**2 / 2 + 1e-12)
        self.assertAlmostEqual(finer.dx, 2 * spacing)
        self.assertEqual((finer.obstacles, finer.ramp, finer.granular.box,
                          finer.num_frames, finer.name),
                         (s.obstacles, s.ramp, s.granular.box, s.num_frames,
                          s.name))

  def test_the_plan_covers_every_test_group(self):
    groups = {s.name.split("/")[2] for s in study.study_scenes(14)}
    self.assertLen(groups, 7)
    self.assertIn("triangle", groups)

  def test_compare_frames_are_common_to_every_simulator(self):
    np.testing.assert_array_equal(study.compare_frames(61), [15, 30, 45, 60])
    np.testing.assert_array_equal(
        study.compare_frames(61, [range(18, 61, 3), range(6, 61)]),
        [30, 45, 60])
    with self.assertRaisesRegex(ValueError, "no frame common"):
      study.compare_frames(61, [[16, 17]])


class ScoreTest(absltest.TestCase):

  def setUp(self):
    super().setUp()
    self.scene = study.study_scenes(1)[0]   # no obstacle
    rng = np.random.default_rng(0)
    start = np.stack([rng.uniform(1.25, 1.45, 300),
                      rng.uniform(0.6, 0.8, 300)], -1)
    # The reference slides 0.6 m down x in 3 frames, 0.2 m per frame.
    self.reference = np.stack([start - [0.2 * k, 0.1 * k]
                               for k in (1, 2, 3)])
    self.start = start

  def test_the_reference_against_itself(self):
    errors = study.score(self.reference, self.reference, self.start,
                         self.scene)
    self.assertEqual(errors, {m: 0.0 for m in tradeoff.METRICS})

  def test_a_run_behind_the_reference(self):
    # 0.06 m behind at the end: 10% of the runout distance.
    run = self.reference + [0.02, 0.0] * np.arange(1, 4)[:, None, None]
    errors = study.score(run, self.reference, self.start, self.scene)
    self.assertAlmostEqual(errors["front_error"], 0.1, places=6)
    past = lambda x: np.mean(x[..., 0][..., None] < np.array(study.LINES),
                            -2)
    expected = np.max(np.mean(np.abs(past(run) - past(self.reference)), 0))
    self.assertAlmostEqual(errors["past_error"], expected)
    self.assertGreater(errors["past_error"], 0)
    self.assertGreater(errors["deposit_error"], 0)

  def test_sand_in_the_ramp_counts_as_inside(self):
    run = self.reference.copy()
    run[:, :30, 1] = 0.0   # below the ramp (its lowest point is above 0)
    errors = study.score(run, self.reference, self.start, self.scene)
    self.assertAlmostEqual(errors["inside"], 0.1)

  def test_a_broken_run_scores_nan(self):
    run = self.reference.copy()
    run[2, 5] = np.nan
    errors = study.score(run, self.reference, self.start, self.scene)
    self.assertTrue(all(math.isnan(v) for v in errors.values()))

  def test_mass_past_by_hand(self):
    x = np.array([[[0.1, 0], [0.5, 0], [0.9, 0], [1.3, 0]]])
    np.testing.assert_allclose(metrics.mass_past(x, np.array([1.0, 0.4])),
                               [[0.75, 0.25]])


class StudyTest(absltest.TestCase):
  """Two scenes, 31 frames: the MPM at 20 mm and at 10 mm (the reference),
  the shipped model starting from the reference's frames (its spacing)."""

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    scenes = study.study_scenes(2, num_frames=31)
    cls.coarse = study.run_mpm(scenes, 0.02, repeats=2, timing_scene=1,
                               batched=True)
    cls.reference = study.run_mpm(scenes, 0.01, repeats=1, timing_scene=1,
                                  batched=False)
    run = run_lib.load_run(PRETRAINED)
    cls.gns = study.run_gns("small", PRETRAINED, run, cls.reference,
                            repeats=1, timing_scene=1, batched=True)
    cls.frames = study.compare_frames(31, [cls.gns.frames])
    cls.rows = study.table_rows(cls.reference, [cls.coarse, cls.reference],
                                [cls.gns], cls.frames)

  def test_points(self):
    p = self.coarse.point
    self.assertEqual((p["name"], p["kind"], p["spacing"]), ("mpm_0.02",
                                                            "mpm", 0.02))
    self.assertLen(p["seconds_all"], 2)
    self.assertEqual(p["seconds"], np.median(p["seconds_all"]))
    self.assertGreater(p["seconds_batched"], 0)
    self.assertIsNone(self.reference.point["seconds_batched"])
    g = self.gns.point
    self.assertEqual((g["kind"], g["frame_stride"], g["spacing"]),
                     ("gns", 3, 0.01))
    self.assertGreater(g["training_s"], 3600)   # from its provenance
    self.assertGreater(g["seconds_batched"], 0)
    self.assertGreaterEqual(g["compile_batched_s"], 0)
    np.testing.assert_array_equal(self.frames, [30])

  def test_rows_score_against_the_reference(self):
    self.assertLen(self.rows, 2 * 3)
    for r in self.rows:
      if r["point"] == "mpm_0.01":
        self.assertEqual([r[m] for m in tradeoff.METRICS], [0.0] * 4)
      for m in tradeoff.METRICS:
        self.assertTrue(np.isfinite(r[m]), r)
    # The learned rollout's positions are compared at the same frame.
    g = next(r for r in self.rows if r["point"] == "small")
    f64 = lambda a: np.asarray(a, np.float64)
    ref = f64(self.reference.results[0].positions[30])
    pred = f64(self.gns.positions[0][list(self.gns.frames).index(30)])
    self.assertAlmostEqual(
        g["front_error"], metrics.front_error_relative(
            pred, ref, f64(self.reference.results[0].positions[0])))

  def test_summary_report_and_choice(self):
    points = [self.coarse.point, self.reference.point, self.gns.point]
    summary = study.summarise(points, self.rows)
    reference = next(e for e in summary if e["name"] == "mpm_0.01")
    self.assertTrue(reference["pareto"])   # exact, so never dominated
    table = {"points": points, "rows": self.rows,
             "frames": self.frames.tolist(), "num_frames": 31, "reference":
             self.reference.point, "scenes": [s.name for s in
                                              self.coarse.scenes],
             "environment": {"platform": "p", "cpu_count": 2,
                             "jax_version": "v", "jax_backend": "cpu",
                             "load_average_start": [0.5], "date": "d"}}
    text = study.report({
        "table": {**table, "command": "cmd"}, "configurations": summary,
        "tolerances": [0.5, 1e-9],
        "picks": study.picks(table, self.coarse.scenes, (0.5, 1e-9))})
    self.assertIn("Command: `cmd`", text)
    self.assertIn("| MPM, spacing 20 mm (dx 40 mm) |", text)
    self.assertIn("GNS small", text)
    # A tolerance only the reference meets (against itself): none.
    self.assertIn("| all | small (", text)
    self.assertRegex(text, r"\| all \| [^|]+ \| none \|")
    with self.assertRaisesRegex(mpm.InputError, "no configuration meets"):
      tradeoff.cheapest(table, 1e-9)


class SettingsTest(absltest.TestCase):

  def test_bad_settings_name_their_flags(self):
    study.Settings()
    bad = [({"spacings": (0.02, 0.0)}, "--spacings=0.0: allowed: > 0"),
           ({"reference_spacing": -1.0}, "--reference_spacing=-1.0: "
            "allowed: > 0"),
           ({"spacings": (0.02, 0.01), "reference_spacing": 0.015},
            "--reference_spacing=0.015 is coarser than --spacings' 0.01"),
           ({"gns": ("small",)}, "--gns item 'small'; allowed: NAME=WORKDIR"),
           ({"gns": ("a=x", "a=y")}, r"--gns: name\(s\) \['a'\] given "
            "twice"),
           ({"num_frames": 29}, "--num_frames=29: allowed: >= 30")]
    for changes, message in bad:
      with self.assertRaisesRegex(mpm.InputError, "^" + message,
                                  msg=str(changes)):
        study.Settings(**changes)
    self.assertEqual(study.Settings(gns=()).gns_workdirs(), [])

  def test_a_run_trained_elsewhere_is_refused_before_anything_is_written(
      self):
    with tempfile.TemporaryDirectory() as d:
      out = os.path.join(d, "out")
      with self.assertRaisesRegex(mpm.InputError, "^--gns small: trained at "
                                  "spacing 0.01 m, which is not in "
                                  "--spacings"):
        study.run(study.Settings(spacings=(0.02,), reference_spacing=0.02,
                                 gns=(f"small={PRETRAINED}",)), out)
      self.assertFalse(os.path.exists(out))


class RunTest(absltest.TestCase):
  """``run`` on one scene, the MPM alone at 40 mm against 20 mm."""

  def test_writes_the_table_the_library_reads(self):
    s = study.Settings(spacings=(0.02, 0.04), reference_spacing=0.02,
                       scenes=1, num_frames=30, repeats=1, gns=())
    with tempfile.TemporaryDirectory() as d:
      summary = study.run(s, d)
      self.assertCountEqual(os.listdir(d), [
          "tradeoff.json", "tradeoff.md", "points.csv", "rows.csv",
          "tradeoff.png", "tradeoff_batched.png"])
      table = tradeoff.load(os.path.join(d, "tradeoff.json"))
      with open(os.path.join(d, "tradeoff.md")) as f:
        self.assertEqual(f.read(), study.report(summary))
    self.assertEqual(table["settings"], s.to_dict())
    # Coarse to fine, whatever the order asked.
    self.assertEqual([p["name"] for p in table["points"]],
                     ["mpm_0.04", "mpm_0.02"])
    # The reference (2 cm) is never the answer, however tight the tolerance.
    with self.assertRaisesRegex(mpm.InputError, "mpm_0.04, reaches"):
      tradeoff.cheapest(table, 1e-9)
    self.assertEqual([p["scenes"] for p in summary["picks"]],
                     ["all", "none"])
    self.assertIn("Settings: `{", study.report(summary))


if __name__ == "__main__":
  absltest.main()
