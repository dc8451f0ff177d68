"""Smoke tests: each entry point runs as a user would run it (tiny inputs)."""

import glob
import json
import os
import re
import subprocess
import sys
import tempfile

from absl.testing import absltest
import numpy as np

from mpm import io as mpm_io

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(__file__)))
TINY_SCENE = {
    "name": "tiny",
    "domain": {"width": 0.4, "height": 0.3},
    "ramp": {"kind": "polyline", "points": [[0.0, 0.05], [0.4, 0.15]]},
    "obstacles": [{"shape": "rectangle", "x": 0.15, "width": 0.03,
                   "height": 0.03}],
    "granular": {"box": [0.25, 0.12, 0.35, 0.2], "spacing": 0.01},
    "num_frames": 12,
}


def run(*args):
  env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu",
             GNSJAX_CACHE_DIR=os.path.join(ROOT, ".jax_cache"))
  proc = subprocess.run([sys.executable, "-m", *args], env=env, cwd=ROOT,
                        capture_output=True, text=True, timeout=600)
  if proc.returncode != 0:
    raise AssertionError(f"{args} failed ({proc.returncode}):\n"
                         f"{proc.stdout[-2000:]}\n{proc.stderr[-4000:]}")
  return proc.stdout


class LayoutTest(absltest.TestCase):

  def test_tests_import_no_entry_point_that_defines_flags(self):
    # absl flags are process-global: two imported entry points that both
    # define --out fail to load in one pytest worker. Tests import the
    # library modules beside them (evaluation, extremes, ...), the benchmark
    # driver being the one entry point imported (its flags are its API).
    allowed = {"runtime", "benchmarks/__main__"}
    defines = {os.path.relpath(p, os.path.join(ROOT, "experiments"))[:-3]
               for p in glob.glob(os.path.join(ROOT, "experiments", "**",
                                               "*.py"), recursive=True)
               if "flags.DEFINE_" in open(p).read()}
    pattern = re.compile(r"^from experiments(\.[\w.]+)? import (\w+)", re.M)
    offenders = []
    for path in glob.glob(os.path.join(ROOT, "tests", "**", "*.py"),
                          recursive=True):
      for package, name in pattern.findall(open(path).read()):
        module = (package.lstrip(".").replace(".", "/") + "/" + name
                  ).lstrip("/")
        if module in defines - allowed:
          offenders.append(f"{os.path.relpath(path, ROOT)}: {module}")
    self.assertEqual(offenders, [])


class EntryPointsTest(absltest.TestCase):

  def setUp(self):
    super().setUp()
    tmp = tempfile.TemporaryDirectory()
    self.addCleanup(tmp.cleanup)
    self.dir = tmp.name

  def test_simulate_then_render(self):
    scene = os.path.join(self.dir, "scene.json")
    with open(scene, "w") as f:
      json.dump(TINY_SCENE, f)
    # The output's directory is created (after the simulation, which a
    # missing directory used to lose).
    traj = os.path.join(self.dir, "new", "traj.h5")
    out = run("experiments.simulate", f"--scene={scene}", f"--out={traj}")
    self.assertIn("12 frames", out)
    (t,) = mpm_io.read_trajectories(traj)
    self.assertEqual(t.positions.shape[0], 12)
    self.assertTrue(np.all(np.isfinite(t.positions)))
    self.assertGreater(t.wall_time_s, 0)
    # Sand on a 14 degree slope with friction 0.5 and gravity: it settles
    # or moves down, never up.
    self.assertLessEqual(t.positions[-1, :, 1].mean(),
                         t.positions[0, :, 1].mean() + 1e-4)
    pictures = os.path.join(self.dir, "pictures")
    out = run("experiments.render", f"--traj={traj}", f"--out={pictures}",
              "--frames=0,5,11")
    self.assertTrue(os.path.getsize(os.path.join(pictures, "animation.gif")))
    self.assertTrue(os.path.getsize(os.path.join(pictures, "frames.png")))

  def test_simulate_refuses_a_bad_scene(self):
    scene = os.path.join(self.dir, "bad.json")
    with open(scene, "w") as f:
      json.dump({**TINY_SCENE, "obstacles": [{"shape": "hexagon", "x": 0.2}]},
                f)
    with self.assertRaisesRegex(AssertionError, "obstacles\\[0\\].shape"):
      run("experiments.simulate", f"--scene={scene}",
          f"--out={self.dir}/x.h5")
    self.assertFalse(os.path.exists(f"{self.dir}/x.h5"))

  def test_generate_dataset_and_verify(self):
    out = os.path.join(self.dir, "data")
    # One scene per split: the splits' plans and the writer are the library's
    # (tests/mpm/dataset_test.py); here, the entry point end to end.
    run("experiments.generate_dataset",
        "--config=experiments/configs/test.py", f"--out={out}",
        "--config.dataset.num_frames=8", "--config.dataset.num_train=1",
        "--config.dataset.num_test=1")
    self.assertEqual(sorted(os.listdir(out)),
                     ["metadata.json", "test.h5", "train.h5"])
    self.assertIn("OK", run("experiments.generate_dataset",
                            "--config=experiments/configs/test.py",
                            f"--out={out}", "--verify"))

  def test_demo(self):
    # The small config learns steps of 3 frames from 6 inputs: windows of 19
    # frames; 22 leave two learned steps after frame 15 (18 and 21).
    out = run("experiments.demo", f"--out={self.dir}/demo", "--num_frames=22",
              "--num_train=2", "--finetune_steps=2", "--nopretrained")
    for name in ("metrics.json", "animation.gif", "frames.png", "truth.h5",
                 "predicted.h5"):
      self.assertIn(name, out)
      self.assertTrue(os.path.exists(os.path.join(self.dir, "demo", name)))
    with open(os.path.join(self.dir, "demo", "metrics.json")) as f:
      metrics = json.load(f)
    self.assertIn("triangle", metrics["scene"])
    self.assertGreater(metrics["constant_velocity_mean_mse_m2"], 0)
    self.assertEqual(metrics["frame_stride"], 3)
    self.assertEqual(metrics["learned_steps"], 2)
    # The files hold the 6 input frames at the stride, then the predictions.
    (truth,) = mpm_io.read_trajectories(os.path.join(self.dir, "demo",
                                                     "truth.h5"))
    (predicted,) = mpm_io.read_trajectories(os.path.join(self.dir, "demo",
                                                         "predicted.h5"))
    self.assertEqual(truth.positions.shape[0], 8)
    self.assertEqual(predicted.positions.shape, truth.positions.shape)
    np.testing.assert_array_equal(predicted.positions[:6],
                                  truth.positions[:6])
    self.assertAlmostEqual(truth.scene.frame_dt, 3 * 0.0025)


if __name__ == "__main__":
  absltest.main()
