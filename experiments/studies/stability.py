"""Where each simulator stays finite and physical, and where it breaks
(``python -m experiments.stability``).

Runs the MPM and the learned simulator at the extremes of what a user may
ask (particle counts, obstacle sizes at both ends of the ramp, friction
angle, stiffness, long learned rollouts from moving starts, scenes outside
the training distribution) and checks every stored frame:

* finite positions;
* no sand more than half a particle spacing outside the domain;
* at most ``MAX_INSIDE`` of the sand deeper than half a spacing inside the
  ramp or an obstacle (the MPM itself leaves up to ~1.4% there, measured);
* no particle faster than ``SPEED_MARGIN`` times the free-fall speed from
  the top of the domain (sand starting at rest cannot gain more energy).

The first frame that fails a check is reported with what failed; a run that
raises (the MPM's own blow-up detection, a refused scene) is reported with
its message. Nothing is saved as data: only the table
(``stability.csv``, ``stability.md``) and one picture per case are written.
"""

import dataclasses
import math
import os
import time
from typing import Any, Callable

import numpy as np
import tqdm

import mpm
from experiments import figures
from experiments.studies import settings
from gnsjax import metrics
from gnsjax import rollout as rollout_lib
from gnsjax import run as run_lib
from mpm import io as mpm_io

MAX_INSIDE = 0.02     # fraction of the sand allowed inside solids
SPEED_MARGIN = 1.25   # times the free-fall speed from the domain's top
REST_SPEED = 0.01     # m/s: sand whose mean speed stays below this rests

@dataclasses.dataclass(frozen=True)
class Check:
  """The outcome of one case: ``frame`` and ``reason`` are None when every
  frame passed."""
  frame: int | None
  reason: str | None
  max_inside: float
  max_outside: float
  max_speed: float
  final_speed: float     # mean sand speed over the last stored interval
  rest_time: float = math.inf   # s; from then on mean speed <= REST_SPEED
  creep: float = 0.0     # m/s, the sand's mean drift after rest_time

  @property
  def ok(self) -> bool:
    return self.frame is None


def check_frames(positions: np.ndarray, frames: np.ndarray,
                 scene: mpm.Scene) -> Check:
  """Checks stored frames of a run for the first unphysical one.

  Args:
    positions: [T, N, 2] sand positions (m) at stored ``frames`` [T]
      (increasing frame numbers, in ``scene.frame_dt`` units).
    scene: the scene simulated (solids, domain, spacing, frame time).

  Returns:
    The first failing frame and why, with the worst values seen over the
    finite frames, and when the sand came to rest (mean speed at most
    ``REST_SPEED`` from then on; inf if it never did) and how fast it
    drifted afterwards.
  """
  x = np.asarray(positions, np.float64)
  frames = np.asarray(frames)
  finite = np.all(np.isfinite(x), axis=(1, 2))
  good = x[finite] if np.any(finite) else x[:0]
  inside = (metrics.inside_solids(good, scene) if len(good) else
            np.zeros(0))
  outside = (metrics.outside_domain(good, scene) if len(good) else
             np.zeros(0))
  dt = np.diff(frames)[:, None] * scene.frame_dt
  speed = np.max(np.linalg.norm(np.diff(x, axis=0), axis=-1) / dt, axis=1,
                 initial=0.0) if len(x) > 1 else np.zeros(0)
  bound = SPEED_MARGIN * math.sqrt(2 * mpm.GRAVITY * scene.domain.height)
  inside_all = np.full(len(x), np.nan)
  outside_all = np.full(len(x), np.nan)
  inside_all[finite], outside_all[finite] = inside, outside
  frame, reason = None, None
  for t in range(len(x)):
    if not finite[t]:
      frame, reason = frames[t], "positions are not finite"
    elif outside_all[t] > 0:
      frame, reason = frames[t], (f"{outside_all[t]:.1%} of the sand "
                                  "outside the domain")
    elif inside_all[t] > MAX_INSIDE:
      frame, reason = frames[t], (f"{inside_all[t]:.1%} of the sand inside "
                                  f"solids (allowed {MAX_INSIDE:.0%})")
    elif t > 0 and np.isfinite(speed[t - 1]) and speed[t - 1] > bound:
      frame, reason = frames[t], (f"speed {speed[t - 1]:.2f} m/s above "
                                  f"{bound:.2f} m/s (free fall x "
                                  f"{SPEED_MARGIN})")
    if frame is not None:
      break
  finite_speed = speed[np.isfinite(speed)]
  final_speed = (float(np.mean(np.linalg.norm(x[-1] - x[-2], axis=-1))
                       / dt[-1, 0]) if len(x) > 1 else 0.0)
  rest, drift = math.inf, 0.0
  if len(good) > 1 and np.all(finite):
    times = frames * scene.frame_dt
    rest = metrics.rest_time(x, times, REST_SPEED)
    drift = metrics.creep(x, times, rest) if math.isfinite(rest) else 0.0
  return Check(None if frame is None else int(frame), reason,
               float(np.max(inside, initial=0.0)),
               float(np.max(outside, initial=0.0)),
               float(np.max(finite_speed, initial=0.0)), final_speed,
               rest, drift)


