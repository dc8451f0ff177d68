"""The shipped small model: it loads as `make demo` loads it, and is what its
provenance says it is."""

import json
import os

from absl.testing import absltest
import jax
import numpy as np

from experiments import tasks
from gnsjax import train


class PretrainedTest(absltest.TestCase):

  def test_loads_at_the_step_its_provenance_names(self):
    with open(os.path.join(tasks.PRETRAINED, "provenance.json")) as f:
      provenance = json.load(f)
    steps = os.listdir(os.path.join(tasks.PRETRAINED, "checkpoints"))
    # One step directory, as a checkpoint manager writes it (the demo copies
    # it into its own work directory and resumes from it).
    self.assertEqual(steps, [str(provenance["step"])])
    run = train.load_run(tasks.PRETRAINED)
    self.assertEqual(run.step, provenance["step"])
    self.assertEqual(run.config.model.to_dict(), provenance["config"]["model"])
    leaves = jax.tree.leaves(run.params)
    self.assertTrue(all(np.all(np.isfinite(x)) for x in leaves))
    self.assertEqual(run.problem.frame_stride,
                     provenance["config"]["train"]["frame_stride"])


if __name__ == "__main__":
  absltest.main()
