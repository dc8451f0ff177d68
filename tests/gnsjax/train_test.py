"""Tests for `gnsjax.train` and `gnsjax.checkpoint`."""

import dataclasses
import math
import os
import re
import signal
import subprocess
import sys
import tempfile
import time

from absl.testing import absltest
import jax
import numpy as np

import mpm
from gnsjax import checkpoint
from gnsjax import config as config_lib
from gnsjax import data
from gnsjax import features
from gnsjax import models
from gnsjax import run as run_lib
from gnsjax import simulator
from gnsjax import train
from mpm import io as mpm_io
from tests.gnsjax import fixtures

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(__file__)))
# The suite's compilation cache (tests/conftest.py), for the subprocesses.
CACHE = os.path.join(ROOT, ".jax_cache")


def assert_same_problem(test, got: run_lib.Problem, want: run_lib.Problem):
  for a, b in zip(got.stats, want.stats):
    np.testing.assert_allclose(a, b, rtol=1e-6)
  np.testing.assert_allclose(got.bounds, want.bounds, rtol=1e-6)
  test.assertEqual(dataclasses.replace(got, stats=None),
                   dataclasses.replace(want, stats=None))


class TrainTest(fixtures.TinyRunTestCase):

  def test_overfits_a_tiny_dataset(self):
    steps = 300
    config = fixtures.tiny_config(num_steps=steps, noise_std=0.0,
                                  lr_init=3e-3, batch_size=1)
    config.model.latent_size = 32
    config.log_every = 1
    config.checkpoint.every_steps = 1000
    train.train_and_evaluate(config, self.data, self.dir)
    losses = fixtures.logged_losses(self.dir)
    # Mean of the first and of the last ten steps (single windows are noisy).
    first = np.mean([losses[s] for s in range(1, 11)])
    last = np.mean([losses[s] for s in range(steps - 9, steps + 1)])
    self.assertLess(last, first / 10, f"loss {first:.3g} -> {last:.3g}")

  def test_checkpoint_round_trip(self):
    config = fixtures.tiny_config(num_steps=5)
    config.checkpoint.every_steps = 5
    train.train_and_evaluate(config, self.data, self.dir)
    problem = run_lib.load_problem(self.data, config)
    trainer = train.Trainer(config, problem)
    mngr = checkpoint.manager(self.dir, 5)
    state, stored_config, stats = checkpoint.restore(
        mngr, trainer.init_state(0))
    self.assertEqual(int(state.step), 5)
    self.assertEqual(stored_config["model"],
                     config_lib.config_dict(config)["model"])
    np.testing.assert_allclose(stats["acc_std"],
                               np.asarray(problem.stats.acc_std), rtol=1e-6)
    # Save again, restore: bit-identical parameters and optimiser state.
    checkpoint.save(mngr, 6, state, stored_config, stats, force=True)
    again, _, _ = checkpoint.restore(mngr, trainer.init_state(0), step=6)
    raw = lambda s: s.replace(key=jax.random.key_data(s.key))
    jax.tree.map(np.testing.assert_array_equal, raw(state), raw(again))
    mngr.close()
    # The run restored for inference alone: the same parameters and
    # problem, so the same predictions.
    run = run_lib.load_run(self.dir, step=5)
    self.assertEqual(run.step, 5)
    self.assertEqual(run.config.model.to_dict(), config.model.to_dict())
    jax.tree.map(np.testing.assert_array_equal, run.params, state.params)
    for got, want in zip(run.problem.stats, problem.stats):
      np.testing.assert_allclose(got, want, rtol=1e-6)
    assert_same_problem(self, run.problem, problem)
    with data.WindowDataset(data.split_path(self.data, "test"),
                            frame_stride=problem.frame_stride) as ds:
      batch = trainer.make_batch([ds[0], ds[1]])
    graphs, _ = trainer.batch_arrays(batch, None, noise=False)
    predict = lambda model, params: jax.vmap(
        lambda g: simulator.predict(model, params, g, run.problem.context,
                                    run.problem.radius))(graphs)
    np.testing.assert_array_equal(predict(run.model, run.params),
                                  predict(trainer.model, state.params))
    self.assertEqual(run_lib.load_run(self.dir).step, 6)
    with self.assertRaisesRegex(FileNotFoundError, "no checkpoint"):
      run_lib.load_run(os.path.join(self.dir, "empty"))

  def test_resumed_trainer_starts_at_the_checkpointed_graph_sizes(self):
    # The neighbour lists grow with the data a run has seen, and their sizes
    # are the shapes the train step runs at. A resumed run that allocated
    # afresh would run at other shapes, and XLA's kernels round differently
    # at other shapes: its losses drifted from the uninterrupted run's
    # (0.15% by 150 steps on the small config). So the sizes are saved.
    config = fixtures.tiny_config(capacity_multiplier=1.0)
    problem = run_lib.load_problem(self.data, config)
    with data.WindowDataset(data.split_path(self.data, "train"),
                            input_frames=problem.input_frames,
                            frame_stride=problem.frame_stride) as ds:
      batches = [[ds[k], ds[k + 1]] for k in range(0, len(ds) - 1, 2)]

    def capacities_after(trainer, chunks):
      for chunk in chunks:
        trainer.batch_arrays(trainer.make_batch(chunk), None, noise=False)
      return trainer.graph_capacities()

    seen = capacities_after(train.Trainer(config, problem), batches)
    # The batch a resumed run would start from: the one needing the fewest
    # edges, so that a fresh allocation would be smaller than `seen`.
    alone = [capacities_after(train.Trainer(config, problem), [b])
             for b in batches]
    (size,) = seen["train"]  # the node count of every batch (one bucket)
    smallest = int(np.argmin([c["train"][size][0] for c in alone]))
    self.assertLess(alone[smallest]["train"][size][0], seen["train"][size][0])
    # Through a checkpoint (JSON: string keys, None cell capacities).
    mngr = checkpoint.manager(self.dir, every_steps=1)
    trainer = train.Trainer(config, problem)
    checkpoint.save(mngr, 1, trainer.init_state(0), {}, {}, seen, force=True)
    stored = checkpoint.read_graph_capacities(mngr, 1)
    mngr.close()
    self.assertEqual(stored, seen)
    trainer.restore_graph_capacities(stored)
    self.assertEqual(capacities_after(trainer, [batches[smallest]]), seen)

  def test_resume_equals_uninterrupted(self):
    config = fixtures.tiny_config(num_steps=12)
    config.log_every = 1
    config.checkpoint.every_steps = 4
    full = os.path.join(self.dir, "full")
    train.train_and_evaluate(config, self.data, full)
    # A run killed by SIGKILL after some checkpoints, then restarted.
    killed = os.path.join(self.dir, "killed")
    script = (
        "import sys\n"
        "import jax\n"
        "from experiments import runtime\n"
        "runtime.enable_compilation_cache()\n"
        "jax.config.update('jax_persistent_cache_min_compile_time_secs', 0)\n"
        "from tests.gnsjax import fixtures\n"
        "from gnsjax import train\n"
        "config = fixtures.tiny_config(num_steps=100000)\n"
        "config.log_every = 1\n"
        "config.checkpoint.every_steps = 4\n"
        "train.train_and_evaluate(config, sys.argv[1], sys.argv[2])\n")
    env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu",
               GNSJAX_CACHE_DIR=CACHE)
    proc = subprocess.Popen([sys.executable, "-c", script, self.data, killed],
                            env=env, cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    ckpts = os.path.join(killed, "checkpoints")
    deadline = time.time() + 300
    while time.time() < deadline and proc.poll() is None:
      if os.path.isdir(ckpts) and any(d.isdigit() and int(d) >= 4
                                      for d in os.listdir(ckpts)):
        break
      time.sleep(0.1)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    restart_from = max(int(d) for d in os.listdir(ckpts) if d.isdigit())
    self.assertLess(restart_from, 12)
    train.train_and_evaluate(config, self.data, killed)
    want, got = fixtures.logged_losses(full), fixtures.logged_losses(killed)
    self.assertEqual(sorted(got), list(range(1, 13)))  # no step twice
    for step in range(1, 13):  # bit for bit
      self.assertEqual(got[step], want[step], f"step {step}")

  def test_bad_inputs(self):
    config = fixtures.tiny_config(num_steps=2)
    with self.assertRaisesRegex(ValueError, r"config.model: unknown key\(s\) "
                                r"\['latent_sise'\]"):
      bad = fixtures.tiny_config()
      bad.model.latent_sise = 3
      train.train_and_evaluate(bad, self.data, self.dir)
    train.train_and_evaluate(config, self.data, self.dir)
    other = fixtures.tiny_config(num_steps=4)
    other.model.latent_size = 8
    # InputError: the entry point reports it in one line (exit code 2).
    with self.assertRaisesRegex(mpm.InputError,
                                "trained with another config"):
      train.train_and_evaluate(other, self.data, self.dir)
    nostats = os.path.join(self.dir, "nostats")
    os.makedirs(nostats)
    with open(os.path.join(self.data, "train.h5"), "rb") as src, open(
        os.path.join(nostats, "train.h5"), "wb") as dst:
      dst.write(src.read())
    import h5py  # pylint: disable=g-import-not-at-top
    with h5py.File(os.path.join(nostats, "train.h5"), "a") as f:
      del f.attrs["acc_std"]
    with self.assertRaisesRegex(mpm_io.FormatError,
                                "no normalisation statistics"):
      train.train_and_evaluate(config, nostats, os.path.join(self.dir, "x"))
    # Values out of range are refused before anything is written.
    for section, key, value, message in (
        ("train", "num_steps", -5, "config.train.num_steps = -5; allowed: "
         ">= 1"),
        ("train", "batch_size", 0, "config.train.batch_size = 0; allowed"),
        ("train", "lr_init", math.nan, "config.train.lr_init = nan; allowed: "
         "a finite number"),
        ("model", "latent_size", 0, "config.model.latent_size = 0"),
        ("eval", "num_windows", 0, "config.eval.num_windows = 0")):
      bad = fixtures.tiny_config()
      bad[section][key] = value
      where = os.path.join(self.dir, f"bad_{key}")
      with self.assertRaisesRegex(mpm.InputError, re.escape(message)):
        train.train_and_evaluate(bad, self.data, where)
      self.assertFalse(os.path.exists(where))

  def test_a_diverging_loss_stops_and_keeps_the_last_finite_checkpoint(self):
    config = fixtures.tiny_config(num_steps=20, lr_init=1e30, lr_min=1e30)
    config.checkpoint.every_steps = 1
    with self.assertRaisesRegex(train.DivergedError,
                                r"the training loss is (nan|inf) at step "
                                r"(\d+); stopped, the latest checkpoint "
                                r"\(step (\d+)\)") as caught:
      train.train_and_evaluate(config, self.data, self.dir)
    bad_step, saved = map(int, re.search(
        r"at step (\d+).*\(step (\d+)\)", str(caught.exception)).groups())
    self.assertEqual(saved, bad_step - 1)
    run = run_lib.load_run(self.dir)
    self.assertEqual(run.step, saved)
    self.assertTrue(all(np.all(np.isfinite(p))
                        for p in jax.tree.leaves(run.params)))


  def test_fine_tuning_starts_from_the_checkpoint(self):
    base = os.path.join(self.dir, "base")
    config = fixtures.tiny_config(num_steps=3)
    config.checkpoint.every_steps = 3
    train.train_and_evaluate(config, self.data, base)
    tuned = os.path.join(self.dir, "tuned")
    fine = fixtures.tiny_config(num_steps=1, init_from=base, lr_init=0.0,
                                lr_min=0.0)
    fine.model.smooth_cutoff = 0.5
    fine.checkpoint.every_steps = 1
    train.train_and_evaluate(fine, self.data, tuned)
    got, want = run_lib.load_run(tuned), run_lib.load_run(base)
    self.assertEqual((got.step, got.model.smooth_cutoff), (1, 0.5))
    # A zero learning rate: the parameters are the checkpoint's, unchanged.
    jax.tree.map(np.testing.assert_array_equal, got.params, want.params)
    assert_same_problem(self, got.problem, want.problem)
    other = fixtures.tiny_config(num_steps=1, init_from=base)
    other.model.latent_size = 8
    with self.assertRaisesRegex(mpm.InputError, "init_from = .*'model'"):
      train.train_and_evaluate(other, self.data,
                               os.path.join(self.dir, "other"))

  def test_fine_tuning_may_add_a_velocity_gate(self):
    # The parent's parameters, and the gate's at their initial values; a
    # gated parent cannot lose its gate.
    base = os.path.join(self.dir, "base")
    config = fixtures.tiny_config(num_steps=2)
    config.checkpoint.every_steps = 2
    train.train_and_evaluate(config, self.data, base)
    gated = os.path.join(self.dir, "gated")
    fine = fixtures.tiny_config(num_steps=1, init_from=base, lr_init=0.0,
                                lr_min=0.0)
    fine.model.velocity_gate = True
    fine.checkpoint.every_steps = 1
    train.train_and_evaluate(fine, self.data, gated)
    got, want = run_lib.load_run(gated), run_lib.load_run(base)
    gate = got.params["params"].pop("velocity_gate")
    jax.tree.map(np.testing.assert_array_equal, got.params, want.params)
    np.testing.assert_array_equal(gate["kernel"], 0)
    np.testing.assert_allclose(gate["bias"] * models.GATE_GAIN,
                               models.GATE_LOGIT_INIT, rtol=1e-6)
    back = fixtures.tiny_config(num_steps=1, init_from=gated)
    with self.assertRaisesRegex(mpm.InputError, "init_from = .*'model'"):
      train.train_and_evaluate(back, self.data, os.path.join(self.dir, "b"))

  def test_trainable_modules_alone_learn(self):
    # A fine-tuning that trains the added gate alone: every other parameter
    # stays the parent's, the gate's moves; a module the model lacks is
    # refused by name.
    base = os.path.join(self.dir, "base")
    config = fixtures.tiny_config(num_steps=2)
    config.checkpoint.every_steps = 2
    train.train_and_evaluate(config, self.data, base)
    fine = fixtures.tiny_config(num_steps=2, init_from=base, lr_init=1e-2,
                                trainable="velocity_gate")
    fine.model.velocity_gate = True
    fine.checkpoint.every_steps = 2
    gated = os.path.join(self.dir, "gate_only")
    train.train_and_evaluate(fine, self.data, gated)
    got, want = run_lib.load_run(gated), run_lib.load_run(base)
    gate = got.params["params"].pop("velocity_gate")
    jax.tree.map(np.testing.assert_array_equal, got.params, want.params)
    self.assertGreater(np.abs(gate["kernel"]).max(), 0)
    wrong = fixtures.tiny_config(num_steps=1, init_from=base,
                                 trainable="velocity_gate,decodr")
    wrong.model.velocity_gate = True
    with self.assertRaisesRegex(mpm.InputError, "trainable.*'decodr'.*"
                                "allowed.*'decoder'"):
      train.train_and_evaluate(wrong, self.data, os.path.join(self.dir, "w"))

  def test_fine_tuning_takes_its_noise_from_the_config(self):
    # The parent's statistics (noise folded in), the config's noise: the
    # same noise a run from scratch with that config would draw.
    def run_at(fraction, name, init_from=""):
      config = fixtures.tiny_config(num_steps=1, init_from=init_from,
                                    lr_init=0.0, lr_min=0.0,
                                    noise_velocity_fraction=fraction,
                                    fold_noise=True)
      config.checkpoint.every_steps = 1
      workdir = os.path.join(self.dir, name)
      train.train_and_evaluate(config, self.data, workdir)
      return run_lib.load_run(workdir), config

    want, _ = run_at(0.25, "base")
    got, fine = run_at(0.1, "tuned", os.path.join(self.dir, "base"))
    for a, b in zip(got.problem.stats, want.problem.stats):
      np.testing.assert_array_equal(a, b)
    from_scratch = run_lib.load_problem(self.data, fine)
    self.assertAlmostEqual(got.problem.noise_std / from_scratch.noise_std,
                           1.0, places=5)
    self.assertAlmostEqual(got.problem.noise_std / want.problem.noise_std,
                           0.4, places=5)
    # A fine-tuning of the fine-tuning unfolds the noise folded into the
    # statistics (0.25's), not its parent's training noise (0.1's).
    twice, again = run_at(0.2, "twice", os.path.join(self.dir, "tuned"))
    self.assertAlmostEqual(
        twice.problem.noise_std
        / run_lib.load_problem(self.data, again).noise_std, 1.0, places=5)

  def test_checkpoints_before_smooth_cutoff_resume(self):
    # A run whose stored config predates the setting resumes (as 0, off).
    config = fixtures.tiny_config(num_steps=2)
    config.checkpoint.every_steps = 2
    train.train_and_evaluate(config, self.data, self.dir)
    mngr = checkpoint.manager(self.dir, 2)
    stored = checkpoint.read_config(mngr, 2)
    mngr.close()
    del stored["model"]["smooth_cutoff"]
    del stored["model"]["solid_range"]
    config_lib.check_compatible(stored, config)
    model = run_lib.create_model(stored["model"])
    self.assertEqual(model.smooth_cutoff, 0)
    self.assertIsNone(model.solid_range)

  def test_solid_range_must_be_a_positive_distance(self):
    config = fixtures.tiny_config(num_steps=2)
    config_lib.check_config(config)  # None: the connectivity radius
    config.model.solid_range = 0.06
    config_lib.check_config(config)
    self.assertEqual(run_lib.create_model(config.model).solid_range, 0.06)
    for bad in (0.0, -0.03):
      config.model.solid_range = bad
      with self.assertRaisesRegex(config_lib.InputError,
                                  r"config.model.solid_range = .*allowed: > 0"):
        config_lib.check_config(config)


class ProblemTest(absltest.TestCase):
  """The statistics, noise and settings a run is trained with."""

  STATS = features.Stats(np.array([1e-4, -2e-4], np.float32),
                         np.array([3e-4, 4e-4], np.float32),
                         np.array([0.0, -1e-5], np.float32),
                         np.array([2e-5, 1e-5], np.float32))

  def test_noise_std_of(self):
    config = fixtures.tiny_config(noise_std=3e-4)
    self.assertEqual(run_lib.noise_std_of(config.train, self.STATS), 3e-4)
    # A fraction of the RMS velocity std: 0.1 sqrt((3^2 + 4^2) / 2) 1e-4.
    config.train.noise_velocity_fraction = 0.1
    np.testing.assert_allclose(run_lib.noise_std_of(config.train, self.STATS),
                               0.1 * np.sqrt(12.5) * 1e-4, rtol=1e-6)

  def test_load_problem_folds_the_noise_at_the_stride(self):
    path = fixtures.tiny_dataset()
    config = fixtures.tiny_config(frame_stride=2, noise_velocity_fraction=0.2,
                                  fold_noise=True)
    problem = run_lib.load_problem(path, config)
    raw = data.load_stats(data.split_path(path, "train"), 2)
    noise = run_lib.noise_std_of(config.train, raw)
    np.testing.assert_allclose(
        noise, 0.2 * np.sqrt(np.mean(np.square(raw.vel_std))), rtol=1e-6)
    self.assertAlmostEqual(problem.noise_std, noise, places=12)
    for got, want in zip(problem.stats, features.fold_noise(raw, noise)):
      np.testing.assert_allclose(got, want, rtol=1e-6)
    self.assertEqual(problem.frame_stride, 2)
    self.assertEqual(problem.input_frames, config.train.input_frames)
    # sdf_spacing None: R / 6.
    self.assertAlmostEqual(problem.sdf_spacing, problem.radius / 6)
    # Without folding: the raw statistics, the same noise.
    config.train.fold_noise = False
    plain = run_lib.load_problem(path, config)
    for got, want in zip(plain.stats, raw):
      np.testing.assert_array_equal(got, want)
    # The checkpoint's record restores the problem.
    assert_same_problem(self, run_lib.problem_from_dict(config,
                                                      problem.to_dict()),
                        problem)

  def test_bad_recipe_settings_are_refused(self):
    for key, value, message in [
        ("frame_stride", 0, "frame_stride = 0"),
        ("pushforward_steps", -1, "pushforward_steps = -1"),
        ("pushforward_probability", 1.5, "pushforward_probability = 1.5"),
        ("rest_pushforward_steps", -2, "rest_pushforward_steps = -2"),
        ("rest_pushforward_probability", -0.1,
         "rest_pushforward_probability = -0.1"),
        ("unroll_steps", -1, "unroll_steps = -1"),
        ("unroll_probability", 2.0, "unroll_probability = 2.0"),
        ("motion_weighting", 2.0, "motion_weighting = 2.0")]:
      with self.assertRaisesRegex(ValueError, message):
        config_lib.check_config(fixtures.tiny_config(**{key: value}))


class DataParallelTest(absltest.TestCase):



  def test_two_devices_match_one(self):
    data = fixtures.tiny_dataset()
    script = (
        "import csv, json, sys\n"
        "import jax\n"
        "from experiments import runtime\n"
        "runtime.enable_compilation_cache()\n"
        "jax.config.update('jax_persistent_cache_min_compile_time_secs', 0)\n"
        "from tests.gnsjax import fixtures\n"
        "from gnsjax import train\n"
        "config = fixtures.tiny_config(num_steps=4, batch_size=2)\n"
        "config.log_every = 1\n"
        "train.train_and_evaluate(config, sys.argv[1], sys.argv[2])\n"
        "print('DEVICES', jax.local_device_count())\n")
    results = {}
    with tempfile.TemporaryDirectory() as d:
      # One device: this process's (the script's run, in this process).
      self.assertEqual(jax.local_device_count(), 1)
      config = fixtures.tiny_config(num_steps=4, batch_size=2)
      config.log_every = 1
      train.train_and_evaluate(config, data, os.path.join(d, "1"))
      results[1] = fixtures.logged_losses(os.path.join(d, "1"))
      for devices in (2,):
        env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu",
                   GNSJAX_CACHE_DIR=CACHE,
                   XLA_FLAGS=f"{os.environ.get('XLA_FLAGS', '')} "
                   f"--xla_force_host_platform_device_count={devices}")
        workdir = os.path.join(d, str(devices))
        out = subprocess.run([sys.executable, "-c", script, data, workdir],
                             env=env, cwd=ROOT, capture_output=True,
                             text=True, timeout=600)
        self.assertEqual(out.returncode, 0, out.stderr[-3000:])
        self.assertIn(f"DEVICES {devices}", out.stdout)
        results[devices] = fixtures.logged_losses(workdir)
    for step in range(1, 5):
      np.testing.assert_allclose(results[2][step], results[1][step],
                                 rtol=1e-4, err_msg=f"step {step}")


if __name__ == "__main__":
  absltest.main()
