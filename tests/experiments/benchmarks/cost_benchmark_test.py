"""Tests for `experiments.benchmarks.cost_benchmark`."""

import json
import os
import tempfile

from absl.testing import absltest

from experiments.benchmarks import cost_benchmark


class CostBenchmarkTest(absltest.TestCase):

  def test_quick_run_writes_consistent_figures(self):
    with tempfile.TemporaryDirectory() as d:
      results = cost_benchmark.run_benchmark(d, quick=True, log=lambda _: 0)
      with open(os.path.join(d, "cost_benchmark_quick.json")) as f:
        stored = json.load(f)
      with open(os.path.join(d, "cost_benchmark_quick.md")) as f:
        markdown = f.read()
    self.assertEqual(stored["columns"], json.loads(json.dumps(
        results["columns"])))
    small, large = stored["columns"]
    # The same sand in a domain of 2 x 2 the size: more grid nodes, the
    # same positions with the window as without.
    self.assertGreater(large["area"], 3.0)
    self.assertEqual(small["particles"], large["particles"])
    self.assertLen(stored["paper_scene"], 2)
    for row in stored["columns"] + stored["paper_scene"]:
      self.assertLessEqual(row["max_position_difference_m"], 1e-6)
      self.assertAlmostEqual(row["window_over_whole"],
                             row["window"]["median_s"] /
                             row["whole_grid"]["median_s"])
    b = stored["batches"]
    self.assertEqual(b["scenes"], 3)
    self.assertLessEqual(b["buckets"], 3)
    # At a threshold of 10 m/s the sand counts as resting at once: each
    # run stops after a chunk, the later frames repeat that one.
    avalanche, pour = stored["rest"]
    self.assertEqual((avalanche["frames"], pour["frames"]), (121, 121))
    for r in stored["rest"]:
      self.assertBetween(r["rest_frame"], 1, r["frames"] - 2)
      self.assertAlmostEqual(
          r["stopped_over_stepped"],
          r["stopped"]["median_s"] / r["stepped"]["median_s"])
      self.assertGreater(r["last_frame_difference_m"], 0.0)
      self.assertGreater(r["fastest_at_end_m_per_s"], 0.0)
      self.assertIn(f"| {r['scene']} | {r['particles']} | {r['frames']} | "
                    f"{r['rest_frame']} |", markdown)
    self.assertIn("column_x2", markdown)
    self.assertIn("size buckets", markdown)


if __name__ == "__main__":
  absltest.main()
