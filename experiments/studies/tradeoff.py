"""Speed against accuracy: the MPM at several resolutions and learned
simulators (``python -m experiments.tradeoff``).

Every configuration (the MPM at several particle spacings, learned
simulators) runs the same held-out scenes, and is scored against the MPM at
the finest spacing (the reference) with metrics that do not need equal
particle counts (``score``). Costs are wall times per trajectory on this
machine, in this run: one scene at a time and, for the MPM, the study's
scenes as one vmapped batch, compilation apart, synchronised, medians of
repeats. The table's format is ``gnsjax.tradeoff``'s, which answers "which
simulator for this tolerance" from it.

Scenes are the paper's test plan (``mpm.dataset.plan``: obstacle count 0-2,
semicircle, rectangle at x = 0.6 / 1.0 / 1.3, the unseen triangle, 700 /
1000 / 1500 particles at the paper's spacing) redrawn at each spacing with
the same sand area (``at_spacing``).

``run`` writes ``tradeoff.json`` (the table ``gnsjax.tradeoff`` reads),
``points.csv``, ``rows.csv``, ``tradeoff.png`` (error against time,
log-log, Pareto front marked), ``tradeoff_batched.png`` and ``tradeoff.md``.
"""

import csv
import dataclasses
import json
import math
import os
import statistics
from typing import Any, Callable, Sequence

import numpy as np
import tqdm

import mpm
from experiments import figures
from experiments import timing
from experiments.studies import settings
from gnsjax import metrics
from gnsjax import rollout as rollout_lib
from gnsjax import run as run_lib
from gnsjax import simulator
from gnsjax import tradeoff
from mpm import budget
from mpm import dataset
from mpm import io as mpm_io
from mpm.resolution import at_spacing  # the study's rule, shipped with mpm

# Lines across the ramp (x, m) whose passing sand is counted over time.
LINES = (1.2, 1.0, 0.8, 0.6, 0.4)
# Bin width (m) of the deposit profile: twice the coarsest spacing studied,
# so every resolution fills its bins.
PROFILE_BIN = 0.04
# Frames compared: every COMPARE_EVERY-th stored frame (37.5 ms).
COMPARE_EVERY = 15


def study_scenes(count: int, num_frames: int = 600) -> list[mpm.Scene]:
  """The first ``count`` scenes of the paper's test plan (paper spacing)."""
  spec = dataset.DatasetSpec(num_train=1, num_test=count,
                             num_frames=num_frames,
                             spacing=dataset.PAPER_SPACING)
  return [p.scene for p in dataset.plan(spec) if p.split == "test"]


def compare_frames(num_frames: int, predicted: Sequence[Sequence[int]] = ()
                   ) -> np.ndarray:
  """Every ``COMPARE_EVERY``-th frame after frame 0 that every learned
  simulator predicts (``predicted``: each one's frame indices)."""
  frames = set(range(COMPARE_EVERY, num_frames, COMPARE_EVERY))
  for p in predicted:
    frames &= set(int(f) for f in p)
  if not frames:
    raise ValueError("compare_frames: no frame common to every simulator")
  return np.array(sorted(frames))


def score(positions: np.ndarray, reference: np.ndarray,
          reference_start: np.ndarray, scene: mpm.Scene) -> dict[str, float]:
  """A run's errors against the reference at the same frames.

  Args:
    positions: [K, N, 2] the run's sand (m) at the compared frames.
    reference: [K, M, 2] the reference's sand at the same frames.
    reference_start: [M, 2] the reference's first frame.
    scene: the run's scene (its solids and spacing for ``inside``).

  Returns:
    ``front_error`` (fraction of the reference's runout distance, at the
    last frame), ``deposit_error`` (m), ``past_error`` (fraction of the sand)
    and ``inside`` (fraction), as in ``gnsjax.tradeoff``.
  """
  x = np.asarray(positions, np.float64)
  reference = np.asarray(reference, np.float64)
  reference_start = np.asarray(reference_start, np.float64)
  if not np.all(np.isfinite(x)):
    return {k: math.nan for k in tradeoff.METRICS}
  past = metrics.mass_past(x, np.array(LINES))
  past_ref = metrics.mass_past(reference, np.array(LINES))
  return {
      "front_error": metrics.front_error_relative(x[-1], reference[-1],
                                                  reference_start),
      "deposit_error": metrics.deposit_error(x[-1], reference[-1],
                                             PROFILE_BIN),
      "past_error": float(np.max(np.mean(np.abs(past - past_ref), 0))),
      "inside": float(np.max(metrics.inside_solids(x, scene))),
  }


