"""Smoke test: train -> rollout -> render side by side -> evaluate, as a user
runs them (tiny dataset and model)."""

import os
import tempfile

from absl.testing import absltest

from gnsjax import train
from tests.experiments.entry_points_test import run
from tests.gnsjax import fixtures


class GnsEntryPointsTest(absltest.TestCase):

  def test_train_rollout_render_evaluate(self):
    data = fixtures.tiny_dataset()
    with tempfile.TemporaryDirectory() as d:
      workdir = os.path.join(d, "run")
      config = fixtures.tiny_config(num_steps=6)
      config.checkpoint.every_steps = 3
      config.checkpoint.named_steps = (3, 6)
      train.train_and_evaluate(config, data, workdir)
      rolled = os.path.join(d, "rollout")
      out = run("experiments.rollout", f"--workdir={workdir}",
                f"--data={data}", f"--out={rolled}", "--max_trajectories=1")
      self.assertIn("predicted.h5", out)
      run("experiments.render", f"--traj={rolled}/truth.h5",
          f"--compare={rolled}/predicted.h5", f"--out={d}/pictures",
          "--frames=0,8,15")
      self.assertTrue(os.path.getsize(f"{d}/pictures/animation.gif"))
      evaluation = os.path.join(d, "evaluation")
      out = run("experiments.evaluate", f"--workdir={workdir}",
                f"--data={data}", f"--out={evaluation}", "--timing_repeats=1")
      self.assertIn("test MSE", out)
      for name in ("report.md", "summary.json", "table2.csv",
                   "trajectories.csv", "fig3_training_loss.png",
                   "fig4_training_time.png", "fig5_test_error.png",
                   "fig6_obstacles.png", "fig8_shape.png"):
        self.assertTrue(os.path.exists(os.path.join(evaluation, name)), name)
      with open(os.path.join(evaluation, "report.md")) as f:
        report = f.read()
      self.assertIn("| 3 |", report)   # Fig. 5 has the named checkpoints
      self.assertIn("| 6 |", report)


if __name__ == "__main__":
  absltest.main()
