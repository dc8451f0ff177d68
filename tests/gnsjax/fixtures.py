"""Tiny datasets and configs shared by the gnsjax tests (cached per process)."""

import csv
import fcntl
import functools
import os
import tempfile

from absl.testing import absltest

from experiments.configs import test as test_config
from mpm import dataset

# About 50 sand particles per scene (spacing 0.02 m), 16 frames.
SPEC = dataset.DatasetSpec(num_train=2, num_test=2, num_frames=16, seed=11,
                           spacing=0.02, connectivity_radius=0.06)
_TMP = tempfile.TemporaryDirectory()


@functools.lru_cache(maxsize=None)
def tiny_dataset() -> str:
  """The dataset's directory: generated once per process, or once per run
  under pytest-xdist, where the workers share it (a directory named after
  the run, written under a lock by the first worker that needs it)."""
  run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
  if run is None:
    path = os.path.join(_TMP.name, "data")
    dataset.generate(SPEC, path, workers=1)
    return path
  shared = os.path.join(tempfile.gettempdir(), f"gnsjax-tests-{run}")
  os.makedirs(shared, exist_ok=True)
  path = os.path.join(shared, "data")
  with open(os.path.join(shared, "lock"), "w") as lock:
    fcntl.flock(lock, fcntl.LOCK_EX)
    if not os.path.exists(os.path.join(path, "metadata.json")):
      dataset.generate(SPEC, path, workers=1)
  return path


def logged_losses(workdir: str) -> dict[int, float]:
  """{step: loss} of a run's metrics.csv."""
  with open(os.path.join(workdir, "metrics.csv"), newline="") as f:
    return {int(r["step"]): float(r["loss"]) for r in csv.DictReader(f)}


def tiny_config(**train):
  config = test_config.get_config()
  config.dataset.num_train = SPEC.num_train
  config.dataset.num_test = SPEC.num_test
  config.dataset.num_frames = SPEC.num_frames
  config.dataset.seed = SPEC.seed
  config.dataset.spacing = SPEC.spacing
  config.dataset.connectivity_radius = SPEC.connectivity_radius
  config.model.num_message_passing_steps = 1
  config.train.node_bucket = 32
  config.eval.every_steps = 0
  for key, value in train.items():
    config.train[key] = value
  return config


class TinyRunTestCase(absltest.TestCase):
  """A temporary work directory (``self.dir``) and the tiny dataset
  (``self.data``)."""

  def setUp(self):
    super().setUp()
    tmp = tempfile.TemporaryDirectory()
    self.addCleanup(tmp.cleanup)
    self.dir = tmp.name
    self.data = tiny_dataset()
