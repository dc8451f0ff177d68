"""Tests for `experiments.timing`."""

import json
import os

from absl.testing import absltest
import jax
import jax.numpy as jnp
import numpy as np

from experiments import timing
from tests.experiments.benchmarks import fixtures


class TimeCallsTest(absltest.TestCase):

  def test_time_calls_runs_each_call_warm_up_plus_repeats(self):
    counts = {"a": 0, "b": 0}

    def call(name):
      counts[name] += 1
      return jnp.zeros(())

    out = timing.time_calls(
        {k: (lambda k=k: call(k)) for k in counts}, repeats=3)
    self.assertEqual(counts, {"a": 4, "b": 4})
    for summary in out.values():
      self.assertEqual(summary["repeats"], 3)
      self.assertLen(summary["all_s"], 3)
      self.assertLessEqual(summary["min_s"], summary["median_s"])
      self.assertGreaterEqual(summary["warmup_s"], 0)

  def test_calls_are_interleaved_and_prepared_outside_the_clock(self):
    order = []
    timing.time_calls({"a": lambda: order.append("a"),
                       "b": lambda: order.append("b")}, repeats=2,
                      prepare={"a": lambda: order.append("reset")})
    self.assertEqual(order, ["reset", "a", "b"] * 3)

  def test_per_unit_us(self):
    out = timing.per_unit_us(timing.summary([2.0, 1.0, 4.0]), units=1000)
    self.assertEqual(out, {"median_us": 2000.0, "min_us": 1000.0,
                           "repeats": 3, "units_per_repeat": 1000})

  def test_self_timed_keeps_the_warm_up_result_out_of_the_figure(self):
    seconds = iter([9.0, 1.0, 3.0])
    first, out = timing.self_timed(lambda: next(seconds), 2, lambda s: s)
    self.assertEqual(first, 9.0)
    self.assertEqual(out["all_s"], [1.0, 3.0])
    self.assertEqual(out["median_s"], 2.0)

  def test_wall_returns_the_result(self):
    result, seconds = timing.wall(lambda: {"n": 3})
    self.assertEqual(result, {"n": 3})
    self.assertGreaterEqual(seconds, 0)

  def test_compile_program_times_apart_and_counts_flops(self):
    x = jnp.ones((16, 16), jnp.float32)
    program = timing.compile_program(jax.jit(jnp.matmul), x, x)
    self.assertGreater(program.compile_s, 0)
    np.testing.assert_allclose(program(x, x), np.full((16, 16), 16.0))
    if program.flops is not None:  # XLA's count: 2 n^3
      self.assertAlmostEqual(program.flops, 2 * 16**3, delta=16**2)


class RecordTest(absltest.TestCase):

  def test_environment_records_machine_and_load(self):
    env = timing.environment(True, extra="x")
    for key in ("date", "cpu_count", "jax_version", "jax_backend",
                "load_average_start"):
      self.assertIn(key, env)
    self.assertEqual(env["extra"], "x")
    timing.end_environment(env)
    self.assertLen(env["load_average_end"], 3)

  def test_write_results_names_quick_files_and_keeps_json_clean(self):
    out = os.path.join(fixtures.tempdir(self), "new")
    results = {"value": np.float32(1.5), "n": np.int64(2),
               "array": np.arange(2)}
    files = timing.write_results(out, "x_benchmark", True, results, "# x\n")
    self.assertEqual([os.path.basename(f) for f in files],
                     ["x_benchmark_quick.json", "x_benchmark_quick.md"])
    with open(files[0]) as f:
      self.assertEqual(json.load(f), {"value": 1.5, "n": 2, "array": [0, 1]})
    with open(files[1]) as f:
      self.assertEqual(f.read(), "# x\n")
    self.assertEqual(results["markdown"], "# x\n")
    self.assertEqual(results["files"], files)
    self.assertEqual(sorted(os.listdir(out)), sorted(
        os.path.basename(f) for f in files))  # no temporary left


if __name__ == "__main__":
  absltest.main()
