"""Tests for `experiments.benchmarks.mpm_benchmark` and `--what=mpm`."""

import importlib.util
import json
import os
import sys
from unittest import mock

from absl import flags
from absl.testing import absltest
from absl.testing import flagsaver
import pytest

from experiments.benchmarks import __main__ as benchmarks_main
from experiments.benchmarks import mpm_benchmark
from tests.experiments.benchmarks import fixtures

FLAGS = flags.FLAGS
HAS_TAICHI = importlib.util.find_spec("taichi") is not None


class PeerTest(absltest.TestCase):

  def test_missing_taichi_is_skipped_with_a_message(self):
    with mock.patch.dict(sys.modules, {
        "taichi": None, "experiments.benchmarks.taichi_peer": None}):
      peer = mpm_benchmark._Peer(  # pylint: disable=protected-access
          enabled=True, num_threads=None)
    self.assertFalse(peer.available)
    self.assertIn("pip install -e .[bench]", peer.reason)

  def test_disabled_peer(self):
    peer = mpm_benchmark._Peer(  # pylint: disable=protected-access
        enabled=False, num_threads=None)
    self.assertFalse(peer.available)


@pytest.mark.slow  # ~40 s on 2 CPU cores: several compilations.
class BenchmarkQuickTest(absltest.TestCase):

  def test_quick_mode_writes_and_prints_results(self):
    if not FLAGS.is_parsed():
      FLAGS.mark_as_parsed()
    out = fixtures.tempdir(self)
    with flagsaver.flagsaver(out=out, quick=True, taichi=HAS_TAICHI,
                             what=["mpm"]):
      benchmarks_main.main(["benchmarks"])

    with open(os.path.join(out, "mpm_benchmark_quick.json")) as f:
      results = json.load(f)
    with open(os.path.join(out, "mpm_benchmark_quick.md")) as f:
      self.assertIn("| JAX (jit, CPU) |", f.read())
    paper = results["paper_scene"]
    self.assertEqual(paper["n_particles"], 1000)
    self.assertGreater(paper["jax"]["median_us"], 0)
    self.assertGreater(paper["trajectory"]["jax_s"], 0)
    sizes = mpm_benchmark.QUICK
    self.assertLen(results["particle_scaling"], len(sizes.particle_counts))
    self.assertLen(results["obstacle_scaling"], len(sizes.obstacle_counts))
    self.assertEqual([b["batch"] for b in results["batches"]["batches"]],
                     list(sizes.batch_sizes))
    if HAS_TAICHI:
      self.assertGreater(paper["taichi"]["median_us"], 0)
      agreement = results["agreement"]["svd"]["closed_form"]
      self.assertTrue(agreement["agrees"], agreement)
    else:
      self.assertIn("skipped", results["agreement"])


if __name__ == "__main__":
  absltest.main()
