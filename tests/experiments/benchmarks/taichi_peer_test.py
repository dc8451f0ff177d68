"""Tests for `experiments.benchmarks.taichi_peer` (skipped without taichi)."""

import dataclasses
import importlib.util

from absl.testing import absltest
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mpm

HAS_TAICHI = importlib.util.find_spec("taichi") is not None


@pytest.mark.slow  # compiles a Taichi kernel and a JAX substep (~10 s)
@absltest.skipIf(not HAS_TAICHI, "taichi is not installed (.[bench])")
class TaichiPeerTest(absltest.TestCase):

  def test_matches_jax_substeps_where_sand_hits_solids(self):
    # Imported here: the module imports taichi at its top.
    # pylint: disable-next=g-import-not-at-top
    from experiments.benchmarks import taichi_peer
    taichi_peer.init()
    setup = mpm.setup(mpm.Scene.from_dict({"obstacles": [
        {"shape": "rectangle", "x": 0.9, "width": 0.04, "height": 0.05}]}))
    # Particles around the ramp and the obstacle, thrown into them, so that
    # the boundary conditions and the particle projection all act.
    n = setup.state.x.shape[0]
    rng = np.random.default_rng(0)
    x = rng.uniform(0.3, 1.4, n)
    y = setup.scene.ramp.height(x) + rng.uniform(-0.004, 0.006, n)
    x[:200] = rng.uniform(0.86, 0.94, 200)
    y[:200] = setup.scene.ramp.height(x[:200]) + rng.uniform(0, 0.06, 200)
    state = setup.state.replace(
        x=jnp.asarray(np.stack([x, y], -1), jnp.float32),
        v=jnp.tile(jnp.asarray([[1.0, -3.0]], jnp.float32), (n, 1)))
    setup = dataclasses.replace(setup, state=state)

    substep = jax.jit(mpm.solver.substep, static_argnums=(3,))
    peer = taichi_peer.TaichiMPM(setup)
    for _ in range(3):
      state, _ = substep(state, setup.params, setup.field, setup.spec)
      peer.substep()
    moved = np.abs(np.asarray(state.x) - np.asarray(setup.state.x)).max()
    self.assertGreater(moved, 1e-3)  # the check is not vacuous
    # float32, different summation order and SVD formulation: ~1e-6 m.
    np.testing.assert_allclose(peer.x.to_numpy(), np.asarray(state.x),
                               atol=2e-5, rtol=0)
    np.testing.assert_allclose(peer.v.to_numpy(), np.asarray(state.v),
                               atol=1e-3, rtol=0)


if __name__ == "__main__":
  absltest.main()
