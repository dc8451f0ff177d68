"""Tests for `experiments.studies.evaluation`: the scores of a rollout, by
hand and on a tiny trained run at a frame stride; the study's settings, files
and report."""

import json
import os
import tempfile
from unittest import mock

from absl.testing import absltest
import numpy as np

import mpm
from experiments.studies import evaluation
from gnsjax import data
from gnsjax import features
from gnsjax import graph
from gnsjax import metrics
from gnsjax import rollout
from gnsjax import run as run_lib
from gnsjax import train
from mpm import io as mpm_io
from mpm import scene as scene_lib
from tests.gnsjax import fixtures

SCENE = mpm.Scene.from_dict({
    "name": "test/00003/rectangle", "domain": {"width": 0.4, "height": 0.3},
    "ramp": {"kind": "polyline", "points": [[0.0, 0.05], [0.4, 0.15]]},
    "obstacles": [{"shape": "rectangle", "x": 0.1, "width": 0.04,
                   "height": 0.03}],
    "granular": {"box": [0.25, 0.15, 0.35, 0.25], "spacing": 0.01,
                 "num_particles": 4}})


def constant_velocity_mse(positions, frames, c, k):
  """Mean over steps and particles of the squared error of carrying the
  velocity of frames (c - 2) k -> (c - 1) k on (plain numpy)."""
  last = (c - 1) * k
  v = (positions[last] - positions[last - k]) / k
  errors = [np.sum((positions[last] + v * (f - last) - positions[f])**2, -1)
            for f in frames]
  return float(np.mean(errors))


def synthetic_trajectory(frames=16):
  """4 particles accelerating down the slope: x = x0 + v t + a t^2 / 2."""
  t = np.arange(frames, dtype=np.float64)[:, None, None]
  x0 = np.array([[0.3, 0.2], [0.31, 0.2], [0.3, 0.21], [0.31, 0.21]])
  x = x0 + np.array([-1e-3, -2e-4]) * t + 0.5 * np.array([-2e-4, -5e-5]) * t**2
  return mpm_io.Trajectory(x.astype(np.float32), np.zeros((0, 2), np.float32),
                           np.zeros(0, np.int32), SCENE)


def problem(c, k):
  stats = features.Stats(*(np.full(2, v, np.float32)
                           for v in (0.0, 1e-3, 0.0, 1e-4)))
  bounds = ((0.0, 0.4), (0.0, 0.3))
  return run_lib.Problem(stats, graph.GraphSpec(0.03, bounds),
                         input_frames=c, frame_stride=k)


