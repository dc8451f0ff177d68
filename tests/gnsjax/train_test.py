"""Tests for `gnsjax.train` and `gnsjax.checkpoint`."""

import csv
import os
import signal
import subprocess
import sys
import tempfile
import time

from absl.testing import absltest
import jax
import numpy as np

from gnsjax import checkpoint
from gnsjax import train
from mpm import io as mpm_io
from tests.gnsjax import fixtures

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(__file__)))


def _losses(workdir):
  with open(os.path.join(workdir, "metrics.csv"), newline="") as f:
    return {int(r["step"]): float(r["loss"]) for r in csv.DictReader(f)}


class TrainTest(absltest.TestCase):

  def setUp(self):
    super().setUp()
    tmp = tempfile.TemporaryDirectory()
    self.addCleanup(tmp.cleanup)
    self.dir = tmp.name
    self.data = fixtures.tiny_dataset()

  def test_overfits_a_tiny_dataset(self):
    steps = 300
    config = fixtures.tiny_config(num_steps=steps, noise_std=0.0,
                                  lr_init=3e-3, batch_size=1)
    config.model.latent_size = 32
    config.log_every = 1
    config.checkpoint.every_steps = 1000
    train.train_and_evaluate(config, self.data, self.dir)
    losses = _losses(self.dir)
    # Mean of the first and of the last ten steps (single windows are noisy).
    first = np.mean([losses[s] for s in range(1, 11)])
    last = np.mean([losses[s] for s in range(steps - 9, steps + 1)])
    self.assertLess(last, first / 10, f"loss {first:.3g} -> {last:.3g}")

  def test_checkpoint_round_trip(self):
    config = fixtures.tiny_config(num_steps=5)
    config.checkpoint.every_steps = 5
    train.train_and_evaluate(config, self.data, self.dir)
    problem = train.load_problem(self.data, config)
    trainer = train.Trainer(config, problem)
    mngr = checkpoint.manager(self.dir, 5)
    state, stored_config, stats = checkpoint.restore(
        mngr, trainer.init_state(0))
    self.assertEqual(int(state.step), 5)
    self.assertEqual(stored_config["model"],
                     train._config_dict(config)["model"])
    np.testing.assert_allclose(stats["acc_std"],
                               np.asarray(problem.stats.acc_std), rtol=1e-6)
    # Save again, restore: bit-identical parameters and optimiser state.
    checkpoint.save(mngr, 6, state, stored_config, stats, force=True)
    again, _, _ = checkpoint.restore(mngr, trainer.init_state(0), step=6)
    raw = lambda s: s.replace(key=jax.random.key_data(s.key))
    jax.tree.map(np.testing.assert_array_equal, raw(state), raw(again))
    mngr.close()

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
        "from tests.gnsjax import fixtures\n"
        "from gnsjax import train\n"
        "config = fixtures.tiny_config(num_steps=100000)\n"
        "config.log_every = 1\n"
        "config.checkpoint.every_steps = 4\n"
        "train.train_and_evaluate(config, sys.argv[1], sys.argv[2])\n")
    env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu")
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
    want, got = _losses(full), _losses(killed)
    self.assertEqual(sorted(got), list(range(1, 13)))  # no step twice
    for step in range(1, 13):
      np.testing.assert_allclose(got[step], want[step], rtol=1e-5,
                                 err_msg=f"step {step}")

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
    with self.assertRaisesRegex(ValueError, "trained with another config"):
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


class DataParallelTest(absltest.TestCase):

  def test_two_devices_match_one(self):
    data = fixtures.tiny_dataset()
    script = (
        "import csv, json, sys\n"
        "import jax\n"
        "from tests.gnsjax import fixtures\n"
        "from gnsjax import train\n"
        "config = fixtures.tiny_config(num_steps=4, batch_size=2)\n"
        "config.log_every = 1\n"
        "train.train_and_evaluate(config, sys.argv[1], sys.argv[2])\n"
        "print('DEVICES', jax.local_device_count())\n")
    results = {}
    with tempfile.TemporaryDirectory() as d:
      for devices in (1, 2):
        env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu",
                   XLA_FLAGS=f"--xla_force_host_platform_device_count="
                   f"{devices}")
        workdir = os.path.join(d, str(devices))
        out = subprocess.run([sys.executable, "-c", script, data, workdir],
                             env=env, cwd=ROOT, capture_output=True,
                             text=True, timeout=600)
        self.assertEqual(out.returncode, 0, out.stderr[-3000:])
        self.assertIn(f"DEVICES {devices}", out.stdout)
        results[devices] = _losses(workdir)
    for step in range(1, 5):
      np.testing.assert_allclose(results[2][step], results[1][step],
                                 rtol=1e-4, err_msg=f"step {step}")


if __name__ == "__main__":
  absltest.main()
