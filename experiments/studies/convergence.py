"""The MPM's answer against its resolution: granular column collapse and the
paper's scenes (``python -m experiments.convergence``).

A column of sand (height h0, width h0 / a for aspect ratio a) against a
frictionless wall collapses on a flat floor (friction 0.7, friction angle 45
deg unless ``friction_angle`` says otherwise). The normalised runout
(L - L0) / L0 is measured from the furthest particle (the front), from the
99.5% and 90% quantiles of x (L behind which that fraction of the sand
lies) and from the centre of mass: the front measures the deposit's
thinnest toe, the centre its bulk.

The column runs at each particle spacing (grid spacing twice it); then the
scenes of the paper's test plan named by ``paper_scenes`` (indices) at
``paper_spacings``, measured by how far the avalanche's front (the smallest
x: the sand runs towards x = 0), its 1% and 10% quantiles and its mean x
travelled. Richardson extrapolation over the three finest spacings
estimates the converged value where the changes shrink. ``run`` writes
``convergence.csv``, ``convergence_paper.csv``, ``convergence.md``,
``deposits.png`` (the final deposits at every spacing, overlaid) and
``environment.json`` (machine, load, command).
"""

import dataclasses
import itertools
import json
import math
import os
from typing import Any, Sequence

import numpy as np
import tqdm

import mpm
from experiments import figures
from experiments import timing
from experiments.studies import settings
from experiments.studies import tradeoff
from mpm import budget
from mpm import dataset
from mpm import io as mpm_io
from mpm import scene as scene_lib

FLOOR = 0.02            # m, the floor's height in the domain
FLOOR_FRICTION = 0.7
FRICTION_ANGLE = 45.0   # deg
FRAME_TIME = 0.0025     # s between stored frames (the scenes' default)


def column_domain(aspect: float, height: float) -> tuple[float, float]:
  """(width, height) (m) of the domain of a column of ``height`` (m) and
  aspect ratio ``aspect``: room to run out, and 6 cm above the column."""
  return height / aspect + max(6.0 * height, 0.3), height + 0.06


def column_scene(aspect: float, spacing: float, height: float = 0.1,
                 cfl: float = 0.4, duration: float = 0.8,
                 rheology: str = "drucker_prager",
                 friction_angle: float = FRICTION_ANGLE) -> mpm.Scene:
  """A column of ``height`` (m) and width height / aspect against the left
  wall, on a flat floor with room to run out; grid spacing 2 x spacing;
  the sand of ``rheology`` (mu(I) with its defaults: at rest the same as
  Drucker-Prager's at ``friction_angle``, deg)."""
  width0 = height / aspect
  width, top = column_domain(aspect, height)
  suffix = "" if rheology == "drucker_prager" else f"_{rheology}"
  return scene_lib.with_rheology(mpm.Scene.from_dict({
      "name": f"column_a{aspect:g}_s{spacing:g}{suffix}",
      "domain": {"width": width, "height": top},
      "ramp": {"kind": "polyline", "points": [[0.0, FLOOR], [width, FLOOR]]},
      "granular": {"box": [0.0, FLOOR, width0, FLOOR + height],
                   "spacing": spacing, "num_particles": None},
      "material": {"friction_angle_deg": friction_angle},
      "boundary_friction": FLOOR_FRICTION, "wall_friction": 0.0,
      "solver": {"dx": 2 * spacing, "cfl": cfl},
      "num_frames": int(round(duration / FRAME_TIME))}), rheology)


# Deposit measures, from the toe to the bulk: (name, quantile of the final
# x; None for the centre of mass).
MEASURES = (("runout_front", 1.0), ("runout_q995", 0.995),
            ("runout_q90", 0.9), ("centre", None))


