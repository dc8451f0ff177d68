"""Tests for `gnsjax.tradeoff`: the Pareto front against brute force, and
the cheapest configuration on hand-made tables."""

import json
import math
import os
import tempfile

from absl.testing import absltest
import numpy as np

import mpm
from gnsjax import tradeoff


def row(point, scene, obstacles, shapes, front, **errors):
  return {"point": point, "scene": scene, "obstacles": obstacles,
          "shapes": shapes, "front_error": front,
          **{m: errors.get(m, 0.0) for m in tradeoff.METRICS
             if m != "front_error"}}


# Three configurations on two scenes: a plain one and one with a triangle.
TABLE = {
    "points": [
        {"name": "fast", "seconds": 0.1, "seconds_batched": 0.05},
        {"name": "middle", "seconds": 1.0, "seconds_batched": None},
        {"name": "slow", "seconds": 10.0, "seconds_batched": 2.0},
    ],
    "rows": [
        row("fast", "a", 0, [], 0.30), row("fast", "b", 1, ["triangle"], 0.5),
        row("middle", "a", 0, [], 0.08),
        row("middle", "b", 1, ["triangle"], 0.12),
        row("slow", "a", 0, [], 0.01), row("slow", "b", 1, ["triangle"], 0.02),
    ],
}


def scene(shapes):
  return mpm.sample_scene(0, num_obstacles=len(shapes),
                          shapes=shapes or ("rectangle",))


class ParetoFrontTest(absltest.TestCase):

  def test_equals_brute_force_on_random_points(self):
    rng = np.random.default_rng(0)
    for _ in range(20):
      costs = rng.integers(1, 6, 8).astype(float)  # ties on purpose
      errors = rng.integers(1, 6, 8).astype(float)
      expected = []
      for i in range(8):
        better = [j for j in range(8) if j != i and costs[j] <= costs[i]
                  and errors[j] <= errors[i] and
                  (costs[j], errors[j]) != (costs[i], errors[i])]
        expected.append(not better)
      self.assertEqual(tradeoff.pareto_front(costs, errors), expected)

  def test_a_broken_point_is_never_on_the_front(self):
    self.assertEqual(tradeoff.pareto_front([1.0, 2.0], [math.nan, 0.1]),
                     [False, True])


class CheapestTest(absltest.TestCase):

  def test_the_cheapest_that_meets_the_tolerance_on_every_scene(self):
    # Over both scenes: fast 0.5, middle 0.12, slow 0.02.
    for tolerance, name in ((0.6, "fast"), (0.2, "middle"), (0.1, "slow"),
                            (0.02, "slow")):
      choice = tradeoff.cheapest(TABLE, tolerance)
      self.assertEqual(choice.point["name"], name, tolerance)
      self.assertEqual(choice.scenes, ("a", "b"))

  def test_errors_come_from_the_matching_scenes(self):
    plain = tradeoff.cheapest(TABLE, 0.1, scene=scene([]))
    self.assertEqual((plain.point["name"], plain.error, plain.scenes),
                     ("middle", 0.08, ("a",)))
    triangle = tradeoff.cheapest(TABLE, 0.1, scene=scene(["triangle"]))
    self.assertEqual((triangle.point["name"], triangle.scenes),
                     ("slow", ("b",)))
    # No study scene has two obstacles: the worst over all scenes counts.
    two = tradeoff.cheapest(TABLE, 0.1, scene=scene(["triangle", "rectangle"]))
    self.assertEqual((two.point["name"], two.error), ("slow", 0.02))

  def test_batched_ranks_by_batched_time_and_skips_unmeasured(self):
    choice = tradeoff.cheapest(TABLE, 0.2, batched=True)
    self.assertEqual((choice.point["name"], choice.seconds), ("slow", 2.0))

  def test_none_meets_the_tolerance(self):
    with self.assertRaisesRegex(mpm.InputError, r"slow, reaches 0\.02"):
      tradeoff.cheapest(TABLE, 0.001)

  def test_the_reference_is_never_picked(self):
    # A study's reference has zero error against itself: with "slow" as the
    # reference, a tolerance only it meets is refused, naming "middle".
    table = {**TABLE, "reference": {"name": "slow"}}
    with self.assertRaisesRegex(mpm.InputError, r"middle, reaches 0\.12"):
      tradeoff.cheapest(table, 0.05)
    self.assertEqual(tradeoff.cheapest(table, 0.2).point["name"], "middle")
    # The committed study: 2.5 mm is its reference, 3.5 mm its finest row.
    study = tradeoff.load(os.path.join(
        os.path.dirname(__file__), "..", "..", "docs", "results", "tradeoff",
        "tradeoff.json"))
    with self.assertRaisesRegex(mpm.InputError, "mpm_0.0035, reaches"):
      tradeoff.cheapest(study, 0.001)

  def test_a_broken_run_never_meets_a_tolerance(self):
    table = {"points": TABLE["points"][:1],
             "rows": [row("fast", "a", 0, [], math.nan)]}
    with self.assertRaisesRegex(mpm.InputError, "reaches inf"):
      tradeoff.cheapest(table, 1e9)

  def test_bad_arguments(self):
    for tolerance in (0, -0.1, math.inf, "0.1"):
      with self.assertRaisesRegex(mpm.InputError, "tolerance"):
        tradeoff.cheapest(TABLE, tolerance)
    with self.assertRaisesRegex(mpm.InputError, "allowed: front_error"):
      tradeoff.cheapest(TABLE, 0.1, metric="mse")

  def test_other_metrics(self):
    table = {"points": TABLE["points"],
             "rows": [row(n, "a", 0, [], 0.0, deposit_error=d)
                      for n, d in (("fast", 0.05), ("middle", 0.01),
                                   ("slow", 0.0))]}
    choice = tradeoff.cheapest(table, 0.02, metric="deposit_error")
    self.assertEqual(choice.point["name"], "middle")

  def test_load_round_trip_and_refusal(self):
    with tempfile.TemporaryDirectory() as d:
      path = os.path.join(d, "t.json")
      with open(path, "w") as f:
        json.dump(TABLE, f)
      self.assertEqual(tradeoff.load(path), TABLE)
      with open(path, "w") as f:
        json.dump({"points": []}, f)
      with self.assertRaisesRegex(ValueError, "not a trade-off table"):
        tradeoff.load(path)


if __name__ == "__main__":
  absltest.main()
