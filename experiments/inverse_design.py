"""Where to put an obstacle: projected Adam on gradients through GNS or MPM.

  python -m experiments.inverse_design --out=out/design \\
      [--simulator=gns|mpm] [--objective=passed_fraction --x_protect=0.4] \\
      [--shape=semicircle --size=0.04 --x0=1.0] [--scene=scene.json]

Optimises the obstacle's x in [0.5, 1.3] m, logs the objective per
iteration, re-simulates the start and the optimum with the MPM, runs the
brute-force MPM sweep over x for comparison, and plots the objective against
x for GNS and MPM with the optimiser's path (see docs/inverse_design.md).

Methods against baselines at equal budget, on the MPM:

  python -m experiments.inverse_design --out=out/two \
      --problem=two_obstacles --xs=0.9,1.1 --radii=0.04,0.04 \
      --method=adam,adam_smoothed,cmaes,random,sweep --budget_s=120

runs each method for the budget (after compiling it), judges every design
by the MPM, re-simulates each method's best, and writes the best objective
against wall time (objective_vs_time.png), trace.csv, summary.json and
report.md. This mode runs when --problem=two_obstacles or baffles, a
baseline (cmaes, random, sweep) or several methods are named, or a budget
is given. --problem=calibrate recovers the sand's friction angle and the
basal friction from a deposit the MPM made at --truth.
"""

from absl import app
from absl import flags

import mpm
from experiments import runtime
from experiments.studies import settings
from experiments import file_jobs
from mpm import sampler
from mpm import scene as scene_lib

_OUT = flags.DEFINE_string("out", "out/design", "Output directory.")
_SIMULATOR = flags.DEFINE_enum("simulator", "gns", ["gns", "mpm"],
                               "Whose gradients drive the optimiser.")
_OBJECTIVE = flags.DEFINE_enum(
    "objective", "passed_fraction", ["runout", "passed_fraction", "centroid"],
    "What to minimise.")
_X_PROTECT = flags.DEFINE_float("x_protect", 0.4,
                                "passed_fraction: the protected line (m).")
_TARGET_X = flags.DEFINE_float("target_x", 0.6,
                               "centroid: the target deposit centroid x (m).")
_TEMPERATURE = flags.DEFINE_float(
    "temperature", None, "Temperature (m) of the smooth surrogate.")
_SCENE = flags.DEFINE_string(
    "scene", None, "Scene JSON whose first obstacle is designed (default: "
    "the small config's heap of 250 particles with --shape at --x0).")
_SHAPE = flags.DEFINE_enum("shape", "semicircle",
                           ["semicircle", "rectangle", "triangle"],
                           "Obstacle shape (without --scene).")
_SIZE = flags.DEFINE_list("size", ["0.04"],
                          "Obstacle size (m): radius, or width/base,height.")
# The design range of x (gnsjax.design.placement.X_RANGE, whose import
# would cost seconds before the flags are even checked).
_X_RANGE = sampler.OBSTACLE_X_RANGE
_X0 = flags.DEFINE_float("x0", 1.0, "Starting obstacle x (m), in [%g, %g]."
                         % _X_RANGE)
_FRAMES = flags.DEFINE_integer("num_frames", 600, "Frames per rollout.",
                               lower_bound=2)
_WORKDIR = flags.DEFINE_string("workdir", settings.PRETRAINED,
                               "Trained GNS (default: the shipped model); "
                               "empty: MPM only.")
_STEPS = flags.DEFINE_integer("steps", 8, "Gradient evaluations.",
                              lower_bound=1)
_LR = flags.DEFINE_float("learning_rate", 0.05, "Adam step size (m).",
                         lower_bound=0)
_SWEEP = flags.DEFINE_integer("sweep_points", 9, "MPM sweep placements "
                              "(per parameter with --method=sweep).",
                              lower_bound=2)
_OPTIMISE_SIZE = flags.DEFINE_bool(
    "optimise_size", False, "Optimise the obstacle's size too (Table 1 "
    "ranges).")


# gnsjax.design.comparison's names (imported late: it imports jax).
_PROBLEMS = ("placement", "two_obstacles", "baffles", "calibrate")
_BAFFLES = (2, 8)   # baffles in a row: the range this flag allows
_CALIBRATION_METHODS = ("adam", "cmaes", "random", "sweep")
_METHODS = ("adam", "adam_smoothed", "cmaes", "random", "sweep")
_BASELINES = ("cmaes", "random", "sweep")
_RADIUS_RANGE = sampler.SIZE_RANGES["semicircle"]["radius"]