class ScoreTest(absltest.TestCase):

  def test_perfect_rollout(self):
    t = synthetic_trajectory()
    c, k = 3, 2
    frames = rollout.predicted_frame_indices(len(t.positions), c, k)
    np.testing.assert_array_equal(frames, [6, 8, 10, 12, 14])
    pushed = np.array([0, 1, 0, 2, 0], np.int32)
    depth = np.array([0.0, 1e-3, 0.0, 2e-3, 0.0], np.float32)
    out = rollout.Rollout(t.positions[frames], pushed, depth)
    s = evaluation.score(t, out, frames, problem(c, k))
    np.testing.assert_array_equal(s["mse"], 0.0)
    np.testing.assert_array_equal(s["runout_error"], 0.0)
    self.assertEqual(s["front_error_relative"], 0.0)
    self.assertEqual(s["deposit_error"], 0.0)
    np.testing.assert_array_equal(s["truth"], t.positions[frames])
    # The baseline carries the velocity of frames 2 -> 4 on.
    self.assertGreater(np.mean(s["mse_constant_velocity"]), 1e-8)
    np.testing.assert_allclose(
        np.mean(s["mse_constant_velocity"]),
        constant_velocity_mse(t.positions.astype(np.float64), frames, c, k),
        rtol=1e-4)
    np.testing.assert_array_equal(s["pushed_fraction"], pushed / 4)
    np.testing.assert_array_equal(s["pushed_depth"], depth)
    # At rest: the steps in the last REST_WINDOW_S (here all of them; with
    # a window of 5 frames the last three steps, frames 10-14).
    self.assertAlmostEqual(s["rest_pushed_fraction"], 3 / 20)
    with mock.patch.object(evaluation, "REST_WINDOW_S", 5 * SCENE.frame_dt):
      s = evaluation.score(t, out, frames, problem(c, k))
    self.assertAlmostEqual(s["rest_pushed_fraction"], 2 / 12)
    np.testing.assert_array_equal(s["inside_solids"], 0.0)
    np.testing.assert_array_equal(s["outside_domain"], 0.0)

  def test_rollout_that_leaves_the_domain_and_goes_into_the_ramp(self):
    t = synthetic_trajectory()
    c, k = 3, 1
    frames = rollout.predicted_frame_indices(len(t.positions), c, k)
    pred = t.positions[frames].copy()
    pred[-1, 0] = [0.3, 0.0]      # 12.5 cm below the ramp's surface
    pred[-1, 1] = [0.45, 0.2]     # 5 cm right of the domain
    out = rollout.Rollout(pred, np.zeros(len(frames), np.int32),
                          np.zeros(len(frames), np.float32))
    s = evaluation.score(t, out, frames, problem(c, k))
    np.testing.assert_array_equal(s["inside_solids"][:-1], 0.0)
    self.assertEqual(s["inside_solids"][-1], 0.25)
    self.assertEqual(s["outside_domain"][-1], 0.25)
    self.assertGreater(s["mse"][-1], 0.0)
    np.testing.assert_array_equal(s["mse"][:-1], 0.0)
    row = evaluation.per_trajectory_row({
        "index": 0, "name": SCENE.name, **evaluation.describe(SCENE), **s})
    self.assertEqual(row["group"], "rectangle")
    self.assertEqual(row["obstacles"], 1)
    self.assertEqual(row["max_inside_solids"], 0.25)
    self.assertEqual(row["max_outside_domain"], 0.25)
    np.testing.assert_allclose(row["mean_mse"], np.mean(s["mse"]))
    np.testing.assert_allclose(row["mean_mse_constant_velocity"],
                               constant_velocity_mse(t.positions, frames, c,
                                                     k), rtol=1e-4)
    self.assertNotIn("free_mean_mse", row)

  def test_group_summary(self):
    rows = [
        {"group": "a", "mean_mse": 1.0, "mean_mse_constant_velocity": 4.0,
         "front_error_relative": 0.1, "deposit_error": 0.01,
         "max_inside_solids": 0.0, "max_outside_domain": 0.0,
         "mean_pushed_fraction": 0.1, "max_pushed_depth": 1e-3,
         "final_speed": 0.1, "mpm_final_speed": 0.0,
         "kinetic_energy_ratio": 2.0},
        {"group": "a", "mean_mse": 3.0, "mean_mse_constant_velocity": 6.0,
         "front_error_relative": 0.3, "deposit_error": 0.03,
         "max_inside_solids": 0.2, "max_outside_domain": 0.1,
         "mean_pushed_fraction": 0.3, "max_pushed_depth": 2e-3,
         "final_speed": 0.3, "mpm_final_speed": 0.01,
         "kinetic_energy_ratio": 3000.0},
        {"group": "b", "mean_mse": 5.0, "mean_mse_constant_velocity": 2.0,
         "front_error_relative": 0.5, "deposit_error": 0.05,
         "max_inside_solids": 0.1, "max_outside_domain": 0.3,
         "mean_pushed_fraction": 0.2, "max_pushed_depth": 5e-3,
         "final_speed": 0.2, "mpm_final_speed": 0.15,
         "kinetic_energy_ratio": 10.0}]
    groups = {g["group"]: g for g in evaluation.group_summary(rows)}
    self.assertEqual(sorted(groups), ["a", "all", "b"])
    every, a = groups["all"], groups["a"]
    self.assertEqual(every["trajectories"], 3)
    self.assertAlmostEqual(every["mean_mse"], 3.0)
    self.assertAlmostEqual(every["mean_mse_constant_velocity"], 4.0)
    self.assertAlmostEqual(every["median_front_error_relative"], 0.3)
    self.assertAlmostEqual(every["max_front_error_relative"], 0.5)
    self.assertAlmostEqual(a["max_front_error_relative"], 0.3)
    self.assertAlmostEqual(every["max_inside_solids"], 0.2)
    self.assertAlmostEqual(every["max_outside_domain"], 0.3)
    self.assertAlmostEqual(every["max_pushed_depth"], 5e-3)
    self.assertAlmostEqual(every["median_final_speed"], 0.2)
    self.assertAlmostEqual(every["median_mpm_final_speed"], 0.01)
    self.assertAlmostEqual(every["median_kinetic_energy_ratio"], 10.0)
    self.assertAlmostEqual(every["max_kinetic_energy_ratio"], 3000.0)
    # Speed bounds 1, 2 and 30 cm/s: the first two end over theirs, the
    # third under; kinetic-energy ratios 2, 3000 and exactly 10.
    self.assertEqual(every["over_speed_bound"], 2)
    self.assertEqual(groups["b"]["over_speed_bound"], 0)
    self.assertEqual(every["over_kinetic_energy_ratio"], 1)
    self.assertEqual(groups["b"]["over_kinetic_energy_ratio"], 0)
    self.assertAlmostEqual(a["mean_mse"], 2.0)
    self.assertAlmostEqual(a["median_deposit_error"], 0.02)
    self.assertAlmostEqual(a["mean_pushed_fraction"], 0.2)
    self.assertNotIn("free_max_inside_solids", every)
    self.assertNotIn(evaluation.HELD_OUT, groups)
    self.assertNotIn(evaluation.UNSEEN_SHAPE, groups)

  def test_held_out_group_leaves_out_seen_scenes(self):
    base = {"mean_mse_constant_velocity": 1.0, "front_error_relative": 0.1,
            "deposit_error": 0.01, "max_inside_solids": 0.0,
            "max_outside_domain": 0.0, "mean_pushed_fraction": 0.0,
            "max_pushed_depth": 0.0, "final_speed": 0.0,
            "mpm_final_speed": 0.0}
    rows = [{**base, "group": "none", "mean_mse": 1.0, "seen": True},
            {**base, "group": "none", "mean_mse": 2.0, "seen": False},
            {**base, "group": "two", "mean_mse": 6.0, "seen": False}]
    groups = {g["group"]: g for g in evaluation.group_summary(rows)}
    held = groups[evaluation.HELD_OUT]
    self.assertEqual(held["trajectories"], 2)
    self.assertAlmostEqual(held["mean_mse"], 4.0)
    self.assertEqual(groups["all"]["trajectories"], 3)

  def test_unseen_shape_groups_split_by_the_shapes_training_draws(self):
    sizes = {"semicircle": dict(radius=0.04),
             "rectangle": dict(width=0.04, height=0.04),
             "triangle": dict(base=0.04, height=0.05)}
    scene = lambda *shapes: mpm.Scene(name="test/00000/two", obstacles=tuple(
        scene_lib.Obstacle(shape=s, x=0.8 + 0.2 * i, **sizes[s])
        for i, s in enumerate(shapes)))
    self.assertFalse(evaluation.describe(scene("semicircle", "rectangle"))[
        "unseen_shape"])
    self.assertTrue(evaluation.describe(scene("rectangle", "triangle"))[
        "unseen_shape"])
    base = {"group": "two", "mean_mse_constant_velocity": 1.0,
            "deposit_error": 0.01, "max_inside_solids": 0.0,
            "max_outside_domain": 0.0, "mean_pushed_fraction": 0.0,
            "max_pushed_depth": 0.0, "final_speed": 0.0,
            "mpm_final_speed": 0.0}
    rows = [{**base, "mean_mse": 1.0, "front_error_relative": 0.1,
             "unseen_shape": False},
            {**base, "mean_mse": 2.0, "front_error_relative": 0.6,
             "unseen_shape": True},
            {**base, "mean_mse": 4.0, "front_error_relative": 0.2,
             "unseen_shape": True}]
    groups = {g["group"]: g for g in evaluation.group_summary(rows)}
    unseen, seen = groups[evaluation.UNSEEN_SHAPE], groups[
        evaluation.SEEN_SHAPES]
    self.assertEqual((unseen["trajectories"], seen["trajectories"]), (2, 1))
    self.assertAlmostEqual(unseen["mean_mse"], 3.0)
    self.assertAlmostEqual(unseen["max_front_error_relative"], 0.6)
    self.assertAlmostEqual(seen["max_front_error_relative"], 0.1)


