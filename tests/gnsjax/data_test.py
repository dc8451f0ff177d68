"""Tests for `gnsjax.data` (npz interop: tests/mpm/interop_test.py)."""

import os
import tempfile

from absl.testing import absltest
import h5py
import numpy as np

import mpm
from gnsjax import batching
from gnsjax import data
from gnsjax import graph
from mpm import dataset
from mpm import io as mpm_io

SPEC = dataset.DatasetSpec(num_train=2, num_test=2, num_frames=10, seed=3,
                           spacing=0.01, connectivity_radius=0.03)


def numpy_stats(trajectories, k):
  """Mean and std of the stride-k velocities and accelerations, every frame
  of every particle of every trajectory pooled (plain numpy)."""
  v = np.concatenate([(x[k:] - x[:-k]).reshape(-1, 2)
                      for x in trajectories]).astype(np.float64)
  a = np.concatenate([(x[2 * k:] - 2 * x[k:-k] + x[:-2 * k]).reshape(-1, 2)
                      for x in trajectories]).astype(np.float64)
  return v.mean(0), v.std(0), a.mean(0), a.std(0)


def write_moving_and_resting(path, frames=12, n=5):
  """A file of two synthetic trajectories: sand sliding at 1 mm per frame,
  then sand at rest."""
  t = np.arange(frames, dtype=np.float32)[:, None, None]
  start = np.stack([np.linspace(0.5, 0.6, n), np.full(n, 0.5)],
                   -1).astype(np.float32)
  moving = start[None] + t * np.array([-1e-3, 0.0], np.float32)
  resting = np.broadcast_to(start[None], moving.shape)
  scene = mpm.Scene.from_dict({"name": "synthetic"})
  mpm_io.write_trajectories(path, [
      mpm_io.Trajectory(np.ascontiguousarray(x), np.zeros((0, 2), np.float32),
                        np.zeros(0, np.int32), scene)
      for x in (moving, resting)])


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

  def test_stride_windows_are_the_subsampled_trajectory(self):
    trajectories = list(mpm_io.read_trajectories(self.train))
    for c, k in ((2, 3), (3, 3), (2, 4)):
      with data.WindowDataset(self.train, input_frames=c, frame_stride=k,
                              seed=0) as ds:
        per_trajectory = [len(t.positions) - c * k for t in trajectories]
        self.assertLen(ds, sum(per_trajectory))
        seen = set()
        for i in range(len(ds)):
          w = ds[i]
          seen.add((w.trajectory, w.start))
          x = trajectories[w.trajectory].positions
          self.assertEqual(w.positions.shape, (c + 1,) + x.shape[1:])
          np.testing.assert_array_equal(
              w.positions, x[w.start:w.start + c * k + 1:k])
          self.assertEqual(w.scene, trajectories[w.trajectory].scene)
        self.assertLen(seen, len(ds))
    with self.assertRaisesRegex(ValueError, "frame_stride"):
      data.WindowDataset(self.train, frame_stride=0)

  def test_stats_at_a_stride_are_numpy_stats_of_its_differences(self):
    positions = [t.positions for t in mpm_io.read_trajectories(self.train)]
    header = mpm_io.read_header(self.train)
    # Stride 1: what the file stores, which is the numpy statistics.
    stored = data.load_stats(self.train, 1)
    for got, key, want in zip(stored, data.Stats._fields,
                              numpy_stats(positions, 1)):
      self.assertEqual(got.dtype, np.float32)
      np.testing.assert_allclose(got, header[key], rtol=1e-6, err_msg=key)
      np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-9,
                                 err_msg=key)
    strided = data.load_stats(self.train, 3)
    for got, key, want in zip(strided, data.Stats._fields,
                              numpy_stats(positions, 3)):
      np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-9,
                                 err_msg=key)
    # Three frames per step: velocities about 3x those of one frame.
    self.assertGreater(np.max(strided.vel_std / stored.vel_std), 2)
    with self.assertRaisesRegex(ValueError, "stride"):
      data.load_stats(self.train, 0)

  def test_uniform_order_is_a_permutation(self):
    with data.WindowDataset(self.train, input_frames=3, seed=4,
                            motion_weighting=0.0) as ds:
      flat = lambda w: (w.trajectory, w.start)
      for epoch in range(2):
        seen = [flat(ds[k]) for k in range(epoch * len(ds),
                                           (epoch + 1) * len(ds))]
        self.assertLen(set(seen), len(ds))

  def test_motion_weighting_draws_resting_sand_less(self):
    with tempfile.TemporaryDirectory() as d:
      path = os.path.join(d, "two.h5")
      write_moving_and_resting(path)
      counts = {}
      for p in (0.0, 0.5, 1.0):
        with data.WindowDataset(path, input_frames=3, seed=0,
                                motion_weighting=p) as ds:
          self.assertLen(ds, 2 * (12 - 3))
          drawn = [ds[k].trajectory for k in range(20 * len(ds))]
        counts[p] = np.bincount(drawn, minlength=2)
      # Uniform: as many of each; p: weights (1 - p) + p m / mean(m), i.e.
      # 1 - p for the resting windows and 1 + p for the moving ones.
      self.assertEqual(counts[0.0][0], counts[0.0][1])
      self.assertEqual(counts[1.0][1], 0)
      self.assertGreater(counts[0.5][1], 0)
      np.testing.assert_allclose(counts[0.5][1] / counts[0.5].sum(), 0.25,
                                 atol=0.06)
      # A pure function of (seed, index): a fresh dataset, read in another
      # order, draws the same windows.
      with data.WindowDataset(path, input_frames=3, seed=0,
                              motion_weighting=0.5) as a, \
          data.WindowDataset(path, input_frames=3, seed=0,
                             motion_weighting=0.5) as b:
        ks = list(range(3 * len(a)))
        first = [(a[k].trajectory, a[k].start) for k in ks]
        again = {k: (b[k].trajectory, b[k].start) for k in reversed(ks)}
        self.assertEqual(first, [again[k] for k in ks])
      with self.assertRaisesRegex(ValueError, "motion_weighting"):
        data.WindowDataset(path, motion_weighting=1.5)

  def test_batches_hold_the_windows_nodes_and_sdf_grids(self):
    bounds = np.asarray(mpm_io.read_header(self.train)["bounds"])
    spec = graph.GraphSpec(SPEC.connectivity_radius, bounds.tolist())
    with data.WindowDataset(self.train, input_frames=3, frame_stride=2,
                            seed=0) as ds:
      windows = [ds[0], ds[1], ds[2]]
    for boundary in (True, False):
      batch = batching.make_batch(windows, spec, node_bucket=32,
                                  boundary=boundary, sdf_spacing=0.02)
      b, frames, n, _ = batch.positions.shape
      self.assertEqual((b, frames), (3, 4))
      self.assertEqual(n % 32, 0)
      self.assertEqual(batch.solids.shape[0], 3)
      for i, w in enumerate(windows):
        np.testing.assert_array_equal(batch.solids[i],
                                      data.solids_of(w.scene, 0.02).values)
        sand = w.positions.shape[1]
        np.testing.assert_array_equal(batch.positions[i, :, :sand],
                                      w.positions)
        np.testing.assert_array_equal(batch.moving[i],
                                      np.arange(n) < sand)
        fixed = batch.particle_type[i, sand:] != 0
        if not boundary:
          self.assertFalse(fixed.any())
          continue
        # The boundary particles within R of the sand's last input frame,
        # still over all frames.
        nodes = batch.positions[i, :, sand:][:, fixed]
        near = batching.near_boundary(w.positions[-2], w.boundary_positions,
                                      spec.radius)
        self.assertGreater(near.sum(), 0)
        self.assertLess(near.sum(), len(near))
        np.testing.assert_array_equal(nodes[0], w.boundary_positions[near])
        np.testing.assert_array_equal(nodes, np.broadcast_to(
            nodes[:1], nodes.shape))
        d = np.linalg.norm(nodes[0][:, None] - w.positions[-2][None], axis=-1)
        np.testing.assert_array_less(d.min(1), spec.radius)

  def test_too_short_for_windows(self):
    with self.assertRaisesRegex(mpm_io.FormatError, "at least 11 frames"):
      data.WindowDataset(self.train, input_frames=10)
    with self.assertRaisesRegex(mpm_io.FormatError,
                                "at least 13 frames.*stride 2"):
      data.WindowDataset(self.train, input_frames=6, frame_stride=2)


if __name__ == "__main__":
  absltest.main()
