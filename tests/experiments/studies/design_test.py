"""The inverse-design entry point's job on a short scene."""

import json
import os
import tempfile

from absl.testing import absltest

from experiments import tasks
from gnsjax import train
from tests.gnsjax import fixtures


class InverseDesignTest(absltest.TestCase):

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
    summary = tasks.inverse_design(
        out, shape="semicircle", size=(0.03,), x0=1.28, num_frames=16,
        simulator="gns", objective="centroid", target_x=1.0, steps=2,
        learning_rate=0.01, sweep_points=2, workdir=self.workdir)
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
    with self.assertRaisesRegex(ValueError, r"x = 1.4.*\[0.5, 1.3\]"):
      tasks.inverse_design(tempfile.mkdtemp(), x0=1.4, num_frames=12,
                           simulator="mpm", workdir=None)
    with self.assertRaisesRegex(ValueError, "semicircle needs 1"):
      tasks.inverse_design(tempfile.mkdtemp(), size=(0.03, 0.04),
                           num_frames=12)
    with self.assertRaisesRegex(ValueError, "must exceed the 6 input frames "
                                "at stride 2"):
      tasks.inverse_design(tempfile.mkdtemp(), num_frames=12,
                           simulator="gns", workdir=self.workdir)
    with self.assertRaisesRegex(ValueError, "simulator.*allowed"):
      tasks.inverse_design(tempfile.mkdtemp(), simulator="fem",
                           num_frames=12, workdir=None)


if __name__ == "__main__":
  absltest.main()