_PROBLEM = flags.DEFINE_enum(
    "problem", "placement", list(_PROBLEMS),
    "placement: one obstacle (x, and its size with --optimise_size); "
    "two_obstacles: two semicircles, x and radius each (4 parameters, MPM "
    "only); calibrate: the sand's friction angle and the basal friction from "
    "an observed deposit (--truth, --start; MPM only); baffles: a row of "
    "--num_baffles small rectangles, their x (MPM only).")
_METHOD = flags.DEFINE_list(
    "method", ["adam"],
    "One or more (comma-separated) of: adam (plain gradients), "
    "adam_smoothed (gradients of the objective smoothed at --sigma), "
    "cmaes, random, sweep (baselines, batched MPM).")
_BUDGET_S = flags.DEFINE_float(
    "budget_s", None, "Wall-time budget (s) per method, after compilation.")
_BUDGET_EVALS = flags.DEFINE_integer(
    "budget_evals", None, "Evaluation budget per method (designs; for "
    "Adam, gradient evaluations).")
_XS = flags.DEFINE_list("xs", ["0.9", "1.1"], "two_obstacles: starting "
                        "base positions (m), in [0.5, 1.3].")
_RADII = flags.DEFINE_list("radii", ["0.04", "0.04"], "two_obstacles: "
                           "starting radii (m), in [0.02, 0.05].")
_NUM_BAFFLES = flags.DEFINE_integer(
    "num_baffles", 5, "baffles: how many, in a row (%d-%d)." % _BAFFLES)
_TRUTH = flags.DEFINE_list(
    "truth", ["33.3", "0.37"], "calibrate: the friction angle (deg) and "
    "basal friction that make the observed deposit (hidden from the "
    "search).")
_START = flags.DEFINE_list(
    "start", ["25", "0.8"], "calibrate: where the search starts (friction "
    "angle in deg, basal friction).")
_BATCH = flags.DEFINE_integer("batch_size", 8, "Designs per batched MPM "
                              "program of the baselines (CMA-ES's "
                              "population).", lower_bound=2)
_SEED = flags.DEFINE_integer("seed", 0, "Seed of the baselines and the "
                             "smoothing.")
_SIGMA = flags.DEFINE_float("sigma", 0.05, "Smoothing scale (m) of "
                            "adam_smoothed.", lower_bound=1e-6)
_SAMPLES = flags.DEFINE_integer(
    "num_samples", 16, "Perturbed designs per smoothed gradient (even).",
    lower_bound=2)
_ESTIMATOR = flags.DEFINE_enum("estimator", "score", ["score", "pathwise"],
                               "Estimator of the smoothed gradient.")


def _comparing() -> bool:
  """Whether the flags ask for the budgeted comparison (module docstring)."""
  return (_PROBLEM.value != "placement" or len(_METHOD.value) > 1 or
          any(m in _BASELINES for m in _METHOD.value) or
          _BUDGET_S.value is not None or _BUDGET_EVALS.value is not None)


def _floats(name: str, values: list[str], count: int) -> list[float]:
  try:
    out = [float(v) for v in values]
  except ValueError:
    out = []
  if len(out) != count:
    raise runtime.InputError(f"--{name}={','.join(values)}: allowed: "
                             f"{count} comma-separated numbers (m)")
  return out


