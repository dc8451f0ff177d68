"""Tests for `gnsjax.data` (npz interop: tests/mpm/interop_test.py)."""

import os
import tempfile

from absl.testing import absltest
import h5py
import numpy as np

from gnsjax import data
from mpm import dataset
from mpm import io as mpm_io

SPEC = dataset.DatasetSpec(num_train=2, num_test=2, num_frames=10, seed=3,
                           spacing=0.01, connectivity_radius=0.03)


class DataTest(absltest.TestCase):

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls._tmp = tempfile.TemporaryDirectory()
    cls.dir = cls._tmp.name
    dataset.generate(SPEC, cls.dir, workers=1)
    cls.train = os.path.join(cls.dir, "train.h5")

  @classmethod
  def tearDownClass(cls):
    cls._tmp.cleanup()
    super().tearDownClass()

  def test_windows_cover_each_epoch_once_and_match_the_file(self):
    trajectories = list(mpm_io.read_trajectories(self.train))
    with data.WindowDataset(self.train, input_frames=6, seed=0) as ds:
      per_epoch = sum(len(t.positions) - 6 for t in trajectories)
      self.assertLen(ds, per_epoch)
      for epoch in range(2):
        seen = set()
        for k in range(epoch * len(ds), (epoch + 1) * len(ds)):
          w = ds[k]
          seen.add((w.trajectory, w.start))
          t = trajectories[w.trajectory]
          np.testing.assert_array_equal(
              w.positions, t.positions[w.start:w.start + 7])
          np.testing.assert_array_equal(w.boundary_positions,
                                        t.boundary_positions)
          np.testing.assert_array_equal(w.particle_type, t.particle_type)
        self.assertLen(seen, per_epoch)

  def test_order_is_a_function_of_seed_and_index(self):
    with data.WindowDataset(self.train, seed=1) as a, \
        data.WindowDataset(self.train, seed=1) as b, \
        data.WindowDataset(self.train, seed=2) as c:
      order_a = [(a[k].trajectory, a[k].start) for k in range(len(a) * 2)]
      # Resuming at step k reads what an uninterrupted run reads.
      resumed = [(b[k].trajectory, b[k].start)
                 for k in range(len(b) + 3, 2 * len(b))]
      self.assertEqual(order_a[len(a) + 3:], resumed)
      order_c = [(c[k].trajectory, c[k].start) for k in range(len(c))]
      self.assertNotEqual(order_a[:len(a)], order_c)
      self.assertNotEqual(order_a[:len(a)], order_a[len(a):])

  def test_stats_match_file_and_missing_stats_error(self):
    stats = data.load_stats(self.train)
    header = mpm_io.read_header(self.train)
    np.testing.assert_allclose(stats.acc_std, header["acc_std"], rtol=1e-6)
    with tempfile.TemporaryDirectory() as d:
      path = os.path.join(d, "nostats.h5")
      with h5py.File(path, "w") as f:
        f.attrs["format_version"] = mpm_io.FORMAT_VERSION
      with self.assertRaisesRegex(mpm_io.FormatError,
                                  "no normalisation statistics"):
        data.load_stats(path)
      with self.assertRaisesRegex(mpm_io.FormatError, "no valid split"):
        data.split_path(d, "valid")

  def test_too_short_for_windows(self):
    with self.assertRaisesRegex(mpm_io.FormatError, "at least 11 frames"):
      data.WindowDataset(self.train, input_frames=10)


if __name__ == "__main__":
  absltest.main()
