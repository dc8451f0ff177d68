"""The MPM against laboratory granular flows, both rheologies side by side
(``python -m experiments.validation``).

Two benchmarks, each a table and a plot:

* **Column collapse.** The column of ``experiments.studies.convergence``
  (height h0, width L0 = h0 / a, a frictionless wall behind it) at aspect
  ratios ``aspect_ratios``. Measured: the runout (L - L0) / L0 from the
  99.5% quantile of x, the final height h / L0, and the deposit's flank
  angle at its steepest fitted tenth of the height. Against:

  - Lube et al. (2005, 2D columns): (L - L0) / L0 = 1.2 a +- 20% for
    a <= 1 (the band 0.96-1.44 at a = 1);
  - the exponent of the runout over the tall columns (a >= 2): 2/3 in the
    2D experiments of Lube et al. (2005) and Lajeunesse et al. (2005),
    0.65 +- 0.05 in the narrow slots of Balmforth & Kerswell (2005);
  - the exponent of h0 / h over the tall columns: 0.5 in Balmforth &
    Kerswell's narrow slots (0.6 in their wide channels).

* **Steady flow down a rough incline** (``mpm.incline``): a periodic strip
  ``incline_depth`` deep tilted by ``incline_angles``; under mu(I) its
  surface speed against the Bagnold profile's. Drucker-Prager has no steady
  flow on a slope steeper than its friction (the layer accelerates): its row
  reports the speed at the end and whether it was still growing.

``run`` writes ``validation.md``, ``column.csv``, ``incline.csv``,
``column.png``, ``incline.png`` and ``environment.json``.
"""

import dataclasses
import json
import math
import os
from typing import Any

import numpy as np
import tqdm

import mpm
from experiments import figures
from experiments import timing
from experiments.studies import convergence
from experiments.studies import settings
from mpm import budget
from mpm import incline
from mpm import io as mpm_io
from mpm import scene as scene_lib

LUBE_SLOPE, LUBE_BAND = 1.2, 0.2    # (L - L0) / L0 = 1.2 a +- 20%, a <= 1
TALL = 2.0                          # the tall columns' regime: a >= 2
RUNOUT_EXPONENT = 2 / 3             # tall columns (Lube; Lajeunesse)
HEIGHT_EXPONENT = 0.5               # h0 / h ~ a^0.5 (B&K, narrow slots)
# The incline's surface speed: the mean of the top tenth of the layer,
# against the Bagnold profile's mean over the same tenth.
SURFACE = 0.9


@dataclasses.dataclass(frozen=True)
class Settings(settings.Base):
  """The columns and the incline, and at what resolution each runs."""
  aspect_ratios: tuple[float, ...] = settings.field(
      (0.5, 1.0, 2.0, 4.0, 8.0), "Column height / width values ('' for "
      "none).", lower=0, strict=True, allow_empty=True)
  spacing: float = settings.field(
      0.0025, "Particle spacing of the columns (m); grid twice it.",
      lower=0, strict=True)
  height: float = settings.field(0.1, "Column height h0 (m).", lower=0,
                                 strict=True, upper=1)
  time: float = settings.field(1.0, "Simulated time of each column (s).",
                               lower=0, strict=True, upper=10)
  incline_angles: tuple[float, ...] = settings.field(
      (32.0, 34.0, 36.0), "Incline angles (deg) ('' for none).", lower=0,
      strict=True, upper=90, allow_empty=True)
  incline_depth: float = settings.field(0.02, "Layer depth (m).", lower=0,
                                        strict=True, upper=0.5)
  incline_dx: float = settings.field(0.001, "Grid spacing of the incline "
                                     "(m).", lower=0, strict=True)
  incline_time: float = settings.field(
      3.0, "Simulated time of each incline (s): steady by 2.5 s at 34 deg "
      "and 1 mm, its particles' arrangement degrading after 3.5 s "
      "(docs/physics.md).", lower=0, strict=True, upper=60)
  grain_diameter: float = settings.field(
      0.002, "mu(I)'s grain diameter d (m) on the incline: the Bagnold "
      "speed scales as 1/d, its shape does not.", lower=0, strict=True,
      upper=0.1)
  rheologies: tuple[str, ...] = settings.field(
      ("drucker_prager", "mu_i"), "Rheologies, each run on every case "
      "(not mu_i_regularized: these sands have no well-posed range for it, "
      "docs/physics.md section 12).",
      choices=("drucker_prager", "mu_i"), distinct=True)
  command: str = settings.field(
      "", "The command line that asked for the run, for the report.",
      flag=False)

  def validate(self):
    if not self.aspect_ratios and not self.incline_angles:
      raise settings.InputError(
          "--aspect_ratios and --incline_angles are both empty: nothing to "
          "run; allowed: a column and/or an incline")
    for a in self.aspect_ratios:
      try:
        self.column(a, "drucker_prager")
      except mpm.InputError as e:
        raise settings.InputError(
            f"--aspect_ratios={a:g} with --spacing={self.spacing:g} and "
            f"--height={self.height:g}: the column is refused: {e}") from None
    if self.incline_angles:
      try:
        self.strip("drucker_prager")
      except (mpm.InputError, ValueError) as e:
        raise settings.InputError(
            f"--incline_depth={self.incline_depth:g} with --incline_dx="
            f"{self.incline_dx:g}: the strip is refused: {e}") from None

  def column(self, aspect: float, rheology: str) -> mpm.Scene:
    return convergence.column_scene(aspect, self.spacing, self.height,
                                    duration=self.time, rheology=rheology)

  def strip(self, rheology: str) -> mpm.Scene:
    material = ({} if rheology == "drucker_prager" else
                {"rheology": rheology, "grain_diameter": self.grain_diameter})
    return incline.strip_scene(self.incline_depth, dx=self.incline_dx,
                               material=material)

  def simulations(self) -> list[budget.Planned]:
    names = {"spacing": "--spacing", "num_frames": "--time", "dx": None,
             "scenes": None}
    return [budget.Planned(self.column(a, "drucker_prager"), names=names,
                           count=len(self.rheologies))
            for a in self.aspect_ratios]


