"""Tests for `gnsjax.batching.DeviceWindows` against the host batches."""

import shutil
import tempfile

from absl.testing import absltest
import numpy as np

from gnsjax import run as run_lib
from gnsjax import batching
from gnsjax import data
from gnsjax import train
from tests.gnsjax import fixtures

STRIDE = 2


class DeviceWindowsTest(absltest.TestCase):

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls.data = fixtures.tiny_dataset()
    cls.config = fixtures.tiny_config(frame_stride=STRIDE)
    cls.config.model.boundary_particles = False
    cls.problem = run_lib.load_problem(cls.data, cls.config)
    cls.trainer = train.Trainer(cls.config, cls.problem)
    path = data.split_path(cls.data, "train")
    c = cls.config.train.input_frames
    cls.dataset = data.WindowDataset(path, input_frames=c,
                                     frame_stride=STRIDE, seed=3)
    cls.windows = batching.DeviceWindows(
        path, cls.problem.spec, input_frames=c, frame_stride=STRIDE,
        node_bucket=cls.config.train.node_bucket,
        sdf_spacing=cls.problem.sdf_spacing)

  def _both(self, step: int):
    b = self.config.train.batch_size
    where = np.array([self.dataset.locate(step * b + i) for i in range(b)])
    host = self.trainer.make_batch([self.dataset[step * b + i]
                                    for i in range(b)])
    return host, self.windows.batch(where[:, 0], where[:, 1])

  def test_device_windows_equal_the_host_windows(self):
    for step in range(4):
      host, device = self._both(step)
      positions = np.asarray(device.positions)
      for b in range(len(host.moving)):
        n = int(host.moving[b].sum())
        self.assertEqual(int(np.asarray(device.moving[b]).sum()), n)
        np.testing.assert_array_equal(positions[b, :, :n],
                                      host.positions[b, :, :n])
        np.testing.assert_array_equal(np.asarray(device.particle_type[b])[:n],
                                      host.particle_type[b, :n])
        np.testing.assert_array_equal(np.asarray(device.solids[b]),
                                      host.solids[b])

  def test_device_built_graph_and_loss_equal_the_host_built(self):
    params = self.trainer.init_state(0).params
    for step in range(3):
      host, device = self._both(step)
      hg, ht = self.trainer.batch_arrays(host, None, noise=False)
      dg, dt = self.trainer.batch_arrays(device, None, noise=False)
      for b in range(len(host.moving)):
        n = int(host.moving[b].sum())
        edges = lambda g: {(int(s), int(r)) for s, r in zip(
            np.asarray(g.senders[b]), np.asarray(g.receivers[b]))
                           if s < n and r < n}
        self.assertEqual(edges(hg), edges(dg))
      np.testing.assert_allclose(
          float(self.trainer.eval_loss(params, hg, ht)),
          float(self.trainer.eval_loss(params, dg, dt)), rtol=1e-5)

  def test_training_with_device_windows_equals_host_windows(self):
    losses = []
    for device in (False, True):
      config = fixtures.tiny_config(frame_stride=STRIDE, num_steps=6,
                                    device_windows=device)
      config.model.boundary_particles = False
      config.log_every = 1
      workdir = tempfile.mkdtemp()
      self.addCleanup(shutil.rmtree, workdir)
      train.train_and_evaluate(config, self.data, workdir)
      with open(f"{workdir}/metrics.csv") as f:
        losses.append([float(line.split(",")[1])
                       for line in f.read().splitlines()[1:]])
    np.testing.assert_allclose(losses[0], losses[1], rtol=1e-4)

  def test_refuses_boundary_particles(self):
    config = fixtures.tiny_config(device_windows=True)
    config.model.boundary_particles = True
    with self.assertRaisesRegex(ValueError, "boundary_particles = False"):
      workdir = tempfile.mkdtemp()
      self.addCleanup(shutil.rmtree, workdir)
      train.train_and_evaluate(config, self.data, workdir)


if __name__ == "__main__":
  absltest.main()