def _check_comparison() -> None:
  """The budgeted comparison's flags: methods, budget, starting design."""
  methods = _METHOD.value
  unknown = [m for m in methods if m not in _METHODS]
  if not methods or unknown or len(set(methods)) != len(methods):
    raise runtime.InputError(f"--method={','.join(methods)}: allowed: one or "
                             f"more distinct of {', '.join(_METHODS)}")
  if _SIMULATOR.present and _SIMULATOR.value != "mpm":
    raise runtime.InputError("the comparison of methods runs on the MPM; "
                             "allowed: --simulator=mpm")
  if _BUDGET_S.value is None and _BUDGET_EVALS.value is None:
    raise runtime.InputError("the comparison of methods needs a budget; "
                             "allowed: --budget_s > 0 and/or --budget_evals "
                             ">= 1")
  if _BUDGET_S.value is not None and not _BUDGET_S.value > 0:
    raise runtime.InputError(f"--budget_s={_BUDGET_S.value:g}; allowed: > 0 "
                             "(s)")
  if _BUDGET_EVALS.value is not None and _BUDGET_EVALS.value < 1:
    raise runtime.InputError(f"--budget_evals={_BUDGET_EVALS.value}; "
                             "allowed: >= 1")
  if _SAMPLES.value % 2:
    raise runtime.InputError(f"--num_samples={_SAMPLES.value}; allowed: "
                             "an even number >= 2 (antithetic pairs)")
  if _PROBLEM.value == "calibrate":
    if "adam_smoothed" in methods:
      raise runtime.InputError(
          f"--method={','.join(methods)}: allowed for --problem=calibrate: "
          f"one or more of {', '.join(_CALIBRATION_METHODS)}")
    from gnsjax.design import calibration  # pylint: disable=g-import-not-at-top
    for name, flag in (("truth", _TRUTH), ("start", _START)):
      try:
        values = [float(v) for v in flag.value]
      except ValueError:
        values = []
      if len(values) != 2:
        raise runtime.InputError(
            f"--{name}={','.join(flag.value)}: allowed: two numbers, the "
            "friction angle (deg) and the basal friction")
      try:
        calibration.check(values)
      except scene_lib.InputError as e:
        raise runtime.InputError(f"--{name}: {e}") from None
  if _PROBLEM.value == "baffles":
    lo, hi = _BAFFLES
    if not lo <= _NUM_BAFFLES.value <= hi:
      raise runtime.InputError(f"--num_baffles={_NUM_BAFFLES.value}; "
                               f"allowed: {lo}-{hi}")
  if _PROBLEM.value == "two_obstacles":
    lo, hi = _X_RANGE
    xs = _floats("xs", _XS.value, 2)
    radii = _floats("radii", _RADII.value, 2)
    for k, x in enumerate(xs):
      if not lo <= x <= hi:
        raise runtime.InputError(f"--xs={','.join(_XS.value)}: obstacle {k} "
                                 f"at x = {x:g}; allowed: [{lo:g}, {hi:g}] m")
    rlo, rhi = _RADIUS_RANGE
    for k, r in enumerate(radii):
      if not rlo <= r <= rhi:
        raise runtime.InputError(
            f"--radii={','.join(_RADII.value)}: obstacle {k} of radius "
            f"{r:g}; allowed: [{rlo:g}, {rhi:g}] m")
    if abs(xs[1] - xs[0]) < radii[0] + radii[1]:
      raise runtime.InputError(
          f"--xs={','.join(_XS.value)} with --radii={','.join(_RADII.value)}"
          f": the obstacles overlap; allowed: base centres at least "
          f"{radii[0] + radii[1]:g} m apart")