@dataclasses.dataclass
class MPMRuns:
  """The MPM at one spacing over the study's scenes.

  Attributes:
    scenes: the scenes at this spacing.
    results: their ``mpm.SimulationResult``s (one run each).
    point: the table entry (``gnsjax.tradeoff``'s ``points``).
  """
  scenes: list[mpm.Scene]
  results: list[mpm.SimulationResult]
  point: dict[str, Any]


def mpm_name(spacing: float) -> str:
  return f"mpm_{spacing:g}"


def run_mpm(scenes: Sequence[mpm.Scene], spacing: float, *, repeats: int,
            timing_scene: int, batched: bool,
            progress: Callable[[], None] = lambda: None) -> MPMRuns:
  """Runs every scene at ``spacing`` once, then times.

  Seconds: ``mpm.simulate``'s own clock (compilation excluded, every chunk
  synchronised), the median of ``repeats`` runs of scene ``timing_scene``
  (its first run included). Compile: the longest over the scenes (a scene
  whose program was already compiled reports 0). Batched: the scenes handed
  to ``mpm.simulate_batch`` at once (vmapped size buckets, one scene per
  program on the CPU), per trajectory, median of ``repeats``.
  """
  scenes = [at_spacing(s, spacing) for s in scenes]
  results = []
  for s in scenes:
    results.append(mpm.simulate(s))
    progress()
  samples = [results[timing_scene].wall_time_s]
  samples += [mpm.simulate(scenes[timing_scene]).wall_time_s
              for _ in range(repeats - 1)]
  batch_s, batch_compile = None, None
  if batched:
    # Scenes of similar size share a program (mpm.simulate_batch's
    # buckets): the per-trajectory time is the mean over all of them.
    runs = [mpm.simulate_batch(scenes) for _ in range(repeats)]
    batch_s = statistics.median(
        statistics.mean(x.wall_time_s for x in r) for r in runs)
    batch_compile = max(x.compile_time_s for x in runs[0])
  point = {
      "name": mpm_name(spacing), "kind": "mpm",
      "label": f"MPM, spacing {spacing * 1000:g} mm (dx {2000 * spacing:g} "
               "mm)",
      "spacing": spacing, "seconds": statistics.median(samples),
      "seconds_all": samples, "seconds_batched": batch_s,
      "compile_s": max(r.compile_time_s for r in results),
      "compile_batched_s": batch_compile, "training_s": None,
      "particles": scenes[timing_scene].granular.num_particles,
      "substeps_per_frame": results[timing_scene].n_substeps,
  }
  return MPMRuns(scenes, results, point)


@dataclasses.dataclass
class GNSRuns:
  """A learned simulator over the study's scenes.

  Attributes:
    positions: per scene, [T, N, 2] the rollout's sand at ``frames``.
    frames: [T] the stored frames its steps land on.
    point: the table entry.
  """
  positions: list[np.ndarray]
  frames: np.ndarray
  point: dict[str, Any]


def training_seconds(workdir: str) -> float | None:
  """A run's training time (s): its provenance (a shipped model) or the
  last row of its ``metrics.csv``."""
  provenance = os.path.join(workdir, "provenance.json")
  if os.path.exists(provenance):
    with open(provenance) as f:
      return json.load(f).get("training_time_s")
  log = os.path.join(workdir, "metrics.csv")
  if os.path.exists(log):
    with open(log, newline="") as f:
      rows = list(csv.DictReader(f))
    if rows:
      return float(rows[-1]["wall_time_s"])
  return None


def gns_batched_seconds(run: run_lib.Run,
                        trajectories: Sequence[mpm_io.Trajectory],
                        repeats: int) -> tuple[float, float]:
  """Seconds per trajectory when the scenes roll out as vmapped programs
  over scenes of similar size (``rollout.rollout_buckets``), and those
  programs' compile seconds.

  The median of ``repeats`` synchronised batches after a warm-up batch
  (whose extra time is the compile), divided by the number of scenes.
  """
  problem = run.problem
  c, k = problem.input_frames, problem.frame_stride
  scenes = [rollout_lib.trajectory_nodes(t, c, k, problem.boundary_particles,
                                         problem.sdf_spacing)
            for t in trajectories]
  n_steps = len(rollout_lib.predicted_frame_indices(
      len(trajectories[0].positions), c, k))
  predictor = simulator.ModelPredictor(run.model)
  batch = lambda: rollout_lib.rollout_buckets(predictor, run.params, scenes,
                                              n_steps, problem.context,
                                              problem.spec)
  timed = timing.time_calls({"batch": batch}, repeats)["batch"]
  return (timed["median_s"] / len(scenes),
          max(timed["warmup_s"] - timed["median_s"], 0.0))


