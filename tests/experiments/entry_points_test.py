"""Smoke tests: each entry point runs as a user would run it (tiny inputs)."""

import glob
import importlib
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
    # library modules beside them (experiments.studies, ...), the benchmark
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


  def test_the_layout_of_issue_25_holds(self):
    def lines(path):
      with open(path) as f:
        return sum(1 for _ in f)

    def files(*parts):
      return glob.glob(os.path.join(ROOT, *parts), recursive=True)

    too_long = [os.path.relpath(p, ROOT)
                for p in files("mpm", "**", "*.py") +
                files("gnsjax", "**", "*.py") if lines(p) > 600]
    self.assertEqual(too_long, [], "library files over 600 lines")
    entry_points = [p for p in files("experiments", "*.py")
                    if 'if __name__ == "__main__":' in open(p).read()]
    self.assertGreater(len(entry_points), 10)
    self.assertEqual([os.path.relpath(p, ROOT) for p in entry_points
                      if lines(p) > 200], [], "entry points over 200 lines")
    plotting = [os.path.relpath(p, ROOT) for p in
                files("mpm", "**", "*.py") + files("gnsjax", "**", "*.py") +
                files("experiments", "**", "*.py")
                if re.search(r"^\s*(import|from) matplotlib", open(p).read(),
                             re.M)]
    self.assertEqual(plotting, ["experiments/figures.py"])
    studies = [p for p in files("experiments", "studies", "*.py")
               if not p.endswith(("__init__.py", "settings.py"))]
    self.assertGreaterEqual(len(studies), 10)
    from experiments.studies import settings  # pylint: disable=g-import-not-at-top
    for path in studies:
      name = os.path.basename(path)[:-3]
      module = importlib.import_module(f"experiments.studies.{name}")
      self.assertTrue(issubclass(module.Settings, settings.Base), name)
      self.assertTrue(callable(module.run) and callable(module.report), name)


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
    # Verifying needs no config: the dataset carries its own.
    self.assertIn("OK", run("experiments.generate_dataset", f"--out={out}",
                            "--verify"))


if __name__ == "__main__":
  absltest.main()
