"""Tests for `mpm.budget`: the estimate before any work, and the refusal of
what cannot fit (pure arithmetic: no array is built, nothing compiles)."""

import dataclasses
import re

from absl.testing import absltest

import mpm
from mpm import budget
from mpm import simulation
from mpm import transfer

GIB = 2**30


def _paper(**changes) -> mpm.Scene:
  scene = mpm.sample_scene(0)
  granular = {k: changes.pop(k) for k in ("spacing", "num_particles")
              if k in changes}
  if granular:
    scene = dataclasses.replace(scene, granular=dataclasses.replace(
        scene.granular, **granular))
  if "dx" in changes:
    scene = dataclasses.replace(scene, solver=dataclasses.replace(
        scene.solver, dx=changes.pop("dx")))
  return dataclasses.replace(scene, **changes)


class EstimateTest(absltest.TestCase):

  def test_the_paper_scene(self):
    scene = _paper()
    cost = budget.estimate(scene)
    self.assertEqual(cost.particles, scene.granular.num_particles)
    spec = transfer.GridSpec.covering(scene.domain.width,
                                      scene.domain.height, scene.dx)
    self.assertEqual(cost.grid_nodes, spec.n_nodes)
    self.assertEqual(cost.substeps_per_frame, simulation.substeps_per_frame(
        scene, simulation.speed_bound(scene)))
    # docs/performance.md: 3.8 s per 600-frame trajectory, and a few
    # hundred MB (most of it the process itself).
    self.assertBetween(cost.seconds, 2.0, 6.0)
    self.assertBetween(cost.memory_bytes, 0.4 * GIB, 1.0 * GIB)
    self.assertIsNone(budget.warning(cost))

  def test_a_filled_box_scales_with_the_spacing_squared(self):
    coarse = budget.estimate(_paper(spacing=0.002, num_particles=None,
                                    dx=0.004))
    fine = budget.estimate(_paper(spacing=0.001, num_particles=None,
                                  dx=0.002))
    self.assertBetween(fine.particles / coarse.particles, 3.9, 4.1)
    self.assertBetween(fine.grid_nodes / coarse.grid_nodes, 3.5, 4.1)
    self.assertGreater(fine.substeps_per_frame, coarse.substeps_per_frame)

  def test_frames_kept_and_scenes_at_once_add_memory(self):
    short = budget.estimate(_paper(num_frames=600))
    long = budget.estimate(_paper(num_frames=60_000))
    self.assertGreater(long.memory_bytes - short.memory_bytes,
                       59_000 * 1000 * 8)
    self.assertBetween(long.seconds / short.seconds, 99, 101)
    four = budget.estimate(_paper(), scenes=4)
    self.assertEqual(four.memory_bytes, 4 * short.memory_bytes)

  def test_hours_are_warned_with_the_estimate(self):
    cost = budget.estimate(_paper(num_frames=2_000_000))
    self.assertRegex(budget.warning(cost), r"^warning: about 3\.\d+ h of "
                     r"simulating .*956 particles")
    # Many short scenes over few workers add up too.
    self.assertIn("h of simulating",
                  budget.warning(budget.estimate(_paper()), 10_000, 2))