def deposit_surface(x: np.ndarray, spacing: float
                    ) -> tuple[np.ndarray, np.ndarray]:
  """The surface of a deposit x [N, 2] (m): bin centres along x and the
  highest particle above the floor in each bin 2 ``spacing`` wide (m; NaN
  in an empty bin)."""
  bins = np.floor(x[:, 0] / (2 * spacing)).astype(int)
  surface = np.full(bins.max() + 1, np.nan)
  np.fmax.at(surface, bins, x[:, 1] - convergence.FLOOR)
  return (np.arange(len(surface)) + 0.5) * 2 * spacing, surface


def column_measures(x: np.ndarray, aspect: float, height: float,
                    spacing: float) -> dict[str, float]:
  """Runout, final height and flank angle of a final deposit x [N, 2] (m)
  of a column of ``height`` h0 (m) and aspect ratio ``aspect``."""
  width0 = height / aspect
  centres, surface = deposit_surface(x, spacing)
  top = float(np.nanmax(surface))
  # The flank: where the surface lies between 20% and 80% of the top,
  # beyond its highest point.
  flank = (surface > 0.2 * top) & (surface < 0.8 * top) & (
      centres > centres[np.nanargmax(surface)])
  angle = (math.degrees(math.atan(-np.polyfit(
      centres[flank], surface[flank], 1)[0])) if flank.sum() >= 3
           else math.nan)
  return {"runout": float(np.quantile(x[:, 0], 0.995) - width0) / width0,
          "height_over_L0": top / width0, "h0_over_h": height / top,
          "flank_angle_deg": angle}


def exponent(aspects, values) -> float:
  """The least-squares power of ``values`` in ``aspects`` over a >= TALL;
  nan with fewer than two such columns."""
  a = np.asarray(aspects, float)
  v = np.asarray(values, float)
  tall = a >= TALL
  if tall.sum() < 2:
    return math.nan
  return float(np.polyfit(np.log(a[tall]), np.log(v[tall]), 1)[0])


def bagnold_surface(depth: float, theta: float,
                    material: scene_lib.Material) -> float:
  """The Bagnold profile's mean speed over the top (1 - SURFACE) of the
  layer (m/s): what ``incline.run`` measures."""
  z = np.linspace(SURFACE * depth, depth, 201)
  return float(np.mean(incline.bagnold_velocity(z, depth, theta, material)))


def _column_rows(s: Settings, deposits: dict) -> list[dict]:
  rows = []
  for rheology in s.rheologies:
    for aspect in tqdm.tqdm(s.aspect_ratios, desc=f"columns, {rheology}",
                            unit="run"):
      scene = s.column(aspect, rheology)
      result = mpm.simulate(scene)
      x = np.asarray(result.positions)
      centres, surface = deposit_surface(x[-1], s.spacing)
      width0 = s.height / aspect
      deposits.setdefault(rheology, []).append(
          (aspect, centres / width0, surface / width0))
      row = {"rheology": rheology, "aspect_ratio": aspect,
             **column_measures(x[-1], aspect, s.height, s.spacing),
             "still_moving_m": float(np.abs(x[-1] - x[-11]).max()),
             "wall_time_s": round(result.wall_time_s, 2)}
      if aspect <= 1:
        low, high = (LUBE_SLOPE * aspect * (1 - LUBE_BAND),
                     LUBE_SLOPE * aspect * (1 + LUBE_BAND))
        row["lube_band"] = f"{low:.2f}-{high:.2f}"
        row["in_band"] = bool(low <= row["runout"] <= high)
      rows.append(row)
  return rows


