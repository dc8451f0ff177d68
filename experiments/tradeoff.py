"""The speed/accuracy trade of the MPM and the learned simulator, measured.

  python -m experiments.tradeoff --out=docs/results/tradeoff \
      [--spacings=0.02,0.014,0.01,0.007,0.005,0.0035] \
      [--reference_spacing=0.0025] [--scenes=14] [--repeats=3] \
      [--gns=small=experiments/pretrained/small,...]

Writes ``tradeoff.json`` (the table ``gnsjax.tradeoff`` reads),
``points.csv``, ``rows.csv``, ``tradeoff.png`` (error against time,
log-log, Pareto front marked), ``tradeoff_batched.png`` and
``tradeoff.md``. The study itself is ``experiments.pareto``.
"""

import os
import sys

from absl import flags
from absl import logging
import tqdm

import mpm
from experiments import figures
from experiments import pareto
from experiments import runtime
from experiments import timing
from gnsjax import run as run_lib
from mpm import io as mpm_io

_OUT = flags.DEFINE_string("out", None, "Output directory.")
_SPACINGS = flags.DEFINE_list(
    "spacings", ["0.02", "0.014", "0.01", "0.007", "0.005", "0.0035"],
    "MPM particle spacings (m) to measure; grid spacing twice each.")
_REFERENCE = flags.DEFINE_float("reference_spacing", 0.0025,
                                "Particle spacing (m) of the reference MPM.")
_SCENES = flags.DEFINE_integer("scenes", 14, "Held-out scenes (the test "
                               "plan's first N; 7 groups).", lower_bound=1)
_FRAMES = flags.DEFINE_integer("num_frames", 600, "Frames per trajectory.",
                               lower_bound=2 * pareto.COMPARE_EVERY)
_REPEATS = flags.DEFINE_integer("repeats", 3, "Timed repeats.", lower_bound=1)
_GNS = flags.DEFINE_list(
    "gns", ["small=experiments/pretrained/small"],
    "Learned simulators as NAME=WORKDIR ('' for none).")
_BATCHED_MIN = flags.DEFINE_float(
    "batched_min_spacing", 0.005, "Time the batched MPM only at spacings at "
    "least this coarse (the finest batches take many minutes on a CPU).")
_TOLERANCES = (0.05, 0.1, 0.2, 0.5)


def _spacings() -> list[float]:
  try:
    spacings = sorted({float(s) for s in _SPACINGS.value}, reverse=True)
  except ValueError:
    raise mpm.InputError(f"--spacings={','.join(_SPACINGS.value)}; allowed: "
                         "numbers (m)") from None
  if not spacings or min(spacings) <= 0 or _REFERENCE.value <= 0:
    raise mpm.InputError("--spacings and --reference_spacing: allowed: "
                         "numbers > 0")
  if _REFERENCE.value > min(spacings):
    raise mpm.InputError(f"--reference_spacing={_REFERENCE.value:g} is "
                         f"coarser than --spacings' {min(spacings):g}; "
                         "allowed: at most the finest spacing")
  return spacings


def _gns_runs(spacings) -> list[tuple[str, str, run_lib.Run]]:
  parsed = []
  for item in [g for g in _GNS.value if g]:
    name, sep, workdir = item.partition("=")
    if not sep or not name:
      raise mpm.InputError(f"--gns item {item!r}; allowed: NAME=WORKDIR")
    runtime.existing_dir("gns", workdir, holding="checkpoints")
    parsed.append((name, workdir))
  runs = []
  for name, workdir in parsed:
    run = run_lib.load_run(workdir)
    spacing = run.config.dataset.spacing
    if not any(abs(spacing - s) < 1e-9 for s in spacings):
      raise mpm.InputError(
          f"--gns {name}: trained at spacing {spacing:g} m, which is not in "
          f"--spacings ({', '.join(f'{s:g}' for s in spacings)}); its "
          "rollouts start from the MPM at its own spacing")
    runs.append((name, workdir, run))
  return runs


def main(argv):
  del argv
  logging.set_verbosity(logging.WARNING)  # orbax's restore chatter
  spacings = _spacings()
  runtime.writable("out", _OUT.value)
  # No persistent compilation cache: the compile times are part of the
  # figures, and a cached program would report its loading time.
  gns = _gns_runs(spacings)
  env = timing.environment(quick=False)
  scenes = pareto.study_scenes(_SCENES.value, _FRAMES.value)
  # The paper's 1000-particle scene with one obstacle times each point.
  timing_scene = next((i for i, s in enumerate(scenes)
                       if s.granular.num_particles == 1000
                       and len(s.obstacles) == 1), 0)
  all_spacings = spacings + ([_REFERENCE.value] if _REFERENCE.value
                             not in spacings else [])
  bar = tqdm.tqdm(total=len(scenes) * (len(all_spacings) + len(gns)),
                  unit="run")
  mpm_runs = {}
  for s in all_spacings:
    bar.set_description(f"MPM {s:g} m")
    mpm_runs[s] = pareto.run_mpm(
        scenes, s, repeats=_REPEATS.value, timing_scene=timing_scene,
        batched=s >= _BATCHED_MIN.value, progress=lambda: bar.update(1))
  gns_runs = []
  for name, workdir, run in gns:
    bar.set_description(f"GNS {name}")
    start = next(r for s, r in mpm_runs.items()
                 if abs(s - run.config.dataset.spacing) < 1e-9)
    gns_runs.append(pareto.run_gns(name, workdir, run, start,
                                   repeats=_REPEATS.value,
                                   timing_scene=timing_scene,
                                   batched=True,
                                   progress=lambda: bar.update(1)))
  bar.close()
  timing.end_environment(env)
  reference = mpm_runs[_REFERENCE.value]
  frames = pareto.compare_frames(_FRAMES.value, [g.frames for g in gns_runs])
  points = [r.point for r in mpm_runs.values()] + [g.point for g in gns_runs]
  rows = pareto.table_rows(reference, list(mpm_runs.values()), gns_runs,
                           frames)
  summary = pareto.summarise(points, rows)
  command = "python -m experiments.tradeoff " + " ".join(sys.argv[1:])
  table = {"points": points, "rows": rows, "frames": frames.tolist(),
           "num_frames": _FRAMES.value,
           "reference": reference.point,
           "scenes": [s.name for s in scenes], "environment": env,
           "command": command}
  out = _OUT.value
  text = pareto.report(summary, table, scenes, _TOLERANCES, command)
  timing.write_results(out, "tradeoff", False, table, text)
  keys = list(dict.fromkeys(k for e in summary for k in e))
  mpm_io.write_csv(os.path.join(out, "points.csv"),
                       [{k: e.get(k) for k in keys} for e in summary])
  mpm_io.write_csv(os.path.join(out, "rows.csv"), rows)
  figures.pareto(summary, os.path.join(out, "tradeoff.png"))
  figures.pareto(summary, os.path.join(out, "tradeoff_batched.png"),
                 batched=True)
  print(text)


if __name__ == "__main__":
  flags.mark_flags_as_required(["out"])
  runtime.run(main)