def run_gns(name: str, workdir: str, run: run_lib.Run,
            starts: MPMRuns, *, repeats: int, timing_scene: int,
            batched: bool = False,
            progress: Callable[[], None] = lambda: None) -> GNSRuns:
  """Rolls out every scene from the first frames of the MPM at the run's
  own spacing (``starts``), with the solid constraint.

  Seconds: a whole rollout after a warm-up rollout (compilation excluded),
  synchronised, the median of ``repeats`` (``timing.time_calls``); compile:
  the first rollout's extra time. The MPM frames it starts from are not
  counted (the first (C - 1) k + 1 of 600 frames). Batched: every scene as
  one program (``gns_batched_seconds``).
  """
  problem = run.problem
  trajectories = [mpm_io.Trajectory.from_result(r) for r in starts.results]
  roll = lambda t: rollout_lib.rollout_trajectory(run.model, run.params, t,
                                                  problem)
  positions = [None] * len(trajectories)
  last = []   # the timing scene's rollouts (deterministic: all the same)

  def roll_timing_scene():
    last[:] = [roll(trajectories[timing_scene])]
    return last[0]

  # The warm-up call (its compilation included) is the first rollout.
  timed = timing.time_calls({"gns": roll_timing_scene}, repeats)["gns"]
  first_s = timed["warmup_s"]
  positions[timing_scene] = np.asarray(last[0].positions)
  progress()
  for i in range(len(trajectories)):
    if i != timing_scene:
      positions[i] = np.asarray(roll(trajectories[i]).positions)
      progress()
  frames = rollout_lib.predicted_frame_indices(
      len(trajectories[0].positions), problem.input_frames,
      problem.frame_stride)
  batch_s, batch_compile = None, None
  if batched:
    batch_s, batch_compile = gns_batched_seconds(run, trajectories, repeats)
  point = {
      "name": name, "kind": "gns",
      "label": f"GNS {name} (stride {problem.frame_stride}, spacing "
               f"{starts.point['spacing'] * 1000:g} mm)",
      "workdir": workdir, "step": run.step,
      "spacing": starts.point["spacing"], "seconds": timed["median_s"],
      "seconds_all": timed["all_s"], "seconds_batched": batch_s,
      "compile_s": max(first_s - timed["median_s"], 0.0),
      "compile_batched_s": batch_compile,
      "training_s": training_seconds(workdir),
      "particles": starts.point["particles"],
      "frame_stride": problem.frame_stride,
  }
  return GNSRuns(positions, np.asarray(frames), point)


def scene_row(point: str, scene: mpm.Scene) -> dict[str, Any]:
  return {"point": point, "scene": scene.name,
          "group": dataset.group_of(scene.name),
          "obstacles": len(scene.obstacles),
          "shapes": sorted(o.shape for o in scene.obstacles),
          "particles": scene.granular.num_particles}


def table_rows(reference: MPMRuns, mpm_runs: Sequence[MPMRuns],
               gns_runs: Sequence[GNSRuns], frames: np.ndarray
               ) -> list[dict[str, Any]]:
  """Every configuration's errors on every scene at ``frames``."""
  rows = []
  for i, ref_result in enumerate(reference.results):
    ref = ref_result.positions[frames]
    start = ref_result.positions[0]
    for runs in mpm_runs:
      rows.append({**scene_row(runs.point["name"], runs.scenes[i]),
                   "seconds": runs.results[i].wall_time_s,
                   **score(runs.results[i].positions[frames], ref, start,
                           runs.scenes[i])})
    for g in gns_runs:
      index = np.searchsorted(g.frames, frames)
      scene = next(r.scenes[i] for r in mpm_runs
                   if r.point["spacing"] == g.point["spacing"])
      rows.append({**scene_row(g.point["name"], scene), "seconds": None,
                   **score(g.positions[i][index], ref, start, scene)})
  return rows


