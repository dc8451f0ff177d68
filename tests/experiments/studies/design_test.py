"""Tests for `experiments.studies.design`: the study on a short scene with a
tiny trained GNS, and its refusals."""

import json
import os
import tempfile

from absl.testing import absltest

import mpm
from experiments.studies import design
from gnsjax import train
from tests.gnsjax import fixtures


class DesignTest(absltest.TestCase):

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    # A tiny run of the new recipe: two stored frames per learned step, the
    # solids seen through the SDF only.
    cls._tmp = tempfile.TemporaryDirectory()
    cls.workdir = os.path.join(cls._tmp.name, "run")
    config = fixtures.tiny_config(num_steps=2, frame_stride=2)
    config.model.boundary_particles = False
    config.checkpoint.every_steps = 2
    train.train_and_evaluate(config, fixtures.tiny_dataset(), cls.workdir)

  @classmethod
  def tearDownClass(cls):
    cls._tmp.cleanup()
    super().tearDownClass()

  def test_gns_study_writes_history_sweep_plot_and_verdict(self):
    out = tempfile.mkdtemp()
    # 16 frames: inputs 0, 2, ..., 10, learned steps to 12 and 14.
    summary = design.run(design.Settings(
        shape="semicircle", size=(0.03,), x0=1.28, num_frames=16,
        simulator="gns", objective="centroid", target_x=1.0, steps=2,
        learning_rate=0.01, sweep_points=2, workdir=self.workdir), out)
    for name in ("history.csv", "sweep.csv", "objective_vs_x.png",
                 "summary.json", "report.md"):
      self.assertTrue(os.path.exists(os.path.join(out, name)), name)
    with open(os.path.join(out, "summary.json")) as f:
      self.assertEqual(json.load(f)["simulator"], "gns")
    # The optimiser moved x by at most one step per iteration, in range.
    self.assertLessEqual(abs(summary["optimiser"]["best_x"] - 1.28), 0.0101)
    v = summary["mpm_verdict"]
    self.assertEqual(summary["improved_under_mpm"],
                     v["optimum"]["plain"] < v["start"]["plain"])
    self.assertEqual(summary["sweep"]["points"], 2)

  def test_bad_inputs_are_refused(self):
    for changes, message in (
        ({"x0": 1.4}, r"^--x0=1.4; allowed: \[0.5, 1.3\] m"),
        ({"size": (0.03, 0.04)}, r"^--size=0.03,0.04: a semicircle needs "
         r"\['radius'\]; allowed: positive lengths in m"),
        ({"size": (0.06,), "optimise_size": True},
         r"radius in \[0.02, 0.05\] m \(--optimise_size\)"),
        ({"simulator": "fem"}, r"^--simulator=fem: allowed: one of"),
        ({"workdir": ""}, r"^--simulator=gns needs --workdir"),
        ({"method": "adam_smoothed", "num_samples": 3},
         r"^--num_samples=3; allowed: an even number"),
        ({"temperature": 0.0}, r"^--temperature=0.0: allowed: > 0")):
      with self.assertRaisesRegex(mpm.InputError, message, msg=str(changes)):
        design.Settings(**changes)
    # An odd sample count is no error where nothing is smoothed.
    design.Settings(num_samples=3)
    scene = os.path.join(self._tmp.name, "no_obstacle.json")
    with open(scene, "w") as f:
      json.dump({"name": "none", "num_frames": 12}, f)
    with self.assertRaisesRegex(mpm.InputError, "no obstacle to design"):
      design.run(design.Settings(scene=scene, simulator="mpm", workdir=""),
                 os.path.join(self._tmp.name, "never"))
    self.assertFalse(os.path.exists(os.path.join(self._tmp.name, "never")))
    with self.assertRaisesRegex(ValueError, "must exceed the 6 input frames "
                                "at stride 2"):
      design.run(design.Settings(num_frames=12, workdir=self.workdir),
                 tempfile.mkdtemp())


if __name__ == "__main__":
  absltest.main()
