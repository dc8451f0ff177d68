"""Tests for `experiments.benchmarks.gns_inputs` (the sand block window)."""

import os
import tempfile
from unittest import mock

from absl.testing import absltest
import numpy as np
import pytest

from experiments.benchmarks import gns_inputs
from experiments.benchmarks import gns_report
from experiments.benchmarks import scenes
from mpm import geometry
from tests.experiments.benchmarks import fixtures

# The shared window the peers were timed on, where a machine has it.
SHARED_SAND_BLOCK_DIR = os.environ.get("GNSJAX_SAND_BLOCK_DIR")


class SandBlockTest(absltest.TestCase):

  def setUp(self):
    super().setUp()
    self.dir = fixtures.tempdir(self)
    self.n_edges = fixtures.write_sand_block(self.dir)

  def test_window_and_graph(self):
    # The check of the peers' edge count, against this window's count.
    with mock.patch.object(gns_inputs, "SAND_BLOCK_EDGES", self.n_edges):
      g = gns_inputs.load_sand_block(self.dir)
    self.assertEqual(g.n_edges, self.n_edges)
    self.assertEqual(g.positions.shape, (7, 1000, 2))
    self.assertTrue(np.all(g.moving))
    # The padded list holds the same edges plus padding pointing at N.
    real = g.padded_senders < g.n_nodes
    np.testing.assert_array_equal(g.padded_senders[real], g.senders)
    # No scene of its own: the solids are the paper scene's SDF at R / 6.
    self.assertEqual(g.scene.name, scenes.PAPER_SCENE["name"])
    self.assertAlmostEqual(g.solids.spacing, fixtures.RADIUS / 6)
    domain = g.scene.domain
    self.assertEqual(g.solids.values.shape, geometry.grid_shape(
        domain.width, domain.height, fixtures.RADIUS / 6) + (3,))
    self.assertEqual(g.sdf_info["sdf_scene"], scenes.PAPER_SCENE["name"])
    self.assertIs(g.solids_at(None), g.solids)
    self.assertEqual(g.solids_at(0.01).spacing, 0.01)

  def test_other_edge_count_is_refused(self):
    with self.assertRaisesRegex(RuntimeError, "want 24930"):
      gns_inputs.load_sand_block(self.dir)

  def test_missing_input_is_named(self):
    with tempfile.TemporaryDirectory() as empty:
      with self.assertRaisesRegex(FileNotFoundError, "sand_block_window.npz"):
        gns_inputs.load_sand_block(empty)


@pytest.mark.skipif(not SHARED_SAND_BLOCK_DIR,
                    reason="$GNSJAX_SAND_BLOCK_DIR (the shared window) unset")
class SharedSandBlockTest(absltest.TestCase):

  def test_graph_has_the_peers_edge_count(self):
    g = gns_inputs.load_sand_block(SHARED_SAND_BLOCK_DIR)
    self.assertEqual(g.n_edges, gns_inputs.SAND_BLOCK_EDGES)
    self.assertEqual(g.positions.shape, (7, 1000, 2))
    self.assertTrue(np.all(g.moving))
    real = g.padded_senders < g.n_nodes
    np.testing.assert_array_equal(g.padded_senders[real], g.senders)
    self.assertTrue(gns_report.check_quotes(os.path.join(
        SHARED_SAND_BLOCK_DIR, gns_inputs.SAND_BLOCK_README))[
            "readme_checked"])




if __name__ == "__main__":
  absltest.main()