def runouts(final_x: np.ndarray, width0: float) -> dict[str, float]:
  """Normalised runouts of the final x [N] (m) of a column of width
  ``width0`` (m), keyed as ``MEASURES``.

  A quantile q gives (L_q - L0) / L0, L_q the x behind which a fraction q of
  the sand lies (1: the furthest particle, the front); the centre gives
  (X - L0 / 2) / L0, X the mean x, L0 / 2 the column's own.
  """
  out = {}
  for name, q in MEASURES:
    if q is None:
      out[name] = (float(np.mean(final_x)) - width0 / 2) / width0
    else:
      out[name] = (float(np.quantile(final_x, q)) - width0) / width0
  return out


def richardson(values: Sequence[float]) -> tuple[float, float]:
  """(extrapolated value, observed order) from values at spacings h, h/2,
  h/4 (coarse to fine); NaN when the changes do not shrink."""
  a, b, c = values[-3:]
  d1, d2 = b - a, c - b
  if d1 == 0 or d2 / d1 <= 0 or abs(d2) >= abs(d1):
    return float("nan"), float("nan")
  ratio = d1 / d2
  order = math.log2(ratio)
  return c + d2 / (ratio - 1), order


# Paper scenes: (name, quantile of x; None for the mean). The sand runs
# towards x = 0, so its front is a low quantile.
PAPER_MEASURES = (("front_travel_m", 0.0), ("front_q01_travel_m", 0.01),
                  ("front_q10_travel_m", 0.1), ("mean_travel_m", None))


def paper_measures(initial_x: np.ndarray,
                   final_x: np.ndarray) -> dict[str, float]:
  """How far (m) each of ``PAPER_MEASURES`` moved downhill between the first
  and the last frame's x [N] (m): distances travelled, so that relative
  errors do not depend on where the domain's origin lies."""
  def at(x, q):
    return float(np.mean(x) if q is None else np.quantile(x, q))
  return {name: at(initial_x, q) - at(final_x, q)
          for name, q in PAPER_MEASURES}


# Below this observed order an extrapolation is dominated by its last change
# (at order 0.1 the limit lies 13 changes away) and is not reported.
MIN_ORDER = 0.5


def extrapolations(rows: Sequence[dict], group: str, keys: Sequence[str],
                   default_spacing: float = dataset.PAPER_SPACING
                   ) -> list[str]:
  """A line per value of ``rows``' column ``group`` and per ``key``: the
  changes between successive rows (coarse to fine, column ``spacing_m``),
  Richardson extrapolation over the last three, and how far the row at
  ``default_spacing`` (m) and the finest row lie from it (relative)."""
  lines = []
  for value in dict.fromkeys(r[group] for r in rows):
    mine = [r for r in rows if r[group] == value]
    if len(mine) < 3:
      continue
    for key in keys:
      values = [r[key] for r in mine]
      limit, order = richardson(values)
      label = f"{value:g}" if isinstance(value, float) else value
      if not math.isfinite(limit):
        verdict = "Richardson undefined: the changes do not shrink"
      elif order < MIN_ORDER:
        verdict = (f"the changes shrink too slowly (order {order:.2f}) for "
                   "an extrapolation to mean anything")
      else:
        verdict = (f"Richardson {limit:.4g} (order {order:.2f}); the "
                   "default spacing's value is "
                   f"{_off(mine, key, limit, default_spacing)} from it, the "
                   f"finest's {_relative(values[-1], limit):.1%}")
      changes = ", ".join(f"{b - a:+.3g}" for a, b in zip(values, values[1:]))
      lines.append(f"- {group} {label}, {key} (changes {changes}): {verdict}")
  return lines


def _relative(value, limit):
  return abs(value - limit) / max(abs(limit), 1e-12)


def _off(rows, key, limit, default_spacing):
  default = [r for r in rows if r["spacing_m"] == default_spacing]
  if not default:
    return "(not run)"
  return f"{_relative(default[0][key], limit):.1%}"