class CheckFitsTest(absltest.TestCase):

  def test_what_fits_passes(self):
    cost = budget.check_fits(_paper(), memory_bytes=4 * GIB)
    self.assertEqual(cost, budget.estimate(_paper()))

  def test_ten_million_particles_are_refused_with_what_fits(self):
    scene = _paper(spacing=0.0001, num_particles=None, dx=0.0002)
    with self.assertRaisesRegex(mpm.InputError, "granular.spacing") as e:
      budget.check_fits(scene, memory_bytes=16 * GIB)
    message = str(e.exception)
    self.assertIn("14,490,000 particles and 49,186,949 grid nodes", message)
    self.assertIn("memory is 16 GiB", message)
    spacing, dx = map(float, re.search(
        r"granular.spacing >= ([\d.e-]+) \(with solver.dx >= ([\d.e-]+)\)",
        message).groups())
    budget.check_fits(_paper(spacing=spacing, num_particles=None, dx=dx),
                      memory_bytes=16 * GIB)
    frames = int(re.search(r"num_frames <= ([\d,]+)", message).group(1)
                 .replace(",", ""))
    budget.check_fits(dataclasses.replace(scene, num_frames=frames),
                      memory_bytes=16 * GIB)

  def test_a_hundred_million_frames_are_refused_by_their_frames(self):
    with self.assertRaisesRegex(mpm.InputError, r"num_frames = 100,000,000: "
                                r".*allowed: what fits, e.g. num_frames <= "
                                r"[\d,]+$"):
      # 956 particles fill no coarser lattice: no spacing is suggested.
      budget.check_fits(_paper(num_frames=100_000_000),
                        memory_bytes=16 * GIB)

  def test_scenes_at_once_name_how_many_fit(self):
    with self.assertRaisesRegex(mpm.InputError, r"--workers <= \d+"):
      budget.check_fits(_paper(), scenes=500, memory_bytes=16 * GIB,
                        names={"scenes": "--workers"})

  def test_a_setting_the_caller_hides_gets_no_fix(self):
    # A study that sets the spacing itself: only its frames are proposed.
    names = {"spacing": None, "dx": None, "num_frames": "--num_frames"}
    with self.assertRaisesRegex(mpm.InputError, r"^spacing = 0.005, "
                                r"--num_frames = 100,000,000: .*e\.g\. "
                                r"--num_frames <= [\d,]+$"):
      budget.check_fits(_paper(num_frames=100_000_000), names=names,
                        memory_bytes=16 * GIB)
    with self.assertRaisesRegex(mpm.InputError, "e.g. a smaller scene$"):
      budget.check_fits(_paper(num_frames=100_000_000),
                        names={**names, "num_frames": None},
                        memory_bytes=16 * GIB)

  def test_this_machine_reports_its_memory(self):
    memory, source = budget.machine_memory_bytes()
    self.assertGreater(memory, 2**28)
    self.assertEqual(source, "this machine's memory")


class PlanTest(absltest.TestCase):

  def test_a_plan_costs_the_sum_of_its_runs(self):
    one, other = _paper(), _paper(num_frames=1200)
    seconds = budget.check_plan([budget.Planned(one, count=3),
                                 budget.Planned(other, count=2)],
                                memory_bytes=16 * GIB)
    self.assertAlmostEqual(seconds, 3 * budget.estimate(one).seconds +
                           2 * budget.estimate(other).seconds)
    self.assertEqual(budget.check_plan([], memory_bytes=16 * GIB), 0.0)

  def test_a_plan_is_refused_by_its_largest_run_naming_its_flag(self):
    plan = [budget.Planned(_paper()),
            budget.Planned(_paper(), at_once=500,
                           names={"scenes": "--batch_size"})]
    with self.assertRaisesRegex(mpm.InputError, r"--batch_size <= (\d+)"):
      budget.check_plan(plan, memory_bytes=16 * GIB)

  def test_hours_are_warned_minutes_are_not(self):
    self.assertIsNone(budget.plan_warning(budget.WARN_SECONDS - 1))
    self.assertIn("about 2 h", budget.plan_warning(7200.0))


class SimulateRefusesTest(absltest.TestCase):
  """The library's own entry points refuse before building anything."""

  def test_simulate_refuses_a_hundred_million_frames(self):
    with self.assertRaisesRegex(mpm.InputError, "num_frames = 100,000,000"):
      mpm.simulate(_paper(num_frames=100_000_000))

  def test_simulate_batch_refuses_a_batch_that_cannot_fit(self):
    # ~0.5 GiB each (mostly the process, counted per scene): 100,000 of
    # them exceed any machine this runs on.
    with self.assertRaisesRegex(mpm.InputError,
                                r"for 100000 at once.*scenes at once <= "):
      mpm.simulate_batch([_paper()] * 100_000)


if __name__ == "__main__":
  absltest.main()