def summarise(points: Sequence[dict], rows: Sequence[dict]) -> list[dict]:
  """Per configuration: its cost, median and worst error of each metric over
  the scenes, and whether it is on the Pareto front (worst front error
  against seconds per trajectory)."""
  out = []
  for p in points:
    mine = [r for r in rows if r["point"] == p["name"]]
    entry = dict(p)
    for m in tradeoff.METRICS:
      values = [math.inf if math.isnan(r[m]) else r[m] for r in mine]
      entry[f"{m}_median"] = float(np.median(values))
      entry[f"{m}_max"] = float(np.max(values))
    out.append(entry)
  front = tradeoff.pareto_front([e["seconds"] for e in out],
                                [e["front_error_max"] for e in out])
  for e, f in zip(out, front):
    e["pareto"] = f
  return out


def _fmt(v, spec=".3g"):
  return "-" if v is None else format(v, spec)


def picks(table: dict[str, Any], scenes: Sequence[mpm.Scene],
          tolerances: Sequence[float]) -> list[dict[str, Any]]:
  """What ``gnsjax.tradeoff.cheapest`` picks from ``table`` for every scene
  (``"all"``) and for each test group (``scenes``: the study's scenes).

  Returns:
    One entry per group: ``scenes`` (its label) and ``choices``, per
    tolerance the pick's ``name`` and ``seconds`` (None if none meets it).
  """
  groups = [("all", None)] + [
      (g, next(s for s in scenes if dataset.group_of(s.name) == g))
      for g in sorted({r["group"] for r in table["rows"]})]
  out = []
  for label, scene in groups:
    choices = []
    for t in tolerances:
      try:
        c = tradeoff.cheapest(table, t, scene=scene)
        choices.append({"name": c.point["name"], "seconds": c.seconds})
      except mpm.InputError:
        choices.append(None)
    out.append({"scenes": label, "choices": choices})
  return out


def report(summary: dict[str, Any]) -> str:
  """The Markdown report of a :func:`run`'s summary: the configurations,
  and which one to pick for each test group and tolerance."""
  table, tolerances = summary["table"], summary["tolerances"]
  env = table["environment"]
  asked = (f"Command: `{table['command']}`" if table.get("command") else
           f"Settings: `{json.dumps(table.get('settings'))}`")
  lines = [
      "# Speed against accuracy: the MPM at several resolutions and the "
      "learned simulator", "",
      asked, "",
      f"Machine: {env['platform']}, {env['cpu_count']} CPU cores, jax "
      f"{env['jax_version']} on {env['jax_backend']}; load average at the "
      f"start {env['load_average_start'][0]:.2f}, at the end "
      f"{env.get('load_average_end', [math.nan])[0]:.2f}. Date "
      f"{env['date']}.", "",
      f"Reference: {table['reference']['label']}. "
      f"{len(table['scenes'])} held-out scenes "
      f"({', '.join(sorted({r['group'] for r in table['rows']}))}); errors "
      f"at frames {table['frames'][0]}-{table['frames'][-1]} every "
      f"{COMPARE_EVERY} (final: frame {table['frames'][-1]}).", "",
      f"Seconds: per trajectory of {table['num_frames']} frames, one scene at "
      "a time (the scene of the paper's 1000 particles), compilation apart "
      "(compile: cold, no persistent cache); batched: "
      "per trajectory when all scenes run as one vmapped program. Front: "
      "|front - reference front| over the reference's runout distance. "
      "Deposit: RMS height error of the final deposit profile (m, "
      f"{PROFILE_BIN * 100:g} cm bins). Past: fraction of the sand past "
      f"the lines x = {', '.join(f'{x:g}' for x in LINES)} m, mean absolute "
      "difference over time, worst line. Inside: largest fraction of sand "
      "deeper than half a spacing inside a solid. Median / worst over the "
      "scenes.", "",
      "| configuration | particles | s / traj | batched s / traj | compile "
      "s | training h | front median / worst | deposit (m) median / worst "
      "| past median / worst | inside worst | Pareto |",
      "|---|---|---|---|---|---|---|---|---|---|---|"]
  for e in summary["configurations"]:
    training = (None if e["training_s"] is None else e["training_s"] / 3600)
    lines.append(
        f"| {e['label']} | {e['particles']} | {_fmt(e['seconds'])} | "
        f"{_fmt(e['seconds_batched'])} | {_fmt(e['compile_s'], '.1f')} | "
        f"{_fmt(training, '.2f')} | {e['front_error_median']:.1%} / "
        f"{e['front_error_max']:.1%} | {e['deposit_error_median']:.3f} / "
        f"{e['deposit_error_max']:.3f} | {e['past_error_median']:.3f} / "
        f"{e['past_error_max']:.3f} | {e['inside_max']:.1%} | "
        f"{'yes' if e['pareto'] else ''} |")
  lines += ["", "## Which to pick (`gnsjax.tradeoff.cheapest`)", "",
            "The cheapest configuration whose worst front error over the "
            "matching study scenes meets the tolerance, one scene at a "
            "time:", "",
            "| scenes | " + " | ".join(f"front <= {t:.0%}" for t in tolerances)
            + " |", "|---|" + "---|" * len(tolerances)]
  for group in summary["picks"]:
    cells = ["none" if c is None else f"{c['name']} ({c['seconds']:.2g} s)"
             for c in group["choices"]]
    lines.append(f"| {group['scenes']} | " + " | ".join(cells) + " |")
  return "\n".join(lines) + "\n"


