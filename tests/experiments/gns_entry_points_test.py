"""Smoke test: train -> rollout -> render side by side -> evaluate, as a user
runs them (tiny dataset and model)."""

import csv
import json
import os
import tempfile

from absl.testing import absltest
import numpy as np

from gnsjax import data
from gnsjax import train
from tests.experiments.entry_points_test import run
from tests.gnsjax import fixtures


class GnsEntryPointsTest(absltest.TestCase):

  def test_train_rollout_render_evaluate(self):
    data_dir = fixtures.tiny_dataset()
    with tempfile.TemporaryDirectory() as d:
      workdir = os.path.join(d, "run")
      config = fixtures.tiny_config(num_steps=6)
      config.checkpoint.every_steps = 3
      config.checkpoint.named_steps = (3, 6)
      train.train_and_evaluate(config, data_dir, workdir)
      rolled = os.path.join(d, "rollout")
      out = run("experiments.rollout", f"--workdir={workdir}",
                f"--data={data_dir}", f"--out={rolled}",
                "--max_trajectories=1")
      self.assertIn("predicted.h5", out)
      run("experiments.render", f"--traj={rolled}/truth.h5",
          f"--compare={rolled}/predicted.h5", f"--out={d}/pictures",
          "--frames=0,8,15")
      self.assertTrue(os.path.getsize(f"{d}/pictures/animation.gif"))
      evaluation = os.path.join(d, "evaluation")
      out = run("experiments.evaluate", f"--workdir={workdir}",
                f"--data={data_dir}", f"--out={evaluation}",
                "--timing_repeats=1")
      self.assertIn("test MSE", out)
      for name in ("report.md", "summary.json", "table2.csv",
                   "trajectories.csv", "groups.csv", "flow_checks.png",
                   "fig3_training_loss.png",
                   "fig4_training_time.png", "fig5_test_error.png",
                   "fig6_obstacles.png", "fig8_shape.png"):
        self.assertTrue(os.path.exists(os.path.join(evaluation, name)), name)
      with open(os.path.join(evaluation, "report.md")) as f:
        report = f.read()
      self.assertIn("| 3 |", report)   # Fig. 5 has the named checkpoints
      self.assertIn("| 6 |", report)
      # The constant-velocity baseline (what --baseline printed), by hand:
      # the velocity of the last two input frames carried on.
      self.assertIn("(constant velocity", out)
      with open(os.path.join(evaluation, "summary.json")) as f:
        summary = json.load(f)
      with open(os.path.join(evaluation, "trajectories.csv"),
                newline="") as f:
        rows = list(csv.DictReader(f))
      c = config.train.input_frames
      want = []
      for t in data.trajectories(data.split_path(data_dir, "test")):
        x = t.positions.astype(np.float64)
        v = x[c - 1] - x[c - 2]
        steps = np.arange(1, len(x) - c + 1)[:, None, None]
        want.append(np.mean(np.sum((x[c - 1] + steps * v - x[c:])**2, -1)))
      self.assertLen(rows, len(want))
      np.testing.assert_allclose(
          [float(r["mean_mse_constant_velocity"]) for r in rows], want,
          rtol=1e-4)
      np.testing.assert_allclose(summary["test_mse_constant_velocity"],
                                 np.mean(want), rtol=1e-4)
      self.assertIn(f"{summary['test_mse_constant_velocity']:.3e} m^2)",
                    report)


if __name__ == "__main__":
  absltest.main()
