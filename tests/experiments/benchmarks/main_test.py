"""Tests for `python -m experiments.benchmarks`: flags checked up front."""

import os

from absl import app
from absl import flags
from absl.testing import absltest
from absl.testing import flagsaver

from experiments.benchmarks import __main__ as benchmarks_main
from tests.experiments.benchmarks import fixtures

FLAGS = flags.FLAGS


class FlagsTest(absltest.TestCase):

  def setUp(self):
    super().setUp()
    if not FLAGS.is_parsed():
      FLAGS.mark_as_parsed()

  def test_what_flag_refuses_unknown_benchmarks(self):
    with flagsaver.flagsaver():
      FLAGS.what = ["gns"]
      with self.assertRaisesRegex(flags.IllegalFlagValueError,
                                  r"--what=mpm,lbm: unknown \['lbm'\].*"
                                  "subset of.*'design'"):
        FLAGS.what = ["mpm", "lbm"]

  def test_gns_needs_sand_block_dir(self):
    with flagsaver.flagsaver(what=["mpm", "gns"], sand_block_dir=None):
      with self.assertRaisesRegex(app.UsageError,
                                  "--sand_block_dir is required"):
        benchmarks_main.main(["benchmarks"])

  def test_sand_block_dir_without_the_window_is_named(self):
    empty = fixtures.tempdir(self)
    with flagsaver.flagsaver(what=["gns"], sand_block_dir=empty):
      with self.assertRaisesRegex(
          app.UsageError, f"--sand_block_dir={empty}: .*"
          "sand_block_window.npz: missing"):
        benchmarks_main.main(["benchmarks"])

  def test_read_data_is_checked(self):
    missing = os.path.join(fixtures.tempdir(self), "none")
    with flagsaver.flagsaver(what=["dataset"], read_data=missing):
      with self.assertRaisesRegex(app.UsageError, "not a directory"):
        benchmarks_main.main(["benchmarks"])
    with flagsaver.flagsaver(what=["mpm"], read_data=missing):
      with self.assertRaisesRegex(app.UsageError, "only used by"):
        benchmarks_main.main(["benchmarks"])

  def test_input_needs_read_data(self):
    with flagsaver.flagsaver(what=["input"], read_data=None):
      with self.assertRaisesRegex(app.UsageError,
                                  "--read_data is required with --what=input"):
        benchmarks_main.main(["benchmarks"])

  def test_gpu_parts_flag_is_checked(self):
    with flagsaver.flagsaver():
      for bad, why in ((["mpm", "lbm"], r"unknown \['lbm'\]"),
                       (["report", "mpm"], "report goes alone")):
        with self.assertRaisesRegex(flags.IllegalFlagValueError,
                                    f"--gpu_parts=.*{why}.*subset of"):
          FLAGS.gpu_parts = bad

  def test_gpu_flags_need_what_gpu_and_an_existing_reference(self):
    missing = os.path.join(fixtures.tempdir(self), "none.json")
    with flagsaver.flagsaver(what=["mpm"], gpu_parts=["gns"]):
      with self.assertRaisesRegex(app.UsageError,
                                  "--gpu_parts=gns: only used by --what=gpu"):
        benchmarks_main.main(["benchmarks"])
    with flagsaver.flagsaver(what=["gpu"], cpu_reference=missing):
      with self.assertRaisesRegex(app.UsageError,
                                  f"--cpu_reference={missing}: no such file"):
        benchmarks_main.main(["benchmarks"])

  def test_gpu_report_alone_needs_part_files(self):
    empty = fixtures.tempdir(self)
    with flagsaver.flagsaver(what=["gpu"], gpu_parts=["report"], out=empty):
      with self.assertRaisesRegex(app.UsageError,
                                  "--gpu_parts=report: no gpu_<part>.json "
                                  "nor gpu_cpu_<part>.json"):
        benchmarks_main.main(["benchmarks"])

  def test_unexpected_arguments(self):
    with self.assertRaisesRegex(app.UsageError, "unexpected arguments"):
      benchmarks_main.main(["benchmarks", "mpm"])


if __name__ == "__main__":
  absltest.main()