def markdown_table(rows: Sequence[dict]) -> list[str]:
  """Lines of a markdown table of ``rows`` (dicts with the same keys)."""
  cols = list(rows[0])
  lines = ["| " + " | ".join(cols) + " |", "|---" * len(cols) + "|"]
  for r in rows:
    lines.append("| " + " | ".join(
        f"{r[c]:.4g}" if isinstance(r[c], float) else str(r[c])
        for c in cols) + " |")
  return lines


# ------------------------------------------------------------------ study ---

# The largest move over the last STILL_FRAMES frames tells whether the
# column's sand still moves at the end (``still_moving_m``).
STILL_FRAMES = 10
# The paper's test plan (``mpm.dataset.plan``) holds this many scenes.
PLAN_SIZE = dataset.DatasetSpec.num_test


def _coarse_to_fine(name: str, spacings: Sequence[float]) -> None:
  if any(b >= a for a, b in zip(spacings, spacings[1:])):
    raise settings.InputError(
        f"--{name}={','.join(f'{x:g}' for x in spacings)}; allowed: "
        "distinct spacings, coarse to fine (decreasing)")


@dataclasses.dataclass(frozen=True)
class Settings(settings.Base):
  """The column's shapes and spacings, and the paper scenes and theirs."""
  aspect_ratios: tuple[float, ...] = settings.field(
      (1.0,), "Column height / width values ('' for no column).", lower=0,
      strict=True, allow_empty=True)
  spacings: tuple[float, ...] = settings.field(
      (0.005, 0.0025, 0.00125), "Particle spacings (m) of the column, "
      "coarse to fine; grid spacing twice each.", lower=0, strict=True)
  cfl: float = settings.field(0.4, "CFL number of the solver.", lower=0,
                              strict=True, upper=1)
  height: float = settings.field(0.1, "Column height h0 (m).", lower=0,
                                 strict=True, upper=1)
  time: float = settings.field(0.8, "Simulated time of the column (s).",
                               lower=0, strict=True, upper=10)
  friction_angle: float = settings.field(
      FRICTION_ANGLE, "Friction angle (deg) of the column's sand (mu(I): "
      "mu_s = its sine).", lower=0, strict=True, upper=80)
  paper_scenes: tuple[int, ...] = settings.field(
      (), "Indices of test-plan scenes to measure too (600 frames each).",
      lower=0, upper=PLAN_SIZE - 1, allow_empty=True)
  paper_spacings: tuple[float, ...] = settings.field(
      (0.01, 0.005, 0.0025), "Particle spacings (m) of the paper scenes, "
      "coarse to fine.", lower=0, strict=True)
  rheologies: tuple[str, ...] = settings.field(
      ("drucker_prager",), "Rheologies of the sand, each run at every "
      "spacing (mu_i: mu(I) with its defaults, docs/physics.md).",
      choices=tuple(scene_lib.RHEOLOGIES), distinct=True)
  command: str = settings.field(
      "", "The command line that asked for the run, for the report ('': "
      "the settings are reported).", flag=False)

  def validate(self):
    if not self.aspect_ratios and not self.paper_scenes:
      raise settings.InputError(
          "--aspect_ratios is empty and so is --paper_scenes: nothing to "
          "measure; allowed: a column (--aspect_ratios) and/or paper scenes")
    frames = int(round(self.time / FRAME_TIME))
    if frames <= STILL_FRAMES:
      raise settings.InputError(
          f"--time={self.time:g}: {frames} frames of {FRAME_TIME * 1e3:g} "
          f"ms; allowed: >= {(STILL_FRAMES + 1) * FRAME_TIME:g} s (the "
          f"last {STILL_FRAMES} frames tell whether the sand still moves)")
    for rheology in self.rheologies:
      for what, angle, used in (
          ("--friction_angle", self.friction_angle, self.aspect_ratios),
          ("the paper scenes' friction angle",
           scene_lib.Material.friction_angle_deg, self.paper_scenes)):
        try:
          scene_lib.with_rheology(mpm.Scene.from_dict(
              {"material": {"friction_angle_deg": angle}}), rheology)
        except mpm.InputError as e:
          if used:
            raise settings.InputError(
                f"--rheologies={rheology} with {what} = {angle:g}: {e}"
                ) from None
    _coarse_to_fine("spacings", self.spacings)
    _coarse_to_fine("paper_spacings", self.paper_spacings)
    h, coarsest = self.height, max(self.spacings)
    for a in self.aspect_ratios:
      fit = min(h / a, h, min(column_domain(a, h)) / 8)
      if coarsest > fit:
        raise settings.InputError(
            f"--spacings={coarsest:g}: too coarse for the column of "
            f"--height={h:g} and --aspect_ratios={a:g} ({h / a:g} m wide); "
            f"allowed: <= {fit:g} m (the column one spacing wide and tall, "
            "the grid, twice the spacing, 4 cells across the domain)")
      for spacing in self.spacings:
        try:
          # The rheologies were checked above, at this friction angle.
          column_scene(a, spacing, h, self.cfl, self.time,
                       friction_angle=self.friction_angle)
        except mpm.InputError as e:
          raise settings.InputError(
              f"--aspect_ratios={a:g} with --spacings={spacing:g} and "
              f"--height={h:g}: the column's scene is refused: {e}") from None
    plan = (tradeoff.study_scenes(max(self.paper_scenes) + 1)
            if self.paper_scenes else [])
    for i in self.paper_scenes:
      for spacing in self.paper_spacings:
        try:
          tradeoff.at_spacing(plan[i], spacing)
        except mpm.InputError as e:
          raise settings.InputError(
              f"--paper_spacings={spacing:g}: scene {plan[i].name} "
              f"(--paper_scenes={i}) is refused at this spacing: {e}"
              ) from None


  def simulations(self) -> list[budget.Planned]:
    column = {"spacing": "--spacings", "num_frames": None, "dx": None,
              "scenes": None}
    plan = [budget.Planned(column_scene(a, spacing, self.height, self.cfl,
                                        self.time, friction_angle=self.
                                        friction_angle), names=column,
                           count=len(self.rheologies))
            for a in self.aspect_ratios for spacing in self.spacings]
    paper = {**column, "spacing": "--paper_spacings"}
    scenes = (tradeoff.study_scenes(max(self.paper_scenes) + 1)
              if self.paper_scenes else [])
    return plan + [budget.Planned(tradeoff.at_spacing(scenes[i], spacing),
                                  names=paper, count=len(self.rheologies))
                   for i in self.paper_scenes
                   for spacing in self.paper_spacings]


