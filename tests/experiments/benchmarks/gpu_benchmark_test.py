"""Tests for `experiments.benchmarks.gpu_benchmark` and its parts
(`gpu_agreement`, `gpu_gns`): the accelerator command end to end at tiny
sizes on the CPU, both roles (the CPU reference, then the accelerator's path
against it, with its CPU twin process)."""

import json
import os
import re
import sys

from absl import flags
from absl.testing import absltest
from absl.testing import flagsaver
import numpy as np
import pytest

from experiments.benchmarks import __main__ as benchmarks_main
from experiments.benchmarks import gpu_agreement
from experiments.benchmarks import gpu_benchmark
from experiments.benchmarks import gpu_gns
from tests.experiments.benchmarks import fixtures


FLAGS = flags.FLAGS


class HelpersTest(absltest.TestCase):

  def setUp(self):
    super().setUp()
    if not FLAGS.is_parsed():
      FLAGS.mark_as_parsed()

  def test_positions_round_trip_through_json(self):
    x = np.random.default_rng(0).normal(size=(2, 5, 2)).astype(np.float32)
    back = gpu_agreement.decode_positions(json.loads(json.dumps(
        gpu_agreement.encode_positions(x))))
    np.testing.assert_array_equal(back, x)

  def test_compare_applies_the_stated_tolerances(self):
    rng = np.random.default_rng(1)
    ref = rng.uniform(0.2, 1.2, size=(2, 300, 2)).astype(np.float32)
    same = gpu_agreement.compare(ref, ref, "mpm")
    self.assertTrue(same["agrees"])
    moved = ref.copy()
    moved[0, 0] += 2e-5  # one particle early: over EARLY_TOLERANCE_M
    c = gpu_agreement.compare(moved, ref, "mpm")
    self.assertFalse(c["agrees"])
    self.assertEqual([k for k, ok in c["checks"].items() if not ok],
                     ["early_max"])
    scattered = ref.copy()
    scattered[1] += rng.normal(0, 3e-3, size=scattered[1].shape)
    # Per particle at the end: the MPM is held to it, the GNS is not.
    self.assertFalse(gpu_agreement.compare(scattered, ref,
                                           "mpm")["checks"]["final_rms"])
    self.assertNotIn("final_rms", gpu_agreement.compare(scattered, ref,
                                                        "gns")["checks"])

  def test_one_ulp_moves_every_x_by_one_ulp(self):
    w = np.array([[[0.5, 0.25], [1.0, 1.5]]], np.float32)
    shifted = gpu_agreement.one_ulp(w)
    np.testing.assert_array_equal(shifted[..., 1], w[..., 1])
    np.testing.assert_array_equal(shifted[..., 0],
                                  np.nextafter(w[..., 0], np.float32(2)))

  def test_still_decoder_zeroes_only_the_last_decoder_layer(self):
    params = {"params": {"decoder": {"dense_0": {"kernel": np.ones(2)},
                                     "dense_1": {"kernel": np.ones(2),
                                                 "bias": np.ones(2)}},
                         "node_encoder": {"dense_1": {"kernel": np.ones(2)}}}}
    p = gpu_gns.still_decoder(params, hidden_layers=1)["params"]
    self.assertEqual(float(p["decoder"]["dense_1"]["kernel"].sum()), 0)
    self.assertEqual(float(p["decoder"]["dense_1"]["bias"].sum()), 0)
    self.assertEqual(float(p["decoder"]["dense_0"]["kernel"].sum()), 2)
    self.assertEqual(float(p["node_encoder"]["dense_1"]["kernel"].sum()), 2)

  def test_params_digest_names_the_model(self):
    a = {"w": np.arange(6, dtype=np.float32).reshape(2, 3),
         "b": np.ones(3, np.float32)}
    same = {k: v.copy() for k, v in a.items()}
    self.assertEqual(gpu_gns.params_digest(a), gpu_gns.params_digest(same))
    one_ulp = dict(a, b=np.nextafter(a["b"], np.float32(2)))
    self.assertNotEqual(gpu_gns.params_digest(a),
                        gpu_gns.params_digest(one_ulp))

  def test_a_reference_of_another_model_is_not_compared(self):
    from experiments.benchmarks import gpu_report
    lines = gpu_report._agreement_lines(  # pylint: disable=protected-access
        "GNS", {"reference": {"skipped": "another model (x against y)"}})
    self.assertIn("| against the CPU reference | - | - "
                  "| - | - | - | not compared: another model (x against y) |",
                  lines)
    self.assertNotIn("**no**", "\n".join(lines))

  def test_report_without_parts_is_refused(self):
    with self.assertRaisesRegex(FileNotFoundError, "no gpu_<part>_quick"):
      gpu_benchmark.write_report(fixtures.tempdir(self), True, quick=True)