# ------------------------------------------------------------------ cases ---


def _scene(**changes) -> mpm.Scene:
  """The paper scene (defaults) with top-level keys of the scene file
  replaced (those of the domain, granular, material and solver sections
  merged into the defaults); the grid spacing stays twice the
  particle spacing unless ``solver`` is given."""
  d = mpm.Scene.from_dict({}).to_dict()
  del d["solver"]["dx"]
  for key, value in changes.items():
    merge = key in ("domain", "granular", "material", "solver")
    d[key] = {**d[key], **value} if merge else value
  return mpm.Scene.from_dict(d)


def _obstacle(shape: str, x: float, end: str) -> dict:
  """An obstacle of ``shape`` at ``x`` (m), all sizes at the ``end`` ('min'
  or 'max') of the paper's ranges."""
  ranges = mpm.sampler.SIZE_RANGES[shape]
  return {"shape": shape, "x": x,
          **{k: r[0 if end == "min" else 1] for k, r in ranges.items()}}


# A straight incline of 15 degrees under the sand box (not a training
# ramp), and three obstacles (training scenes have at most two).
INCLINE = {"kind": "polyline", "points": [[0.0, 0.03], [1.65, 0.47]]}
# 30 deg, twice the training ramps' steepest; the sand's box starts above it.
STEEP_INCLINE = {"kind": "polyline",
                 "points": [[0.0, 0.03], [1.65, 0.03 + 1.65 * math.tan(
                     math.radians(30))]]}
THREE = [_obstacle("semicircle", 0.6, "max"),
         {"shape": "rectangle", "x": 0.85, "width": 0.04, "height": 0.05},
         _obstacle("triangle", 1.1, "min")]


@dataclasses.dataclass(frozen=True)
class Case:
  name: str
  simulator: str            # "mpm" or "gns"
  extreme: str              # what the case pushes, in words
  scene: Callable[[], mpm.Scene]
  start_frame: int = 0      # gns: the MPM frame the learned rollout starts at
  learned_steps: int = 0    # gns: steps to roll out (0: the scene's frames)


def mpm_cases() -> list[Case]:
  cases = [
      Case("mpm_base", "mpm", "the paper scene (1000 particles, 5 mm)",
           _scene),
      Case("mpm_particles_20000", "mpm", "20,000 particles (2 mm)",
           lambda: _scene(granular={"num_particles": 20000,
                                    "spacing": 0.002})),
      Case("mpm_straight_incline", "mpm", "a straight 15 deg incline",
           lambda: _scene(ramp=INCLINE)),
      Case("mpm_three_obstacles", "mpm", "three obstacles",
           lambda: _scene(obstacles=THREE)),
  ]
  # The asked ranges' ends, and beyond them (10 particles, 5 and 70 deg,
  # 1e3 Pa) to find where the MPM breaks.
  for n in (100, 10):
    cases.append(Case(f"mpm_particles_{n}", "mpm", f"{n} particles",
                      lambda n=n: _scene(granular={"num_particles": n})))
  for angle in (20, 50, 5, 70):
    cases.append(Case(
        f"mpm_friction_{angle}", "mpm", f"friction angle {angle} deg",
        lambda a=angle: _scene(material={"friction_angle_deg": float(a)})))
  for modulus in (1e4, 1e7, 1e3):
    cases.append(Case(
        f"mpm_stiffness_{modulus:.0e}".replace("+0", ""), "mpm",
        f"Young's modulus {modulus:.0e} Pa".replace("+0", ""),
        lambda e=modulus: _scene(material={"youngs_modulus": e})))
  for shape in mpm.sampler.SIZE_RANGES:
    for end in ("min", "max"):
      for x in mpm.sampler.OBSTACLE_X_RANGE:
        cases.append(Case(
            f"mpm_{shape}_{end}_x{x:g}", "mpm",
            f"{end} {shape} at x = {x:g} m",
            lambda s=shape, e=end, x=x: _scene(obstacles=[_obstacle(s, x, e)])))
  return cases


