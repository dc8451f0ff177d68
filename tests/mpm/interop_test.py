"""Tests for `mpm.interop`: npz datasets of DeepMind's and geoelements' GNS."""

import json
import os
import tempfile

from absl.testing import absltest
import numpy as np

from mpm import dataset
from mpm import interop
from mpm import io as mpm_io

SPEC = dataset.DatasetSpec(num_train=2, num_test=2, num_frames=10, seed=3,
                           spacing=0.01, connectivity_radius=0.03)


class InteropTest(absltest.TestCase):

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls._tmp = tempfile.TemporaryDirectory()
    dataset.generate(SPEC, cls._tmp.name, workers=1)
    cls.train = os.path.join(cls._tmp.name, "train.h5")

  @classmethod
  def tearDownClass(cls):
    cls._tmp.cleanup()
    super().tearDownClass()

  def test_npz_round_trip(self):
    with tempfile.TemporaryDirectory() as d:
      npz, meta = os.path.join(d, "train.npz"), os.path.join(d, "meta.json")
      self.assertEqual(interop.export_npz(self.train, npz, meta),
                       SPEC.num_train)
      with np.load(npz, allow_pickle=True) as f:
        positions, types = f["simulation_trajectory_0"]
      first = next(mpm_io.read_trajectories(self.train))
      n, nb = first.positions.shape[1], len(first.boundary_type)
      self.assertEqual(positions.shape, (SPEC.num_frames, n + nb, 2))
      self.assertTrue(np.all(types[n:] == interop.KINEMATIC_TYPE))
      with open(meta) as f:
        metadata = json.load(f)
      for key in ("bounds", "sequence_length", "default_connectivity_radius",
                  "dim", "dt", "vel_mean", "vel_std", "acc_mean", "acc_std"):
        self.assertIn(key, metadata)
      back = os.path.join(d, "back.h5")
      interop.import_npz(npz, meta, back)
      for a, b in zip(mpm_io.read_trajectories(self.train),
                      mpm_io.read_trajectories(back)):
        np.testing.assert_array_equal(a.positions, b.positions)
        np.testing.assert_array_equal(a.boundary_positions,
                                      b.boundary_positions)
        np.testing.assert_array_equal(a.particle_type, b.particle_type)
      np.testing.assert_allclose(mpm_io.read_header(back)["vel_std"],
                                 mpm_io.read_header(self.train)["vel_std"])

  def test_import_errors(self):
    with tempfile.TemporaryDirectory() as d:
      meta = os.path.join(d, "meta.json")
      with open(meta, "w") as f:
        json.dump({"bounds": [[0, 1], [0, 1], [0, 1]], "dim": 3, "dt": 0.01,
                   "vel_mean": [0] * 3, "vel_std": [1] * 3,
                   "acc_mean": [0] * 3, "acc_std": [1] * 3}, f)
      with self.assertRaisesRegex(mpm_io.FormatError, "only 2D"):
        interop.import_npz(os.path.join(d, "x.npz"), meta,
                           os.path.join(d, "o.h5"))
      with open(meta, "w") as f:
        json.dump({"bounds": [[0, 1], [0, 1]]}, f)
      with self.assertRaisesRegex(mpm_io.FormatError, "not a GNS metadata"):
        interop.import_npz(os.path.join(d, "x.npz"), meta,
                           os.path.join(d, "o.h5"))


if __name__ == "__main__":
  absltest.main()