# ------------------------------------------------------------------ study ---

# Tolerances (front error, a fraction of the runout) of the report's picks.
TOLERANCES = (0.05, 0.1, 0.2, 0.5)


@dataclasses.dataclass(frozen=True)
class Settings(settings.Base):
  """Which configurations run, on which scenes, timed how often."""
  spacings: tuple[float, ...] = settings.field(
      (0.02, 0.014, 0.01, 0.007, 0.005, 0.0035),
      "MPM particle spacings (m) to measure; grid spacing twice each.",
      lower=0, strict=True)
  reference_spacing: float = settings.field(
      0.0025, "Particle spacing (m) of the reference MPM.", lower=0,
      strict=True)
  scenes: int = settings.field(
      14, "Held-out scenes (the test plan's first N; 7 groups).", lower=1)
  num_frames: int = settings.field(600, "Frames per trajectory.",
                                   lower=2 * COMPARE_EVERY)
  repeats: int = settings.field(3, "Timed repeats.", lower=1)
  gns: tuple[str, ...] = settings.field(
      ("small=experiments/pretrained/small",),
      "Learned simulators as NAME=WORKDIR ('' for none).", allow_empty=True)
  batched_min_spacing: float = settings.field(
      0.005, "Time the batched MPM only at spacings at least this coarse "
      "(the finest batches take many minutes on a CPU).", lower=0)
  command: str = settings.field(
      "", "The command line that asked for the run, for the report ('': "
      "the settings are reported).", flag=False)

  def validate(self):
    if self.reference_spacing > min(self.spacings):
      raise settings.InputError(
          f"--reference_spacing={self.reference_spacing:g} is coarser than "
          f"--spacings' {min(self.spacings):g}; allowed: at most the finest "
          "spacing")
    names = [name for name, _ in self.gns_workdirs()]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
      raise settings.InputError(f"--gns: name(s) {twice} given twice; "
                                "allowed: distinct names")

  def simulations(self) -> list[budget.Planned]:
    scenes = study_scenes(self.scenes, self.num_frames)
    largest = max(scenes, key=lambda x: x.granular.num_particles)
    plan = []
    for spacing in sorted(set(self.spacings) | {self.reference_spacing}):
      names = {"spacing": ("--reference_spacing" if spacing ==
                           self.reference_spacing else "--spacings"),
               "num_frames": "--num_frames", "dx": None, "scenes": None}
      plan += [budget.Planned(at_spacing(x, spacing), names=names)
               for x in scenes]
      plan.append(budget.Planned(at_spacing(largest, spacing),
                                 count=self.repeats - 1, names=names))
      if spacing >= self.batched_min_spacing and spacing in self.spacings:
        plan.append(budget.Planned(
            at_spacing(largest, spacing), count=self.repeats * len(scenes),
            at_once=len(scenes), names={**names, "scenes": "--scenes"}))
    return plan

  def gns_workdirs(self) -> list[tuple[str, str]]:
    """(name, work directory) of each ``--gns`` item; InputError for an
    item that is not NAME=WORKDIR."""
    out = []
    for item in self.gns:
      name, sep, workdir = item.partition("=")
      if not sep or not name or not workdir:
        raise settings.InputError(f"--gns item {item!r}; allowed: "
                                  "NAME=WORKDIR")
      out.append((name, workdir))
    return out