def gns_cases(spacing: float) -> list[Case]:
  """The learned simulator's cases at its training spacing (m)."""
  def small(**changes):
    return _scene(granular={"spacing": spacing, "num_particles": 250},
                  **changes)
  return [
      Case("gns_moving_2000_none", "gns",
           "2000 learned steps from a moving start, no obstacle",
           small, start_frame=60, learned_steps=2000),
      Case("gns_moving_2000_semicircle", "gns",
           "2000 learned steps from a moving start, a semicircle",
           lambda: small(obstacles=[_obstacle("semicircle", 0.9, "max")]),
           start_frame=60, learned_steps=2000),
      Case("gns_moving_2000_triangle", "gns",
           "2000 learned steps from a moving start, an unseen triangle",
           lambda: small(obstacles=[_obstacle("triangle", 0.7, "max")]),
           start_frame=60, learned_steps=2000),
      Case("gns_straight_incline", "gns", "a straight 15 deg incline",
           lambda: small(ramp=INCLINE)),
      Case("gns_straight_incline_30", "gns", "a straight 30 deg incline",
           lambda: _scene(ramp=STEEP_INCLINE, granular={
               "spacing": spacing, "num_particles": 250,
               "box": [1.25, 0.9, 1.46, 1.19]})),
      Case("gns_three_obstacles", "gns", "three obstacles",
           lambda: small(obstacles=THREE)),
      Case("gns_particles_100", "gns", "100 particles",
           lambda: _scene(granular={"spacing": spacing,
                                    "num_particles": 100})),
  ]


# ------------------------------------------------------------------- runs ---


def _row(case: Case, scene: mpm.Scene | None, check: Check | None,
         frames: int, wall: float, error: str | None = None,
         error_frame: int | None = None,
         against_mpm: dict | None = None) -> dict:
  n = 0 if scene is None else len(mpm.granular_particles(scene))
  status = ("refused" if error and scene is None else
            "broken" if error or not check.ok else "ok")
  return {
      "case": case.name, "simulator": case.simulator,
      "extreme": case.extreme, "particles": n, "frames": frames,
      "status": status,
      "break_frame": (check.frame if check is not None and not check.ok
                      else "" if error_frame is None else error_frame),
      "what": error or (check.reason if check and not check.ok else ""),
      "max_inside_solids": "" if check is None else
                           round(check.max_inside, 4),
      "max_outside_domain": "" if check is None else
                            round(check.max_outside, 4),
      "max_speed_m_s": "" if check is None else round(check.max_speed, 3),
      "final_speed_m_s": "" if check is None else
                         round(check.final_speed, 4),
      "rest_time_s": "" if check is None else round(check.rest_time, 3),
      "creep_mm_s": "" if check is None else round(1e3 * check.creep, 3),
      "wall_time_s": round(wall, 1),
      **(against_mpm or dict.fromkeys(AGAINST_MPM, "")),
  }


# The learned rows' comparison with the MPM on the same scene and frames.
AGAINST_MPM = ("mpm_final_speed_m_s", "mpm_rest_time_s", "mpm_creep_mm_s",
               "travel_ratio", "centre_travel_ratio")