class RolloutSplitTest(absltest.TestCase):
  """``rollout_split`` of a tiny run trained at frame stride 2."""

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls._tmp = tempfile.TemporaryDirectory()
    workdir = cls.workdir = os.path.join(cls._tmp.name, "run")
    config = fixtures.tiny_config(num_steps=2, frame_stride=2)
    config.checkpoint.every_steps = 2
    cls.data = fixtures.tiny_dataset()
    train.train_and_evaluate(config, cls.data, workdir)
    cls.trained = run_lib.load_run(workdir)
    cls.path = data.split_path(cls.data, "test")
    cls.results = evaluation.rollout_split(cls.trained, cls.path,
                                           max_trajectories=2)

  @classmethod
  def tearDownClass(cls):
    cls._tmp.cleanup()
    super().tearDownClass()

  def test_scores_at_the_stride(self):
    self.assertEqual(self.trained.problem.frame_stride, 2)
    self.assertLen(self.results, 2)
    for r, t in zip(self.results, data.trajectories(self.path)):
      # 16 frames, inputs 0, 2, ..., 10: predictions at 12 and 14.
      np.testing.assert_array_equal(r["frames"], [12, 14])
      np.testing.assert_array_equal(r["truth"], t.positions[[12, 14]])
      self.assertEqual(r["predicted"].shape, (2,) + t.positions.shape[1:])
      np.testing.assert_allclose(
          r["mse"], np.mean(np.sum((r["predicted"] - r["truth"])**2, -1), -1),
          rtol=1e-6)
      np.testing.assert_allclose(
          np.mean(r["mse_constant_velocity"]),
          constant_velocity_mse(t.positions.astype(np.float64), [12, 14], 6,
                                2), rtol=1e-4)
      # The same model without the constraint was rolled out too.
      for key in ("free_inside_solids", "free_outside_domain", "free_mse"):
        self.assertEqual(np.shape(r[key]), (2,), key)
      self.assertEqual(r["pushed_fraction"].shape, (2,))
      self.assertEqual(r["group"], evaluation.describe(t.scene)["group"])
    row = evaluation.per_trajectory_row(self.results[0])
    self.assertIn("free_mean_mse", row)
    # Held at rest: the same model from the trajectory's last frames.
    t = next(data.trajectories(self.path))
    held = rollout.rollout_trajectory(self.trained.model, self.trained.params,
                                      t, self.trained.problem, 40,
                                      start=16 - 1 - 5 * 2).positions
    path = np.concatenate([t.positions[-1:], held])
    self.assertAlmostEqual(row["held_speed"], metrics.final_speed(
        path, np.arange(41) * 2 * t.scene.frame_dt), places=6)
    self.assertAlmostEqual(row["held_drift"], np.mean(np.linalg.norm(
        held[-1] - t.positions[-1], axis=-1)), places=6)
    summary = evaluation.group_summary(
        [evaluation.per_trajectory_row(r) for r in self.results])[0]
    self.assertEqual(summary["trajectories"], 2)
    self.assertIn("free_max_inside_solids", summary)
    self.assertIn("median_held_speed", summary)

  def test_run_writes_its_files_and_its_report_reads_the_summary(self):
    out = os.path.join(self._tmp.name, "evaluation")
    summary = evaluation.run(evaluation.Settings(
        workdir=self.workdir, data=self.data, max_trajectories=1,
        timing_repeats=1, checkpoint_errors=False, unconstrained=False), out)
    for name in ("summary.json", "report.md", "trajectories.csv",
                 "groups.csv", "table2.csv", "flow_checks.png",
                 "final_deposits.png"):
      self.assertTrue(os.path.exists(os.path.join(out, name)), name)
    # The same rollout as rollout_split's, without the unconstrained one.
    # Marked as seen or not from the tiny dataset's plan: its first test
    # scene (no obstacle) is in no training scene there.
    (row,) = summary["rows"]
    self.assertEqual(row, {
        **{k: v for k, v in
           evaluation.per_trajectory_row(self.results[0]).items()
           if not k.startswith("free_")}, "seen": False})
    with open(os.path.join(out, "report.md")) as f:
      self.assertEqual(f.read(), evaluation.report(summary))
    # The report needs nothing but the summary: the JSON written reads back.
    with open(os.path.join(out, "summary.json")) as f:
      self.assertEqual(evaluation.report(json.load(f)),
                       evaluation.report(summary))
    self.assertIn(f"| 0 | {row['group']} |", evaluation.report(summary))
    # Without the free rollout its columns say so (not "nan%").
    self.assertIn("| not run |", evaluation.report(summary))
    self.assertNotIn("nan", evaluation.report(summary))


class SettingsTest(absltest.TestCase):

  def test_refusals_name_the_flag(self):
    good = {"workdir": "run", "data": "data"}
    evaluation.Settings(**good)
    for changes, message in (
        ({"workdir": None}, "--workdir is required"),
        ({"data": None}, "--data is required"),
        ({"max_trajectories": 0}, "--max_trajectories=0: allowed: >= 1"),
        ({"timing_repeats": 0}, "--timing_repeats=0: allowed: >= 1"),
        ({"checkpoint_trajectories": 0},
         "--checkpoint_trajectories=0: allowed: >= 1")):
      with self.assertRaisesRegex(mpm.InputError, "^" + message,
                                  msg=str(changes)):
        evaluation.Settings(**(good | changes))


if __name__ == "__main__":
  absltest.main()