def _check_inputs() -> None:
  """Refuses bad flags before anything is created or compiled: the design
  range of x is one range, whether x comes from --x0 or --scene."""
  if _comparing():
    _check_comparison()
    if _PROBLEM.value in ("two_obstacles", "baffles", "calibrate"):
      if _TEMPERATURE.value is not None and not _TEMPERATURE.value > 0:
        raise runtime.InputError(f"--temperature={_TEMPERATURE.value:g}; "
                                 "allowed: > 0 (m)")
      runtime.writable("out", _OUT.value)
      return
    if _SCENE.value is not None:
      raise runtime.InputError("--scene: the comparison of methods builds "
                               "its scene; allowed: --shape, --size, --x0")
  elif len(_METHOD.value) != 1 or _METHOD.value[0] not in (
      "adam", "adam_smoothed"):
    raise runtime.InputError(f"--method={','.join(_METHOD.value)}: allowed: "
                             f"one or more of {', '.join(_METHODS)}")
  lo, hi = _X_RANGE
  if _SCENE.value is not None:
    scene = mpm.Scene.load(runtime.existing_file("scene", _SCENE.value))
    if not scene.obstacles:
      raise runtime.InputError(f"--scene={_SCENE.value}: no obstacle to "
                               "design; allowed: a scene with obstacles")
    x = scene.obstacles[0].x
    if not lo <= x <= hi:
      raise runtime.InputError(f"--scene={_SCENE.value}: obstacles[0].x = "
                               f"{x:g}; allowed: [{lo:g}, {hi:g}] m")
  else:
    if not lo <= _X0.value <= hi:
      raise runtime.InputError(f"--x0={_X0.value:g}; allowed: [{lo:g}, "
                               f"{hi:g}] m")
    keys = scene_lib.OBSTACLE_SHAPES[_SHAPE.value]
    ranges = sampler.SIZE_RANGES[_SHAPE.value]
    try:
      size = [float(s) for s in _SIZE.value]
    except ValueError:
      size = []
    # Optimised sizes stay in Table 1's ranges; a fixed one need only fit.
    if _OPTIMISE_SIZE.value:
      ok = all(ranges[k][0] <= s <= ranges[k][1] for k, s in zip(keys, size))
      allowed = ", ".join(f"{k} in [{ranges[k][0]:g}, {ranges[k][1]:g}]"
                          for k in keys) + " m (--optimise_size)"
    else:
      ok = all(s > 0 for s in size)
      allowed = "positive lengths in m"
    if len(size) != len(keys) or not ok:
      raise runtime.InputError(
          f"--size={','.join(_SIZE.value)}: a {_SHAPE.value} needs "
          f"{list(keys)}; allowed: {allowed}")
  if _TEMPERATURE.value is not None and not _TEMPERATURE.value > 0:
    raise runtime.InputError(f"--temperature={_TEMPERATURE.value:g}; "
                             "allowed: > 0 (m)")
  if _comparing():
    runtime.writable("out", _OUT.value)
    return
  if _METHOD.value == ["adam_smoothed"]:
    if _SAMPLES.value % 2:
      raise runtime.InputError(f"--num_samples={_SAMPLES.value}; allowed: "
                               "an even number >= 2 (antithetic pairs)")
  if _WORKDIR.value:
    runtime.existing_dir("workdir", _WORKDIR.value, holding="checkpoints")
  elif _SIMULATOR.value == "gns":
    raise app.UsageError("--simulator=gns needs --workdir (a trained "
                         "model); or use --simulator=mpm")
  runtime.writable("out", _OUT.value)


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"unexpected arguments: {argv[1:]}")
  _check_inputs()
  runtime.enable_compilation_cache()
  if _PROBLEM.value == "calibrate":
    summary = file_jobs.calibration_study(
        _OUT.value, truth=[float(v) for v in _TRUTH.value],
        start=[float(v) for v in _START.value], methods=_METHOD.value,
        budget_s=_BUDGET_S.value, budget_evals=_BUDGET_EVALS.value,
        num_frames=_FRAMES.value, learning_rate=_LR.value,
        batch_size=_BATCH.value, sweep_points=_SWEEP.value, seed=_SEED.value)
    print(f"report: {_OUT.value}/report.md")
    return
  if _comparing():
    summary = file_jobs.design_comparison(
        _OUT.value, problem=_PROBLEM.value, methods=_METHOD.value,
        budget_s=_BUDGET_S.value, budget_evals=_BUDGET_EVALS.value,
        xs=[float(v) for v in _XS.value],
        radii=[float(v) for v in _RADII.value],
        num_baffles=_NUM_BAFFLES.value, shape=_SHAPE.value,
        size=[float(v) for v in _SIZE.value], x0=_X0.value,
        optimise_size=_OPTIMISE_SIZE.value, num_frames=_FRAMES.value,
        objective=_OBJECTIVE.value, x_protect=_X_PROTECT.value,
        target_x=_TARGET_X.value, temperature=_TEMPERATURE.value,
        learning_rate=_LR.value, sigma=_SIGMA.value,
        num_samples=_SAMPLES.value, batch_size=_BATCH.value,
        sweep_points=_SWEEP.value, seed=_SEED.value)
    print(f"winner: {summary['winner']}; report: {_OUT.value}/report.md")
    return
  summary = file_jobs.inverse_design(
      _OUT.value, scene_path=_SCENE.value, shape=_SHAPE.value,
      size=[float(s) for s in _SIZE.value], x0=_X0.value,
      num_frames=_FRAMES.value, simulator=_SIMULATOR.value,
      objective=_OBJECTIVE.value, x_protect=_X_PROTECT.value,
      target_x=_TARGET_X.value, temperature=_TEMPERATURE.value,
      workdir=_WORKDIR.value, steps=_STEPS.value,
      learning_rate=_LR.value, sweep_points=_SWEEP.value,
      optimise_size=_OPTIMISE_SIZE.value, method=_METHOD.value[0],
      sigma=_SIGMA.value, num_samples=_SAMPLES.value,
      estimator=_ESTIMATOR.value)
  print(f"improved under the MPM: {summary['improved_under_mpm']}; "
        f"report: {_OUT.value}/report.md")


if __name__ == "__main__":
  runtime.run(main)
