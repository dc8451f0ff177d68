"""Plain against smoothed gradients over a whole avalanche.

  python -m experiments.gradient_check --out=docs/results/gradient_check \\
      [--sigma=0.05 --num_samples=16 --xs=0.6,0.8,1.0,1.2] \\
      [--objective=passed_fraction --x_protect=0.4] \\
      [--simulator=gns --workdir=experiments/pretrained/small --hs=0.01,0.001]

On the inverse-design study's scene (the small config's heap, 250 particles,
a semicircle of radius 0.04 m, 600 frames), at each obstacle x: the slope of
the objective over x +- sigma (two runs) and central differences at each of
--hs against jax.grad at x and the smoothed gradients
(``gnsjax.design.smoothing``), through the MPM or a trained learned
simulator. Writes ``rows.csv``, ``summary.json`` and ``report.md``
(docs/inverse_design.md).
"""

import os

from absl import flags

from experiments import file_jobs
from experiments import runtime
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
_SIMULATOR = flags.DEFINE_enum("simulator", "mpm", ["mpm", "gns"],
                               "Whose gradients are checked.")
_WORKDIR = flags.DEFINE_string(
    "workdir", "experiments/pretrained/small",
    "The trained learned simulator (--simulator=gns).")
_HS = flags.DEFINE_list("hs", [], "Steps (m) of extra central differences.")


def _check_inputs() -> tuple[list[float], list[float]]:
  try:
    xs = [float(x) for x in _XS.value]
  except ValueError as e:
    raise runtime.InputError(f"--xs={','.join(_XS.value)}: expected "
                             "comma-separated positions (m)") from e
  try:
    hs = [float(h) for h in _HS.value]
  except ValueError as e:
    raise runtime.InputError(f"--hs={','.join(_HS.value)}: expected "
                             "comma-separated steps (m)") from e
  if any(not h > 0 for h in hs):
    raise runtime.InputError(f"--hs={','.join(_HS.value)}: allowed: steps "
                             "> 0 (m)")
  lo, hi = sampler.OBSTACLE_X_RANGE
  for flag, name, reach in ((f"--sigma={_SIGMA.value:g}", "sigma",
                             _SIGMA.value),
                            ("--hs", "h", max(hs, default=0.0))):
    bad = [x for x in xs if not lo <= x - reach <= x + reach <= hi]
    if bad:
      raise runtime.InputError(f"--xs: {bad} with {flag}: x +- {name} must "
                               f"lie in [{lo:g}, {hi:g}] m")
  if _SIMULATOR.value == "gns":
    runtime.existing_dir("workdir", _WORKDIR.value, holding="checkpoints")
  if _SAMPLES.value % 2:
    raise runtime.InputError(f"--num_samples={_SAMPLES.value}: allowed: an "
                             "even number >= 2 (antithetic pairs)")
  runtime.writable("out", _OUT.value)
  return xs, hs


def _driver(scene):
  # pylint: disable=g-import-not-at-top
  from gnsjax.design import gradient_check
  from gnsjax.design import placement
  from gnsjax.design import study
  if _SIMULATOR.value == "mpm":
    return gradient_check.mpm_driver(scene)
  return study.gns_driver(placement.Placement(scene), _WORKDIR.value)


def main(argv):
  del argv
  xs, hs = _check_inputs()
  runtime.enable_compilation_cache()
  # pylint: disable=g-import-not-at-top
  from gnsjax.design import gradient_check
  from gnsjax.design import objectives
  objective = objectives.make(_OBJECTIVE.value, x_protect=_X_PROTECT.value,
                              target_x=_TARGET_X.value)
  scene = file_jobs.design_scene(num_frames=_FRAMES.value)
  rows = gradient_check.check(_driver(scene), objective, xs,
                              sigma=_SIGMA.value, num_samples=_SAMPLES.value,
                              hs=hs)
  os.makedirs(_OUT.value, exist_ok=True)
  mpm_io.write_csv(os.path.join(_OUT.value, "rows.csv"), rows)
  mpm_io.write_json(os.path.join(_OUT.value, "summary.json"), {
      "scene": scene.to_dict(), "objective": _OBJECTIVE.value,
      "x_protect": _X_PROTECT.value, "target_x": _TARGET_X.value,
      "simulator": _SIMULATOR.value,
      "workdir": _WORKDIR.value if _SIMULATOR.value == "gns" else None,
      "rows": rows})
  text = gradient_check.report(
      rows, f"Gradient check ({_SIMULATOR.value.upper()}): "
      f"{_OBJECTIVE.value}, {scene.name}, {_FRAMES.value} frames")
  mpm_io.write_text(os.path.join(_OUT.value, "report.md"), text)
  print(text)


if __name__ == "__main__":
  runtime.run(main)