def against_mpm(learned: np.ndarray, mpm_positions: np.ndarray,
                start: np.ndarray, frames: np.ndarray,
                scene: mpm.Scene) -> dict:
  """The MPM's speed at the end, rest time and creep after it on the same
  stored frames, and the learned front's travel from ``start`` [N, 2] over
  the MPM's, and that of the sand's centre (mean x): a thin sheet can carry
  the front as far as the MPM's while the bulk stays behind.

  Args:
    learned, mpm_positions: [T, N, 2] sand (m) at stored ``frames`` [T].
  """
  check = check_frames(mpm_positions, frames, scene)
  ratio = lambda a, b: round(a / b, 3) if abs(b) > 1e-9 else ""
  travel = [float(metrics.runout(x[-1]) - metrics.runout(start))
            for x in (learned, mpm_positions)]
  centre = [float(x[-1, :, 0].mean() - start[:, 0].mean())
            for x in (learned, mpm_positions)]
  return {"mpm_final_speed_m_s": round(check.final_speed, 4),
          "mpm_rest_time_s": round(check.rest_time, 3),
          "mpm_creep_mm_s": round(1e3 * check.creep, 3),
          "travel_ratio": ratio(*travel),
          "centre_travel_ratio": ratio(*centre)}


@dataclasses.dataclass(frozen=True)
class Outcome:
  """A case's table row, and what it ran (for its picture): the scene and
  the sand [T, N, 2] at stored frame numbers [T] (None if nothing ran)."""
  row: dict
  scene: mpm.Scene | None = None
  positions: np.ndarray | None = None
  frames: np.ndarray | None = None


def run_mpm(case: Case) -> Outcome:
  try:
    scene = dataclasses.replace(case.scene(), name=case.name)
  except mpm.InputError as e:
    return Outcome(_row(case, None, None, 0, 0.0, f"scene refused: {e}"))
  start = time.perf_counter()
  try:
    result = mpm.simulate(scene)
  except mpm.InputError as e:  # e.g. the sand does not fit its box
    return Outcome(_row(case, None, None, 0, 0.0, f"scene refused: {e}"))
  except mpm.SimulationError as e:
    return Outcome(_row(case, scene, None, e.frame,
                        time.perf_counter() - start, str(e), e.frame), scene)
  wall = time.perf_counter() - start
  positions = np.asarray(result.positions)
  frames = np.arange(len(positions))
  check = check_frames(positions, frames, scene)
  return Outcome(_row(case, scene, check, len(positions), wall), scene,
                 positions, frames)


def run_gns(case: Case, run: run_lib.Run) -> Outcome:
  """The MPM gives the start (its frames up to the input window's last);
  the learned simulator rolls on from there."""
  problem = run.problem
  c, k = problem.input_frames, problem.frame_stride
  try:
    scene = dataclasses.replace(case.scene(), name=case.name)
  except mpm.InputError as e:
    return Outcome(_row(case, None, None, 0, 0.0, f"scene refused: {e}"))
  window_end = case.start_frame + (c - 1) * k
  steps = case.learned_steps or len(rollout_lib.predicted_frame_indices(
      scene.num_frames, c, k))
  start_scene = dataclasses.replace(scene, num_frames=window_end + 1)
  t = mpm_io.Trajectory.from_result(mpm.simulate(start_scene))
  t = dataclasses.replace(t, positions=t.positions[case.start_frame:])
  begin = time.perf_counter()
  out = rollout_lib.rollout_trajectory(run.model, run.params, t, problem,
                                       n_steps=steps)
  wall = time.perf_counter() - begin
  frames = window_end + k * np.arange(1, steps + 1)
  check = check_frames(out.positions, frames, scene)
  # The MPM on the same scene over the same frames, for the comparison.
  reference = mpm.simulate(dataclasses.replace(
      scene, num_frames=int(frames[-1]) + 1))
  compared = against_mpm(out.positions,
                         np.asarray(reference.positions)[frames],
                         t.positions[0], frames, scene)
  return Outcome(_row(case, scene, check, int(frames[-1]), wall,
                      against_mpm=compared), scene, out.positions, frames)