def load_gns(s: Settings, spacings: Sequence[float]
             ) -> list[tuple[str, str, run_lib.Run]]:
  """The learned simulators of ``s.gns``, each checked to be trained at one
  of ``spacings`` (m): its rollouts start from the MPM at its own spacing.

  Raises:
    InputError: naming ``--gns`` and ``--spacings``.
  """
  runs = []
  for name, workdir in s.gns_workdirs():
    run = run_lib.load_run(workdir)
    spacing = run.config.dataset.spacing
    if not any(abs(spacing - x) < 1e-9 for x in spacings):
      raise settings.InputError(
          f"--gns {name}: trained at spacing {spacing:g} m, which is not in "
          f"--spacings ({', '.join(f'{x:g}' for x in spacings)}); its "
          "rollouts start from the MPM at its own spacing")
    runs.append((name, workdir, run))
  return runs


def run(s: Settings, out_dir: str) -> dict[str, Any]:
  """Runs every configuration on the study's scenes and writes the table,
  the report and the figures into ``out_dir`` (created after the runs).

  The learned simulators are loaded and checked before anything runs. No
  persistent compilation cache should be enabled: the compile times are
  part of the figures, and a cached program would report its loading time.

  Returns:
    ``table`` (``tradeoff.json``'s content), ``configurations`` (per
    configuration its cost, median and worst errors and Pareto membership:
    :func:`summarise`), ``tolerances`` and ``picks`` (:func:`picks`).
  """
  spacings = sorted(set(s.spacings), reverse=True)
  gns = load_gns(s, spacings)
  env = timing.environment(quick=False)
  scenes = study_scenes(s.scenes, s.num_frames)
  # The paper's 1000-particle scene with one obstacle times each point.
  timing_scene = next((i for i, x in enumerate(scenes)
                       if x.granular.num_particles == 1000
                       and len(x.obstacles) == 1), 0)
  all_spacings = spacings + ([s.reference_spacing] if s.reference_spacing
                             not in spacings else [])
  bar = tqdm.tqdm(total=len(scenes) * (len(all_spacings) + len(gns)),
                  unit="run")
  mpm_runs = {}
  for spacing in all_spacings:
    bar.set_description(f"MPM {spacing:g} m")
    mpm_runs[spacing] = run_mpm(
        scenes, spacing, repeats=s.repeats, timing_scene=timing_scene,
        batched=spacing >= s.batched_min_spacing,
        progress=lambda: bar.update(1))
  gns_runs = []
  for name, workdir, trained in gns:
    bar.set_description(f"GNS {name}")
    start = next(r for x, r in mpm_runs.items()
                 if abs(x - trained.config.dataset.spacing) < 1e-9)
    gns_runs.append(run_gns(name, workdir, trained, start,
                            repeats=s.repeats, timing_scene=timing_scene,
                            batched=True, progress=lambda: bar.update(1)))
  bar.close()
  timing.end_environment(env)
  reference = mpm_runs[s.reference_spacing]
  frames = compare_frames(s.num_frames, [g.frames for g in gns_runs])
  points = [r.point for r in mpm_runs.values()] + [g.point for g in gns_runs]
  rows = table_rows(reference, list(mpm_runs.values()), gns_runs, frames)
  table = {"points": points, "rows": rows, "frames": frames.tolist(),
           "num_frames": s.num_frames, "reference": reference.point,
           "scenes": [x.name for x in scenes], "environment": env,
           "command": s.command, "settings": s.to_dict()}
  configurations = summarise(points, rows)
  summary = {"table": table, "configurations": configurations,
             "tolerances": list(TOLERANCES),
             "picks": picks(table, scenes, TOLERANCES)}
  timing.write_results(out_dir, "tradeoff", False, dict(table),
                       report(summary))
  keys = list(dict.fromkeys(k for e in configurations for k in e))
  mpm_io.write_csv(os.path.join(out_dir, "points.csv"),
                   [{k: e.get(k) for k in keys} for e in configurations])
  mpm_io.write_csv(os.path.join(out_dir, "rows.csv"), rows)
  figures.pareto(configurations, os.path.join(out_dir, "tradeoff.png"))
  figures.pareto(configurations,
                 os.path.join(out_dir, "tradeoff_batched.png"), batched=True)
  return summary