def _per_rheology(rows, group, keys) -> list[str]:
  """``extrapolations`` within each rheology of ``rows`` (rows without the
  column, from before it: Drucker-Prager)."""
  lines = []
  for rheology in dict.fromkeys(r.get("rheology", "drucker_prager")
                                for r in rows):
    mine = [r for r in rows
            if r.get("rheology", "drucker_prager") == rheology]
    lines += [f"- {rheology}, " + line[2:]
              for line in extrapolations(mine, group, keys)]
  return lines


def report(summary: dict[str, Any]) -> str:
  """The Markdown report of a :func:`run`'s summary: how it was run, the
  tables and the extrapolations."""
  env = summary["environment"]
  asked = (f"`{env['command']}`" if env.get("command") else
           f"Settings: `{json.dumps(env['settings'])}`")
  lines = [asked, "",
           f"Machine: {env['platform']}, {env['cpu_count']} CPUs, jax "
           f"{env['jax_version']} ({env['jax_backend']}); load average "
           f"{env['load_average_start'][0]:.2f} at the start, "
           f"{env['load_average_end'][0]:.2f} at the end; {env['date']}.",
           "", "## Column collapse", ""]
  column_rows, paper_rows = summary["column"], summary["paper"]
  if column_rows:
    lines += markdown_table(column_rows) + [""]
    lines += _per_rheology(column_rows, "aspect_ratio",
                           [name for name, _ in MEASURES])
  if paper_rows:
    lines += ["", "## Paper scenes", ""]
    lines += markdown_table(paper_rows) + [""]
    lines += _per_rheology(paper_rows, "scene",
                           [name for name, _ in PAPER_MEASURES])
  return "\n".join(lines) + "\n"


