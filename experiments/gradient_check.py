"""Plain against smoothed gradients over a whole avalanche, through the MPM.

  python -m experiments.gradient_check --out=docs/results/gradient_check \\
      [--sigma=0.05 --num_samples=16 --xs=0.6,0.8,1.0,1.2] \\
      [--objective=passed_fraction --x_protect=0.4]

On the inverse-design study's scene (the small config's heap, 250 particles,
a semicircle of radius 0.04 m, 600 frames), at each obstacle x: the slope of
the objective over x +- sigma (two MPM runs) against jax.grad at x and the
smoothed gradients (``gnsjax.design.smoothing``). Writes ``rows.csv``,
``summary.json`` and ``report.md`` (docs/inverse_design.md).
"""

import os

from absl import flags

from experiments import runtime
from experiments import tasks
from mpm import io as mpm_io
from mpm import sampler

_OUT = flags.DEFINE_string("out", "out/gradient_check", "Output directory.")
_SIGMA = flags.DEFINE_float("sigma", 0.05, "Smoothing scale (m), > 0.",
                            lower_bound=1e-6)
_SAMPLES = flags.DEFINE_integer(
    "num_samples", 16, "Perturbed designs per smoothed gradient (even).",
    lower_bound=2)
_XS = flags.DEFINE_list("xs", ["0.6", "0.8", "1.0", "1.2"],
                        "Obstacle positions (m).")
_OBJECTIVE = flags.DEFINE_enum("objective", "passed_fraction",
                               ["passed_fraction", "runout", "centroid"],
                               "What to minimise.")
_X_PROTECT = flags.DEFINE_float("x_protect", 0.4, "passed_fraction's line "
                                "(m).")
_TARGET_X = flags.DEFINE_float("target_x", 0.6, "centroid's target (m).")
_FRAMES = flags.DEFINE_integer("num_frames", 600, "Frames per rollout.",
                               lower_bound=2)


def _check_inputs() -> list[float]:
  try:
    xs = [float(x) for x in _XS.value]
  except ValueError as e:
    raise runtime.InputError(f"--xs={','.join(_XS.value)}: expected "
                             "comma-separated positions (m)") from e
  lo, hi = sampler.OBSTACLE_X_RANGE
  sigma = _SIGMA.value
  bad = [x for x in xs if not lo <= x - sigma <= x + sigma <= hi]
  if bad:
    raise runtime.InputError(
        f"--xs: {bad} with --sigma={sigma:g}: x +- sigma must lie in "
        f"[{lo:g}, {hi:g}] m")
  if _SAMPLES.value % 2:
    raise runtime.InputError(f"--num_samples={_SAMPLES.value}: allowed: an "
                             "even number >= 2 (antithetic pairs)")
  runtime.writable("out", _OUT.value)
  return xs


def main(argv):
  del argv
  xs = _check_inputs()
  runtime.enable_compilation_cache()
  # pylint: disable=g-import-not-at-top
  from experiments import evaluation
  from gnsjax.design import gradient_check
  from gnsjax.design import objectives
  objective = objectives.make(_OBJECTIVE.value, x_protect=_X_PROTECT.value,
                              target_x=_TARGET_X.value)
  scene = tasks.design_scene(num_frames=_FRAMES.value)
  rows = gradient_check.check(scene, objective, xs, sigma=_SIGMA.value,
                              num_samples=_SAMPLES.value)
  os.makedirs(_OUT.value, exist_ok=True)
  evaluation.write_csv(os.path.join(_OUT.value, "rows.csv"), rows)
  mpm_io.write_json(os.path.join(_OUT.value, "summary.json"), {
      "scene": scene.to_dict(), "objective": _OBJECTIVE.value,
      "x_protect": _X_PROTECT.value, "target_x": _TARGET_X.value,
      "rows": rows})
  text = gradient_check.report(
      rows, f"Gradient check: {_OBJECTIVE.value}, {scene.name}, "
      f"{_FRAMES.value} frames")
  mpm_io.write_text(os.path.join(_OUT.value, "report.md"), text)
  print(text)


if __name__ == "__main__":
  runtime.run(main)