def picture(outcome: Outcome, path: str) -> str | None:
  """The sand at the first, middle and last stored frame (PNG)."""
  if outcome.positions is None:
    return None
  frames = outcome.frames
  x = np.full((frames[-1] + 1,) + outcome.positions.shape[1:], np.nan,
              np.float32)
  x[frames] = outcome.positions
  chosen = [int(frames[0]), int(frames[len(frames) // 2]), int(frames[-1])]
  return figures.frame_grid(
      [(f"{outcome.row['case']} ({outcome.row['status']})", x)],
      outcome.scene, *mpm.boundary_particles(outcome.scene), chosen, path)


def report(summary: dict[str, Any]) -> str:
  """The table of every case run (Markdown)."""
  lines = ["| case | what it pushes | particles | frames | status | first "
           "bad frame: what | max inside solids | max outside | max speed "
           "(m/s) | mean speed at the end (m/s) | at rest from (s) | creep "
           "after (mm/s) | wall (s) | MPM: speed at the end (m/s) | MPM: "
           "at rest from (s) | MPM: creep after (mm/s) | front travel / "
           "MPM's | centre travel / MPM's |",
           "|---" * 18 + "|"]
  for r in summary["rows"]:
    bad = (f"{r['break_frame']}: {r['what']}" if r["break_frame"] != "" else
           r["what"])
    inside = (f"{r['max_inside_solids']:.2%}"
              if r["max_inside_solids"] != "" else "")
    outside = (f"{r['max_outside_domain']:.2%}"
               if r["max_outside_domain"] != "" else "")
    lines.append(f"| {r['case']} | {r['extreme']} | {r['particles']} | "
                 f"{r['frames']} | {r['status']} | {bad} | {inside} | "
                 f"{outside} | {r['max_speed_m_s']} | "
                 f"{r['final_speed_m_s']} | {r.get('rest_time_s', '')} | "
                 f"{r.get('creep_mm_s', '')} | {r['wall_time_s']} | "
                 f"{r.get('mpm_final_speed_m_s', '')} | "
                 f"{r.get('mpm_rest_time_s', '')} | "
                 f"{r.get('mpm_creep_mm_s', '')} | "
                 f"{r.get('travel_ratio', '')} | "
                 f"{r.get('centre_travel_ratio', '')} |")
  return "\n".join(lines) + "\n"


# ------------------------------------------------------------------ study ---

# The learned simulator's case names (they do not depend on its spacing).
GNS_CASE_NAMES = tuple(c.name for c in gns_cases(0.01))
MPM_CASE_NAMES = tuple(c.name for c in mpm_cases())


@dataclasses.dataclass(frozen=True)
class Settings(settings.Base):
  """Which cases to run, and with which learned simulator."""
  workdir: str = settings.field(
      "experiments/pretrained/small",
      "Trained run for the learned simulator's cases ('' to skip them).")
  only: tuple[str, ...] | None = settings.field(
      None, "Run only these cases (names; default: all).")

  def validate(self):
    if self.only is None:
      return
    known = MPM_CASE_NAMES + GNS_CASE_NAMES
    unknown = sorted(set(self.only) - set(known))
    if unknown:
      raise settings.InputError(f"--only: unknown case(s) {unknown}; "
                                f"allowed: {list(known)}")
    needs_run = sorted(set(self.only) & set(GNS_CASE_NAMES))
    if needs_run and not self.workdir:
      raise settings.InputError(
          f"--only={','.join(needs_run)}: learned-simulator case(s) need "
          "--workdir (a trained run)")


def run(s: Settings, out_dir: str) -> dict[str, Any]:
  """Runs the cases; writes ``stability.csv``, ``stability.md`` and
  ``<case>.png`` into ``out_dir``.

  Returns:
    {"rows": one row per case, "broken": the cases not ok}.
  """
  cases = mpm_cases()
  trained = None
  if s.workdir:
    trained = run_lib.load_run(s.workdir)
    cases += gns_cases(trained.config.dataset.spacing)
  if s.only is not None:
    cases = [c for c in cases if c.name in s.only]
  os.makedirs(out_dir, exist_ok=True)
  rows = []
  for case in tqdm.tqdm(cases, unit="case"):
    outcome = (run_mpm(case) if case.simulator == "mpm" else
               run_gns(case, trained))
    picture(outcome, os.path.join(out_dir, f"{case.name}.png"))
    rows.append(outcome.row)
    mpm_io.write_csv(os.path.join(out_dir, "stability.csv"), rows)
  summary = {"rows": rows,
             "broken": [r["case"] for r in rows if r["status"] != "ok"]}
  mpm_io.write_text(os.path.join(out_dir, "stability.md"), report(summary))
  return summary
