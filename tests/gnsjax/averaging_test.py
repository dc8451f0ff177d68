"""Tests for `gnsjax.averaging` (model soups)."""

import json
import os

from absl.testing import absltest
import jax
import numpy as np

import mpm
from gnsjax import averaging
from gnsjax import run as run_lib
from gnsjax import train
from tests.gnsjax import fixtures


class AverageParamsTest(absltest.TestCase):

  def test_weighted_mean_leaf_by_leaf(self):
    a = {"w": np.array([[1.0, 2.0]], np.float32), "b": np.array([4.0])}
    b = {"w": np.array([[3.0, -2.0]], np.float32), "b": np.array([0.0])}
    got = averaging.average_params([a, b], [0.25, 0.75])
    np.testing.assert_allclose(got["w"], [[2.5, -1.0]])
    np.testing.assert_allclose(got["b"], [1.0])
    self.assertEqual(got["w"].dtype, np.float32)
    one = averaging.average_params([a, b], [1.0, 0.0])
    jax.tree.map(np.testing.assert_array_equal, one, a)

  def test_a_head_some_trees_lack_averages_over_those_with_it(self):
    a = {"net": {"w": np.array([1.0])}}
    b = {"net": {"w": np.array([3.0])}, "gate": {"b": np.array([2.0])}}
    c = {"net": {"w": np.array([5.0])}, "gate": {"b": np.array([6.0])}}
    got = averaging.average_params([a, b, c], [0.5, 0.25, 0.25])
    np.testing.assert_allclose(got["net"]["w"], [2.5])
    np.testing.assert_allclose(got["gate"]["b"], [4.0])
    only = averaging.average_params([b, a], [0.0, 1.0])
    np.testing.assert_allclose(only["gate"]["b"], [2.0])

  def test_bad_weights_are_refused(self):
    a = {"w": np.zeros(2)}
    for weights, message in (([0.5, 0.4], "sum to 1"),
                             ([1.5, -0.5], ">= 0"),
                             ([1.0], "1 weights for 2 runs"),
                             ([float("nan"), 1.0], "finite")):
      with self.assertRaisesRegex(mpm.InputError, message):
        averaging.average_params([a, a], weights)