class SmokeTest(absltest.TestCase):

  def test_command_end_to_end_on_the_cpu(self):
    # The command as a user runs it: every part at tiny sizes (about a
    # minute of one CPU core: a dozen compilations).
    d = fixtures.tempdir(self)
    with flagsaver.flagsaver(what=["gpu"], quick=True, out=d):
      benchmarks_main.main(["benchmarks"])
    self.assertEqual(sorted(os.listdir(d)), [
        "gpu_cpu_gns_quick.json", "gpu_cpu_mpm_quick.json",
        "gpu_cpu_reference_quick.json", "gpu_cpu_reference_quick.md",
        "gpu_cpu_train_quick.json"])
    with open(os.path.join(d, "gpu_cpu_reference_quick.json")) as f:
      ref = json.load(f)
    self.assertEqual(ref["commands"]["mpm"],
                     "python -m experiments.benchmarks " + " ".join(
                         sys.argv[1:]))
    m = ref["parts"]["mpm"]
    self.assertEqual([r["batch"] for r in m["vmapped"]], [1, 2])
    for r in m["vmapped"]:
      self.assertTrue(r["finite"])
      self.assertGreater(r["particle_substeps_per_s"], 0)
    self.assertEqual(m["largest_batch"]["batch"], 2)
    self.assertGreater(m["dataset"]["dataset_h"], 0)
    self.assertIn("envelope", m["agreement"])
    self.assertIn("envelope", ref["parts"]["gns"]["small_model"]["agreement"])
    t = ref["parts"]["train"]
    self.assertLen(t["intervals"], 2)
    self.assertGreater(t["projected_h"]["1500000"], 0)
    # The second config, timed the same way, projected to its own steps.
    t2 = t["second"]
    self.assertLen(t2["intervals"], 2)
    self.assertAlmostEqual(t2["own_projected_h"],
                           t2["own_num_steps"] / t2["steps_per_s"] / 3600)
    with open(os.path.join(d, "gpu_cpu_reference_quick.md")) as f:
      md = f.read()
    self.assertIn("The GPU benchmark's programs on this CPU", md)
    self.assertIn("### The test config", md)


class StoppedPartTest(absltest.TestCase):

  def test_a_part_stopped_midway_keeps_what_it_finished(self):
    # A time limit stops the mpm part during its second batch (here: that
    # batch's log line raises); the file holds the finished rows, marked
    # incomplete, and the report shows them as partial.
    d = fixtures.tempdir(self)

    class Stop(Exception):
      pass

    def log(line):
      if line.startswith("vmapped x2:"):
        raise Stop(line)
    with self.assertRaises(Stop):
      gpu_benchmark.run_part("mpm", d, quick=True, accelerator=False,
                             log=log)
    with open(os.path.join(d, "gpu_cpu_mpm_quick.json")) as f:
      part = json.load(f)
    self.assertFalse(part["complete"])
    m = part["mpm"]
    self.assertGreater(m["single"]["median_s"], 0)
    self.assertIn("envelope", m["agreement"])
    self.assertEqual([r["batch"] for r in m["vmapped"]], [1])
    self.assertNotIn("dataset", m)
    # A part stopped before its first measurement is left out.
    with open(os.path.join(d, "gpu_cpu_train_quick.json"), "w") as f:
      json.dump({**{k: v for k, v in part.items() if k != "mpm"},
                 "part": "train"}, f)
    report = gpu_benchmark.write_report(d, False, quick=True)
    self.assertEqual(report["complete"], {"mpm": False})
    self.assertIn("**partial**", report["markdown"])
    self.assertIn("| vmapped x1 |", report["markdown"])
    self.assertNotIn("| vmapped x2 |", report["markdown"])
    self.assertNotIn("The paper's dataset", report["markdown"])

  def test_an_unknown_part_is_refused_before_any_file(self):
    d = fixtures.tempdir(self)
    with self.assertRaisesRegex(ValueError, "part 'gpu'; allowed"):
      gpu_benchmark.run_part("gpu", os.path.join(d, "x"), quick=True)
    self.assertFalse(os.path.exists(os.path.join(d, "x")))


@pytest.mark.slow  # ~2 min of one core: two roles, a CPU twin process
def test_accelerator_path_against_a_twin_and_the_reference(tmp_path):
  """The accelerator's path, taken on this CPU: a twin process and the
  reference, both CPUs of this jax, agree exactly."""
  d = str(tmp_path)
  log = lambda _: None
  ref = gpu_benchmark.run_benchmark(d, parts=("mpm", "gns"), quick=True,
                                    accelerator=False, log=log)
  out = os.path.join(d, "accelerator")
  reference = os.path.join(d, "gpu_cpu_reference_quick.json")
  acc = gpu_benchmark.run_benchmark(
      out, parts=("mpm", "gns"), quick=True, accelerator=True,
      cpu_reference=reference, command="accelerator", log=log)
  a = acc["parts"]["mpm"]["agreement"]
  for c in (a["twin"]["default"], a["reference"]):
    assert c["agrees"], c
    assert c["final"]["max_m"] == 0.0
  g = acc["parts"]["gns"]["small_model"]["agreement"]
  for c in (g["twin"]["default"], g["twin"]["highest"], g["reference"]):
    assert c["agrees"], c
  assert g["reference"]["precision"] == "highest"
  s = acc["summary"]
  single = ref["parts"]["mpm"]["single"]["median_s"]
  assert s["mpm"]["single_s_cpu"] == single
  assert s["gns"]["mpm_cpu_s"] == single
  assert "Accelerator benchmark" in acc["markdown"]
  assert "against the twin CPU, highest precision" in acc["markdown"]
  assert re.search(r"\| vmapped x2 \| [0-9.e-]+ \(extrapolated\) \| "
                   r"[0-9.e+]+ \| [0-9.e-]+ \| [0-9.e+]+x \|",
                   acc["markdown"])
  # --gpu_parts=report: the report again from the part files alone.
  (again,) = gpu_benchmark.report_all(out, quick=True,
                                      cpu_reference=reference)
  assert again["markdown"] == acc["markdown"]


if __name__ == "__main__":
  absltest.main()
