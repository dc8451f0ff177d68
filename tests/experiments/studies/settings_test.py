"""Tests for `experiments.studies.settings` and the flags derived from it
(`experiments.runtime.define_flags`): every bad value is refused naming
its flag, and flags round-trip into the same settings."""

import dataclasses
import math

from absl import flags
from absl.testing import absltest

import mpm
from experiments import runtime
from experiments.studies import settings


@dataclasses.dataclass(frozen=True)
class Example(settings.Base):
  count: int = settings.field(3, "A count.", lower=1)
  rate: float = settings.field(0.1, "A rate.", lower=0, strict=True,
                               upper=1)
  limit: float | None = settings.field(None, "An optional limit.", lower=0)
  spacings: tuple[float, ...] = settings.field((0.01, 0.005), "Spacings.",
                                               lower=0, strict=True)
  names: tuple[str, ...] = settings.field(("a",), "Names.",
                                          choices=("a", "b"))
  mode: str = settings.field("x", "A mode.", choices=("x", "y"))
  label: str = settings.field("", "Any text ('' for none).")
  fast: bool = settings.field(False, "A switch.")
  hidden: int = settings.field(0, "Set by the entry point.", flag=False)

  def validate(self):
    if self.limit is not None and self.limit < self.rate:
      raise settings.InputError(f"--limit={self.limit:g} is below --rate")


@dataclasses.dataclass(frozen=True)
class Group(settings.Base):
  shared: int = settings.field(1, "Held by both studies.", lower=0)


@dataclasses.dataclass(frozen=True)
class First(Group):
  mine: str = settings.field("a", "Only the first's.")
  mode: str = settings.field("x", "Set by the entry point.", flag=False)


@dataclasses.dataclass(frozen=True)
class Second(Group):
  mode: tuple[str, ...] = settings.field(("x",), "The second's list.")
  level: float = settings.field(1.0, "Only the second's.", lower=0)


class SettingsTest(absltest.TestCase):

  def test_defaults_pass_and_each_bad_value_names_its_flag(self):
    Example()
    bad = [({"count": 0}, "--count=0: allowed: >= 1"),
           ({"count": 1.5}, "--count=1.5: allowed: an integer"),
           ({"count": True}, "--count=True: allowed: an integer"),
           ({"rate": 0.0}, "--rate=0.0: allowed: > 0"),
           ({"rate": 2.0}, "--rate=2.0: allowed: <= 1"),
           ({"rate": math.nan}, "--rate=nan: allowed: a finite number"),
           ({"limit": math.inf}, "--limit=inf: allowed: a finite number"),
           ({"spacings": ()}, "--spacings is empty"),
           ({"spacings": (0.01, -1.0)}, "--spacings=-1.0: allowed: > 0"),
           ({"spacings": (math.nan,)}, "--spacings=nan: allowed: a finite"),
           ({"names": ("c",)}, "--names=c: allowed: one of ['a', 'b']"),
           ({"mode": "z"}, "--mode=z: allowed: one of ['x', 'y']"),
           ({"count": None}, "--count is required"),
           ({"limit": 0.05}, "--limit=0.05 is below --rate")]
    for changes, message in bad:
      with self.assertRaisesRegex(mpm.InputError, "^" + message.replace(
          "[", r"\[").replace("]", r"\]"), msg=str(changes)):
        Example(**changes)

  def test_flags_round_trip(self):
    values = flags.FlagValues()
    holders = runtime.define_flags(Example, values, count=5)
    self.assertNotIn("hidden", holders)
    self.assertEqual(values["count"].default, 5)
    values(["prog", "--spacings=0.02,0.01", "--names=a,b", "--fast",
            "--limit=0.5"])
    got = runtime.settings_from_flags(Example, holders, hidden=7)
    self.assertEqual(got, Example(count=5, spacings=(0.02, 0.01),
                                  names=("a", "b"), fast=True, limit=0.5,
                                  hidden=7))
    values["spacings"].parse("0.01,abc")
    with self.assertRaisesRegex(mpm.InputError,
                                r"^--spacings=0.01,abc; allowed: "
                                "comma-separated numbers"):
      runtime.settings_from_flags(Example, holders)
    values["spacings"].parse("")
    with self.assertRaisesRegex(mpm.InputError, "^--spacings is empty"):
      runtime.settings_from_flags(Example, holders)

  def test_studies_of_one_entry_point_share_their_flags(self):
    values = flags.FlagValues()
    holders = runtime.define_flags((First, Second), values)
    self.assertEqual(sorted(holders), ["level", "mine", "mode", "shared"])
    # The flag of a field that the first study sets itself is the second's.
    self.assertEqual(values["mode"].default, ["x"])
    values(["prog", "--shared=3", "--mode=y,z"])
    self.assertEqual(runtime.settings_from_flags(First, holders, mode="q"),
                     First(shared=3, mode="q"))
    self.assertEqual(runtime.settings_from_flags(Second, holders),
                     Second(shared=3, mode=("y", "z")))
    # The second's flag, given, is checked where the first study runs too
    # (issue 29: a bad value of a flag the study ignores is no exit 0).
    values(["prog", "--level=-1"])
    with self.assertRaisesRegex(mpm.InputError,
                                r"^--level=-1.0: allowed: >= 0"):
      runtime.settings_from_flags(First, holders, mode="q")


if __name__ == "__main__":
  absltest.main()
