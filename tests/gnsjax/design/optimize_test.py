"""Tests for `gnsjax.design.optimize`."""

from absl.testing import absltest
import jax.numpy as jnp
import numpy as np

from gnsjax.design import objectives
from gnsjax.design import optimize
from gnsjax.design import placement as placement_lib
from gnsjax.design import rollouts
from tests.gnsjax.design.fixtures import scene


class OptimiseTest(absltest.TestCase):

  def test_projected_adam_stays_in_range_and_logs(self):
    p = placement_lib.Placement(scene(num_frames=20), x_range=(1.25, 1.3))
    sim = rollouts.MPMDriver(rollouts.MPMRollout.create(p))
    obj = objectives.make("centroid", target_x=0.0)  # push the sand far
    records = []
    history = optimize.optimise(sim, obj.smooth, p.initial(), steps=4,
                                learning_rate=0.2, log=records.append)
    self.assertEqual(records, history)
    self.assertLen(history, 4)
    xs = [r["x"] for r in history]
    self.assertTrue(all(1.25 - 1e-6 <= x <= 1.3 + 1e-6 for x in xs), xs)
    # Steps larger than the range land on a bound.
    self.assertTrue(any(min(abs(x - 1.25), abs(x - 1.3)) < 1e-6
                        for x in xs[1:]), xs)

  def test_records_round_trip_and_central_differences(self):
    params = {"x": jnp.float32(0.75), "size": jnp.asarray([0.04, 0.03])}
    record = optimize.plain(params, "")
    self.assertEqual(set(record), {"x", "size0", "size1"})
    back = optimize.from_record(record, with_size=True)
    np.testing.assert_allclose(back["size"], params["size"])
    fd = optimize.central_difference(
        lambda p: float(p["x"]**2 + 3 * p["size"][1]), params, 1e-2)
    np.testing.assert_allclose(fd["x"], 1.5, rtol=1e-4)
    np.testing.assert_allclose(fd["size"], [0.0, 3.0], atol=1e-4)


if __name__ == "__main__":
  absltest.main()