def run(s: Settings, out_dir: str) -> dict[str, Any]:
  """Runs the column at every aspect ratio and spacing, then the paper
  scenes at theirs; writes the tables as they grow, then the figure, the
  report and the environment into ``out_dir``.

  Returns:
    ``column`` and ``paper`` (the rows of ``convergence.csv`` and
    ``convergence_paper.csv``) and ``environment`` (``timing.environment``
    with the command and the settings).
  """
  plan = (tradeoff.study_scenes(max(s.paper_scenes) + 1)
          if s.paper_scenes else [])
  os.makedirs(out_dir, exist_ok=True)
  env = timing.environment(quick=False, command=s.command,
                           settings=s.to_dict())
  column_rows, paper_rows = [], []
  # Panel title -> (scene, [(spacing, final positions [N, 2])]).
  deposits = {}

  def simulate(scene, key, spacing):
    """Positions [T, N, 2] (m) of ``scene`` and the seconds the call
    took; its final deposit goes into panel ``key``."""
    x, wall = timing.wall(lambda: np.asarray(mpm.simulate(scene).positions))
    deposits.setdefault(key, (scene, []))[1].append((spacing, x[-1]))
    return x, round(wall, 1)

  def save():
    mpm_io.write_csv(os.path.join(out_dir, "convergence.csv"), column_rows)
    mpm_io.write_csv(os.path.join(out_dir, "convergence_paper.csv"),
                     paper_rows)

  for aspect, rheology in itertools.product(s.aspect_ratios, s.rheologies):
    for spacing in tqdm.tqdm(s.spacings, desc=f"a = {aspect:g} {rheology}",
                             unit="run"):
      scene = column_scene(aspect, spacing, s.height, s.cfl, s.time,
                           rheology, s.friction_angle)
      x, wall = simulate(scene, f"column, a = {aspect:g}, {rheology}",
                         spacing)
      column_rows.append({
          "aspect_ratio": aspect, "rheology": rheology,
          "spacing_m": spacing, "dx_m": scene.dx,
          "particles": x.shape[1],
          **runouts(x[-1, :, 0], s.height / aspect),
          "still_moving_m": float(
              np.abs(x[-1] - x[-1 - STILL_FRAMES]).max()),
          "wall_time_s": wall})
      save()
  for index, rheology in itertools.product(s.paper_scenes, s.rheologies):
    for spacing in tqdm.tqdm(s.paper_spacings,
                             desc=f"{plan[index].name} {rheology}",
                             unit="run"):
      scene = scene_lib.with_rheology(
          tradeoff.at_spacing(plan[index], spacing), rheology)
      x, wall = simulate(scene, f"{plan[index].name}, {rheology}", spacing)
      paper_rows.append({"scene": plan[index].name, "rheology": rheology,
                         "spacing_m": spacing,
                         "dx_m": scene.dx, "particles": x.shape[1],
                         **paper_measures(x[0, :, 0], x[-1, :, 0]),
                         "wall_time_s": wall})
      save()

  if deposits:
    figures.resolution_deposits(
        [(title, scene, runs) for title, (scene, runs) in deposits.items()],
        os.path.join(out_dir, "deposits.png"))
  timing.end_environment(env)
  summary = {"column": column_rows, "paper": paper_rows, "environment": env}
  mpm_io.write_text(os.path.join(out_dir, "convergence.md"), report(summary))
  mpm_io.write_json(os.path.join(out_dir, "environment.json"), env)
  return summary
