"""Tests for `experiments.studies.demo`: the shipped small model loads as
`make demo` loads it and is what its provenance says it is; the demo runs as
a user runs it (tiny settings) and refuses what it cannot run."""

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
from gnsjax import config as config_lib
from gnsjax import run as run_lib
from mpm import io as mpm_io
from tests.experiments import entry_points_test


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

  def test_the_fine_tuning_keeps_the_shipped_models_recipe(self):
    stored = run_lib.load_run(settings.PRETRAINED).config
    shipped, model = stored.train.to_dict(), stored.model.to_dict()
    config = demo.demo_config(4, 1, 5200, recipe=shipped, model=model)
    plain = demo.demo_config(4, 1, 5200)
    for key in demo.RECIPE_KEYS:
      if key in shipped:
        self.assertEqual(config.train[key], shipped[key], key)
    # The shipped model's architecture, so its checkpoint resumes.
    config_lib.check_compatible(stored.to_dict(), config)
    # Only the recipe and the model: the demo's own data, length and rate
    # stay.
    for section in ("dataset", "checkpoint", "eval"):
      self.assertEqual(config[section].to_dict(), plain[section].to_dict())
    self.assertEqual(config.train.num_steps, 5200)
    self.assertEqual(config.train.lr_init, 1.5e-5)
    # The shipped model trained with pushforward, which the small config
    # leaves off: the recipe is not the small config's.
    self.assertGreater(config.train.pushforward_steps, 0)
    self.assertEqual(plain.train.pushforward_steps, 0)

  def _copy_of_shipped(self, name):
    """(a temporary directory, a copy of the shipped model in it)."""
    tmp_dir = tempfile.TemporaryDirectory()
    self.addCleanup(tmp_dir.cleanup)
    copy = os.path.join(tmp_dir.name, name)
    shutil.copytree(settings.PRETRAINED, copy)
    return tmp_dir.name, copy

  def test_demo_refuses_a_run_of_another_shipped_model(self):
    # After the shipped model changes, a demo's old work directory would
    # resume its own run and show the old model: refused, naming it.
    tmp, source = self._copy_of_shipped("shipped")
    workdir = os.path.join(tmp, "run")
    step = demo.ship_checkpoint(source, workdir)
    self.assertEqual(demo.ship_checkpoint(source, workdir), step)  # resumes
    self.assertEqual(run_lib.load_run(workdir).step, step)
    with open(os.path.join(source, "provenance.json"), "a") as f:
      f.write("\n")  # another shipped model
    with self.assertRaisesRegex(mpm.InputError, "another model"):
      demo.ship_checkpoint(source, workdir)
    fresh = os.path.join(tmp, "fresh")
    self.assertEqual(demo.ship_checkpoint(source, fresh), step)

  def test_demo_starts_from_a_run_named_by_model(self):
    # --model: a run or an averaged run, which has no provenance.json; the
    # run is told from another by its directory and config.
    tmp, run_dir = self._copy_of_shipped("run_a")
    os.remove(os.path.join(run_dir, "provenance.json"))
    workdir = os.path.join(tmp, "demo_run")
    step = demo.ship_checkpoint(run_dir, workdir)
    self.assertEqual(demo.ship_checkpoint(run_dir, workdir), step)
    self.assertEqual(run_lib.load_run(workdir).step, step)
    other = os.path.join(tmp, "run_b")
    shutil.copytree(run_dir, other)
    with self.assertRaisesRegex(mpm.InputError, "another model.*run_b"):
      demo.ship_checkpoint(other, workdir)
    empty = os.path.join(tmp, "empty")
    os.makedirs(empty)
    with self.assertRaisesRegex(
        mpm.InputError, f"^--model={empty}: no trained model there"):
      demo.ship_checkpoint(empty, os.path.join(tmp, "demo_empty"))



class DemoTest(absltest.TestCase):

  def test_settings_refusals_name_the_flag(self):
    demo.Settings()
    for changes, message in (
        ({"num_frames": demo.MIN_FRAMES - 1},
         f"--num_frames={demo.MIN_FRAMES - 1}: allowed: >= 19"),
        ({"finetune_steps": 0}, "--finetune_steps=0: allowed: >= 1"),
        ({"num_train": 0}, "--num_train=0: allowed: >= 1"),
        ({"workers": 0}, "--workers=0: allowed: >= 1")):
      with self.assertRaisesRegex(mpm.InputError, "^" + message,
                                  msg=str(changes)):
        demo.Settings(**changes)

  def test_report(self):
    text = demo.report({"metrics": {"scene": "test/00005/triangle",
                                    "learned_steps": 2,
                                    "gns_mean_mse_m2": 1.23456e-5},
                        "paths": {"metrics": "out/metrics.json"}})
    self.assertIn("| scene | test/00005/triangle |", text)
    self.assertIn("| gns_mean_mse_m2 | 1.235e-05 |", text)
    self.assertIn("| metrics | `out/metrics.json` |", text)

  def test_demo(self):
    # As `make demo` runs it (the entry point), on a tiny default. The small
    # config learns steps of 3 frames from 6 inputs: windows of 19 frames;
    # 22 leave two learned steps after frame 15 (18 and 21). One dataset
    # worker: a second would import jax and compile the MPM again (workers
    # in parallel: tests/mpm/dataset_test.py, generate(workers=2)).
    tmp = tempfile.TemporaryDirectory()
    self.addCleanup(tmp.cleanup)
    out_dir = os.path.join(tmp.name, "demo")
    out = entry_points_test.run(
        "experiments.demo", f"--out={out_dir}", "--num_frames=22",
        "--num_train=2", "--finetune_steps=2", "--nopretrained",
        "--workers=1")
    for name in ("metrics.json", "animation.gif", "frames.png", "truth.h5",
                 "predicted.h5"):
      self.assertIn(name, out)
      self.assertTrue(os.path.exists(os.path.join(out_dir, name)))
    with open(os.path.join(out_dir, "metrics.json")) as f:
      metrics = json.load(f)
    self.assertIn("triangle", metrics["scene"])
    self.assertGreater(metrics["constant_velocity_mean_mse_m2"], 0)
    self.assertEqual(metrics["frame_stride"], 3)
    self.assertEqual(metrics["learned_steps"], 2)
    self.assertEqual(metrics["fine_tuned_from"], 0)
    # The files hold the 6 input frames at the stride, then the predictions.
    (truth,) = mpm_io.read_trajectories(os.path.join(out_dir, "truth.h5"))
    (predicted,) = mpm_io.read_trajectories(os.path.join(out_dir,
                                                         "predicted.h5"))
    self.assertEqual(truth.positions.shape[0], 8)
    self.assertEqual(predicted.positions.shape, truth.positions.shape)
    np.testing.assert_array_equal(predicted.positions[:6],
                                  truth.positions[:6])
    self.assertAlmostEqual(truth.scene.frame_dt, 3 * 0.0025)


if __name__ == "__main__":
  absltest.main()
