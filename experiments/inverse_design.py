"""Where to put an obstacle: projected Adam on gradients through GNS or MPM.

  python -m experiments.inverse_design --out=out/design \\
      [--simulator=gns|mpm] [--objective=passed_fraction --x_protect=0.4] \\
      [--shape=semicircle --size=0.04 --x0=1.0] [--scene=scene.json]

Optimises the obstacle's x in [0.5, 1.3] m, logs the objective per
iteration, re-simulates the start and the optimum with the MPM, runs the
brute-force MPM sweep over x for comparison, and plots the objective against
x for GNS and MPM with the optimiser's path (``experiments.studies.design``;
see docs/inverse_design.md).

Methods against baselines at equal budget, on the MPM:

  python -m experiments.inverse_design --out=out/two \\
      --problem=two_obstacles --xs=0.9,1.1 --radii=0.04,0.04 \\
      --method=adam,adam_smoothed,cmaes,random,sweep --budget_s=120

runs each method for the budget (after compiling it), judges every design
by the MPM, re-simulates each method's best, and writes the best objective
against wall time (objective_vs_time.png), trace.csv, summary.json and
report.md (``experiments.studies.design_comparison``). This mode runs when
--problem=two_obstacles or baffles, a baseline (cmaes, random, sweep) or
several methods are named, or a budget is given. --problem=calibrate
recovers the sand's friction angle and the basal friction from a deposit
the MPM made at --truth (``experiments.studies.calibration``).
"""

from absl import app
from absl import flags

from experiments import runtime
from experiments.studies import calibration
from experiments.studies import design
from experiments.studies import design_comparison

_OUT = flags.DEFINE_string("out", "out/design", "Output directory.")
_PROBLEM = flags.DEFINE_enum(
    "problem", "placement", design_comparison.PROBLEMS + ("calibrate",),
    "placement: one obstacle (x, and its size with --optimise_size); "
    "two_obstacles: two semicircles, x and radius each (4 parameters, MPM "
    "only); calibrate: the sand's friction angle and the basal friction from "
    "an observed deposit (--truth, --start; MPM only); baffles: a row of "
    "--num_baffles small rectangles, their x (MPM only).")
# The three studies' settings: a field they share is one flag.
_SETTINGS = runtime.define_flags((design.Settings, design_comparison.Settings,
                                  calibration.Settings))


def _comparing() -> bool:
  """Whether the flags ask for the budgeted comparison (module docstring)."""
  methods = _SETTINGS["method"].value or []
  return (_PROBLEM.value != "placement" or len(methods) > 1 or
          any(m not in design.METHODS for m in methods) or
          _SETTINGS["budget_s"].value is not None or
          _SETTINGS["budget_evals"].value is not None)


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"unexpected arguments: {argv[1:]}")
  simulator = _SETTINGS["simulator"]
  if _comparing() and simulator.present and simulator.value != "mpm":
    raise runtime.InputError("the comparison of methods runs on the MPM; "
                             "allowed: --simulator=mpm")
  if _PROBLEM.value == "calibrate":
    study = calibration
    settings = runtime.settings_from_flags(calibration.Settings, _SETTINGS)
  elif _comparing():
    study = design_comparison
    settings = runtime.settings_from_flags(
        design_comparison.Settings, _SETTINGS, problem=_PROBLEM.value)
  else:
    study = design
    settings = runtime.settings_from_flags(
        design.Settings, _SETTINGS,
        method=",".join(_SETTINGS["method"].value or []))
    runtime.existing_file("scene", settings.scene)
    if settings.workdir:
      runtime.existing_dir("workdir", settings.workdir, holding="checkpoints")
  runtime.writable("out", _OUT.value)
  runtime.enable_compilation_cache()
  summary = study.run(settings, _OUT.value)
  if study is design:
    print(f"improved under the MPM: {summary['improved_under_mpm']}; "
          f"report: {_OUT.value}/report.md")
  elif study is design_comparison:
    print(f"winner: {summary['winner']}; report: {_OUT.value}/report.md")
  else:
    print(f"report: {_OUT.value}/report.md")


if __name__ == "__main__":
  runtime.run(main)