def _incline_rows(s: Settings, profiles: dict) -> list[dict]:
  rows = []
  for rheology in s.rheologies:
    scene = s.strip(rheology)
    for angle in tqdm.tqdm(s.incline_angles, desc=f"incline, {rheology}",
                           unit="run"):
      strip = incline.periodic_setup(scene, angle)
      times, speeds, final = incline.run(strip, s.incline_time)
      z = np.asarray(final.x[:strip.setup.n_particles, 1]) - incline.FLOOR
      u = np.asarray(final.v[:strip.setup.n_particles, 0])
      half = len(speeds) // 2
      row = {"rheology": rheology, "theta_deg": angle,
             "surface_speed": float(speeds[-1]),
             "growth_last_quarter": float(
                 speeds[-1] / speeds[-1 - max(1, len(speeds) // 4)] - 1),
             "speed_at_half_time": float(speeds[half])}
      m = scene.material
      if rheology == "mu_i":
        i = incline.inertial_number(strip.theta, m)
        row["inertial_number"] = i
        if not math.isnan(i):
          expected = bagnold_surface(strip.depth, strip.theta, m)
          row["bagnold_surface_speed"] = expected
          row["ratio"] = row["surface_speed"] / expected
      rows.append(row)
      profiles[(rheology, angle)] = (z, u, strip, times, speeds)
  return rows


def _table(rows, keys) -> list[str]:
  def cell(v):
    if isinstance(v, float):
      return "nan" if math.isnan(v) else f"{v:.3g}"
    return str(v)
  return (["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)] +
          ["| " + " | ".join(cell(r.get(k, "")) for k in keys) + " |"
           for r in rows])


def report(summary: dict[str, Any]) -> str:
  """The Markdown report of ``run``'s summary."""
  env = summary["environment"]
  asked = (f"`{env['command']}`" if env.get("command") else
           f"Settings: `{json.dumps(env['settings'])}`")
  lines = [asked, "",
           f"Machine: {env['platform']}, {env['cpu_count']} CPUs, jax "
           f"{env['jax_version']} ({env['jax_backend']}); load average "
           f"{env['load_average_start'][0]:.2f} at the start, "
           f"{env['load_average_end'][0]:.2f} at the end; {env['date']}."]
  column = summary["column"]
  if column:
    lines += ["", "## Column collapse", "",
              "Runout (L - L0) / L0 from the 99.5% quantile of x; Lube et "
              "al. (2005): 1.2 a +- 20% for a <= 1.", ""]
    lines += _table(column, ["rheology", "aspect_ratio", "runout",
                             "lube_band", "in_band", "height_over_L0",
                             "h0_over_h", "flank_angle_deg",
                             "still_moving_m", "wall_time_s"])
    lines += ["", f"Exponents over a >= {TALL:g} (2D experiments: runout "
              f"2/3, Lube et al. 2005 and Lajeunesse et al. 2005; "
              f"0.65 +- 0.05 and h0 / h ~ a^0.5, Balmforth & Kerswell "
              f"2005, narrow slots):", ""]
    for rheology, ex in summary["exponents"].items():
      lines.append(f"- {rheology}: runout a^{ex['runout']:.2f}, h0 / h "
                   f"a^{ex['h0_over_h']:.2f}")
  if summary["incline"]:
    lines += ["", "## Steady flow down a rough incline", "",
              "Surface speed: mean downslope speed of the top tenth of the "
              "layer at the end (m/s); Bagnold: the analytic profile's "
              "mean over the same tenth.", ""]
    lines += _table(summary["incline"], [
        "rheology", "theta_deg", "inertial_number", "surface_speed",
        "bagnold_surface_speed", "ratio", "speed_at_half_time",
        "growth_last_quarter"])
  return "\n".join(lines) + "\n"


def run(s: Settings, out_dir: str) -> dict[str, Any]:
  """Runs the columns and the inclines of ``s`` under every rheology and
  writes the tables, the plots and the report into ``out_dir``."""
  os.makedirs(out_dir, exist_ok=True)
  env = timing.environment(quick=False, command=s.command,
                           settings=s.to_dict())
  deposits, profiles = {}, {}
  column = _column_rows(s, deposits)
  mpm_io.write_csv(os.path.join(out_dir, "column.csv"), column)
  slopes = {r: {key: exponent(
      [row["aspect_ratio"] for row in column if row["rheology"] == r],
      [row[key] for row in column if row["rheology"] == r])
                for key in ("runout", "h0_over_h")} for r in s.rheologies}
  slope_rows = _incline_rows(s, profiles)
  mpm_io.write_csv(os.path.join(out_dir, "incline.csv"), slope_rows)
  if column:
    figures.column_validation(column, deposits, os.path.join(
        out_dir, "column.png"), LUBE_SLOPE, LUBE_BAND, RUNOUT_EXPONENT,
        HEIGHT_EXPONENT)
  if slope_rows:
    figures.incline_profiles(profiles, os.path.join(out_dir, "incline.png"))
  timing.end_environment(env)
  summary = {"column": column, "exponents": slopes, "incline": slope_rows,
             "environment": env}
  mpm_io.write_text(os.path.join(out_dir, "validation.md"), report(summary))
  mpm_io.write_json(os.path.join(out_dir, "environment.json"), env)
  return summary
