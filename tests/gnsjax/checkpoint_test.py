"""Tests for `gnsjax.checkpoint`'s damage checks: a checkpoint whose files
were deleted is named with what it lacks, never loaded, and a resumed run
sets it aside for the newest intact one (small numpy states: no model)."""

import glob
import os
import tempfile

from absl.testing import absltest
import numpy as np

from gnsjax import checkpoint
from gnsjax import run as run_lib
from mpm import io as mpm_io


def _state(value: float) -> dict:
  return {"params": {"w": np.full((4, 3), value, np.float32)},
          "step": np.asarray(value, np.int32)}


class DamagedCheckpointTest(absltest.TestCase):

  def setUp(self):
    super().setUp()
    tmp = tempfile.TemporaryDirectory()
    self.addCleanup(tmp.cleanup)
    self.dir = tmp.name
    mngr = checkpoint.manager(self.dir, every_steps=1)
    for step in (1, 2, 3):
      checkpoint.save(mngr, step, _state(step), {"a": 1}, {"b": 2},
                      force=True)
    mngr.close()
    self.root = os.path.join(self.dir, "checkpoints")

  def _delete_data(self, step: int) -> None:
    for path in glob.glob(os.path.join(self.root, str(step), "state", "**",
                                       "d", "*"), recursive=True):
      os.remove(path)

  def test_intact_checkpoints_pass(self):
    for step in (1, 2, 3):
      self.assertEqual(checkpoint.missing_files(
          os.path.join(self.root, str(step))), [])
      checkpoint.check_intact(self.root, step)

  def test_deleted_data_files_are_named(self):
    self._delete_data(3)
    missing = checkpoint.missing_files(os.path.join(self.root, "3"))
    self.assertNotEmpty(missing)
    self.assertIn("d/* (the arrays' data)", missing[0])
    with self.assertRaisesRegex(checkpoint.DamagedCheckpointError,
                                rf"checkpoint {self.root}/3 is damaged: "
                                r"state/.*d/\* \(the arrays' data\)"):
      checkpoint.check_intact(self.root, 3)
    # A FormatError: entry points report it in one line, exit code 2.
    self.assertTrue(issubclass(checkpoint.DamagedCheckpointError,
                               mpm_io.FormatError))

  def test_load_run_names_the_damaged_checkpoint(self):
    os.remove(os.path.join(self.root, "3", "config", "metadata"))
    with self.assertRaisesRegex(checkpoint.DamagedCheckpointError,
                                r"3 is damaged: config/metadata missing"):
      run_lib.load_run(self.dir)

  def test_load_config_needs_no_model(self):
    # These checkpoints hold no model or statistics: load_run cannot
    # restore them, their configs read all the same.
    with self.assertRaises(KeyError):
      run_lib.load_run(self.dir)
    self.assertEqual(run_lib.load_config(self.dir).to_dict(), {"a": 1})
    self.assertEqual(run_lib.load_config(self.dir, step=1).to_dict(),
                     {"a": 1})
    with self.assertRaisesRegex(FileNotFoundError, "no checkpoint"):
      run_lib.load_config(os.path.join(self.dir, "empty"))

  def test_resuming_sets_the_damaged_ones_aside(self):
    self._delete_data(3)
    # Step 2 keeps its files but one is cut short: found by reading it.
    (data,) = [p for p in glob.glob(os.path.join(
        self.root, "2", "state", "**", "d", "*"), recursive=True)
               if os.path.getsize(p) > 100][:1]
    with open(data, "r+b") as f:
      f.truncate(10)
    moved = checkpoint.set_aside_damaged(self.dir)
    self.assertLen(moved, 2)
    self.assertIn("skipped the damaged checkpoint at step 3", moved[0])
    self.assertIn("step 2 (", moved[1])
    self.assertIn("cannot be read", moved[1])
    self.assertEqual(sorted(os.listdir(self.root)), ["1"])
    self.assertEqual(sorted(os.listdir(os.path.join(
        self.dir, "damaged_checkpoints"))), ["2", "3"])
    mngr = checkpoint.manager(self.dir, every_steps=1)
    self.assertEqual(mngr.latest_step(), 1)
    mngr.close()
    self.assertEqual(checkpoint.set_aside_damaged(self.dir), [])


if __name__ == "__main__":
  absltest.main()
