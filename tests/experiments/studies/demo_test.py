"""Tests for `experiments.studies.demo`: the shipped small model loads as
`make demo` loads it, and is what its provenance says it is."""

import json
import os
import shutil
import tempfile

from absl.testing import absltest
import jax
import numpy as np

import mpm
from experiments.studies import demo
from experiments.studies import settings
from gnsjax import run as run_lib


class PretrainedTest(absltest.TestCase):

  def test_loads_at_the_step_its_provenance_names(self):
    with open(os.path.join(settings.PRETRAINED, "provenance.json")) as f:
      provenance = json.load(f)
    steps = os.listdir(os.path.join(settings.PRETRAINED, "checkpoints"))
    # One step directory, as a checkpoint manager writes it (the demo copies
    # it into its own work directory and resumes from it).
    self.assertEqual(steps, [str(provenance["step"])])
    run = run_lib.load_run(settings.PRETRAINED)
    self.assertEqual(run.step, provenance["step"])
    self.assertEqual(run.config.model.to_dict(), provenance["config"]["model"])
    leaves = jax.tree.leaves(run.params)
    self.assertTrue(all(np.all(np.isfinite(x)) for x in leaves))
    self.assertEqual(run.problem.frame_stride,
                     provenance["config"]["train"]["frame_stride"])

  def test_demo_refuses_a_run_of_another_shipped_model(self):
    # After the shipped model changes, a demo's old work directory would
    # resume its own run and show the old model: refused, naming it.
    tmp_dir = tempfile.TemporaryDirectory()
    self.addCleanup(tmp_dir.cleanup)
    tmp = tmp_dir.name
    source = os.path.join(tmp, "shipped")
    shutil.copytree(settings.PRETRAINED, source)
    workdir = os.path.join(tmp, "run")
    step = demo.ship_checkpoint(source, workdir)
    self.assertEqual(demo.ship_checkpoint(source, workdir), step)  # resumes
    self.assertEqual(run_lib.load_run(workdir).step, step)
    with open(os.path.join(source, "provenance.json"), "a") as f:
      f.write("\n")  # another shipped model
    with self.assertRaisesRegex(mpm.InputError, "another shipped model"):
      demo.ship_checkpoint(source, workdir)
    fresh = os.path.join(tmp, "fresh")
    self.assertEqual(demo.ship_checkpoint(source, fresh), step)



if __name__ == "__main__":
  absltest.main()