class WriteAverageTest(fixtures.TinyRunTestCase):

  def setUp(self):
    super().setUp()
    self.base = os.path.join(self.dir, "base")
    config = fixtures.tiny_config(num_steps=3)
    config.checkpoint.every_steps = 3
    train.train_and_evaluate(config, self.data, self.base)
    self.tuned = os.path.join(self.dir, "tuned")
    fine = fixtures.tiny_config(num_steps=2, init_from=self.base,
                                lr_init=1e-2)
    fine.checkpoint.every_steps = 2
    train.train_and_evaluate(fine, self.data, self.tuned)

  def test_the_average_is_a_run_that_loads_and_resumes(self):
    out = os.path.join(self.dir, "soup")
    got = averaging.write_average([self.base, self.tuned], [0.5, 0.5], out)
    base, tuned = run_lib.load_run(self.base), run_lib.load_run(self.tuned)
    # The runs differ (the mean is not vacuous) and the mean is by hand.
    self.assertFalse(all(jax.tree.leaves(jax.tree.map(
        np.array_equal, base.params, tuned.params))))
    jax.tree.map(lambda g, a, b: np.testing.assert_allclose(
        g, 0.5 * (np.asarray(a) + np.asarray(b)), rtol=1e-6, atol=1e-7),
                 got.params, base.params, tuned.params)
    self.assertEqual(got.step, tuned.step)
    self.assertEqual(got.problem.to_dict(), tuned.problem.to_dict())
    with open(os.path.join(out, averaging.RECORD)) as f:
      record = json.load(f)
    self.assertEqual(record["weights"], [0.5, 0.5])
    self.assertEqual([s["step"] for s in record["sources"]], [3, 2])
    # Training resumes from it: the last run's optimiser, averaged weights.
    more = fixtures.tiny_config(num_steps=3, init_from=self.base,
                                lr_init=1e-2)
    more.checkpoint.every_steps = 1
    train.train_and_evaluate(more, self.data, out)
    self.assertEqual(run_lib.load_run(out).step, 3)

  def test_one_runs_kept_checkpoints_average(self):
    # DIR@STEP: the mean of one run's own checkpoints, by hand.
    run = os.path.join(self.dir, "kept")
    config = fixtures.tiny_config(num_steps=3, lr_init=1e-2)
    config.checkpoint.every_steps = 1
    config.checkpoint.named_steps = (1, 2)
    train.train_and_evaluate(config, self.data, run)
    out = os.path.join(self.dir, "kept_soup")
    got = averaging.write_average([f"{run}@1", f"{run}@2"], [0.5, 0.5], out)
    one, two = run_lib.load_run(run, 1), run_lib.load_run(run, 2)
    self.assertFalse(all(jax.tree.leaves(jax.tree.map(
        np.array_equal, one.params, two.params))))
    jax.tree.map(lambda g, a, b: np.testing.assert_allclose(
        g, 0.5 * (np.asarray(a) + np.asarray(b)), rtol=1e-6, atol=1e-7),
                 got.params, one.params, two.params)
    self.assertEqual(got.step, 2)
    with open(os.path.join(out, averaging.RECORD)) as f:
      self.assertEqual([(s["workdir"], s["step"]) for s in
                        json.load(f)["sources"]],
                       [(os.path.normpath(run), 1), (os.path.normpath(run), 2)])
    with self.assertRaisesRegex(mpm.InputError,
                                r"no checkpoint '7'.*allowed: 1, 2, 3"):
      averaging.write_average([f"{run}@7", run], [0.5, 0.5],
                              os.path.join(self.dir, "bad"))

  def test_fine_tunings_at_other_noise_average(self):
    # A fine-tuning keeps its parent's statistics and draws its own noise:
    # it averages with the parent and the soup keeps the last run's noise.
    # A run from scratch at that noise folds it into other statistics and
    # is refused.
    def run(name, **train_settings):
      config = fixtures.tiny_config(num_steps=2, lr_init=1e-2,
                                    noise_velocity_fraction=0.4,
                                    fold_noise=True, **train_settings)
      config.checkpoint.every_steps = 2
      train.train_and_evaluate(config, self.data,
                               os.path.join(self.dir, name))
      return os.path.join(self.dir, name)

    noisier = run("noisier", init_from=self.base)
    base, tuned = run_lib.load_run(self.base), run_lib.load_run(noisier)
    self.assertNotAlmostEqual(tuned.problem.noise_std, base.problem.noise_std)
    got = averaging.write_average([self.base, noisier], [0.5, 0.5],
                                  os.path.join(self.dir, "soup"))
    self.assertEqual(got.problem.to_dict(), tuned.problem.to_dict())
    with self.assertRaisesRegex(mpm.InputError, "statistics differ"):
      averaging.write_average([self.base, run("scratch")], [0.5, 0.5],
                              os.path.join(self.dir, "bad"))

  def test_a_fine_tuning_that_adds_a_velocity_gate_averages(self):
    gated = os.path.join(self.dir, "gated")
    fine = fixtures.tiny_config(num_steps=2, init_from=self.base,
                                lr_init=1e-2)
    fine.model.velocity_gate = True
    fine.checkpoint.every_steps = 2
    train.train_and_evaluate(fine, self.data, gated)
    got = averaging.write_average([self.tuned, gated], [0.25, 0.75],
                                  os.path.join(self.dir, "soup"))
    tuned, gate = run_lib.load_run(self.tuned), run_lib.load_run(gated)
    self.assertTrue(got.config.model.velocity_gate)
    head = got.params["params"].pop("velocity_gate")
    jax.tree.map(np.testing.assert_allclose, head,
                 gate.params["params"].pop("velocity_gate"))
    jax.tree.map(lambda g, a, b: np.testing.assert_allclose(
        g, 0.25 * np.asarray(a) + 0.75 * np.asarray(b), rtol=1e-6,
        atol=1e-7), got.params, tuned.params, gate.params)
    with self.assertRaisesRegex(mpm.InputError,
                                "list a run with model.velocity_gate last"):
      averaging.write_average([gated, self.tuned], [0.5, 0.5],
                              os.path.join(self.dir, "bad"))
    self.assertFalse(os.path.exists(os.path.join(self.dir, "bad")))

  def test_runs_that_do_not_fit_together_are_refused(self):
    other = os.path.join(self.dir, "other")
    config = fixtures.tiny_config(num_steps=1)
    config.model.latent_size = 8
    config.checkpoint.every_steps = 1
    train.train_and_evaluate(config, self.data, other)
    with self.assertRaisesRegex(mpm.InputError, "model.latent_size is 8"):
      averaging.write_average([self.base, other], [0.5, 0.5],
                              os.path.join(self.dir, "bad"))
    with self.assertRaisesRegex(mpm.InputError, "two or more runs"):
      averaging.write_average([self.base], [1.0],
                              os.path.join(self.dir, "bad"))
    with self.assertRaisesRegex(mpm.InputError, "already holds checkpoints"):
      averaging.write_average([self.base, self.tuned], [0.5, 0.5],
                              self.tuned)
    self.assertFalse(os.path.exists(os.path.join(self.dir, "bad")))


if __name__ == "__main__":
  absltest.main()
