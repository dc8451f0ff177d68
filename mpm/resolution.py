"""A front tolerance instead of a spacing: the particle spacing a scene needs.

The speed/accuracy study (``python -m experiments.tradeoff``,
docs/tradeoff.md) measured the MPM at several particle spacings on held-out
paper scenes against the finest spacing, and the learned simulators beside
it. Its table (``tradeoff.json``) answers "which configuration meets this
error, cheapest" (:func:`cheapest`); ``mpm.simulate(scene,
front_tolerance=...)`` asks it of the MPM's own rows, which ship with the
package (``front_errors.json``: the study's MPM points and rows, written
by :func:`mpm_table`), and runs the scene at the spacing it picks
(:func:`choose`, :func:`at_spacing`).

The table:

- ``points``: one per configuration: ``name``, ``kind`` ("mpm" or "gns"),
  ``label``, ``spacing`` (the MPM's particle spacing, m), ``seconds``
  (median wall time per trajectory, one scene at a time, compilation
  excluded), ``seconds_batched`` (per trajectory when the study's scenes run
  as one vmapped batch, or None), ``compile_s``, ``training_s`` (a learned
  simulator's one-time training cost, or None).
- ``rows``: one per (configuration, scene): ``point``, ``scene``,
  ``obstacles`` (count), ``shapes`` (sorted obstacle shapes), ``particles``
  and the errors against the reference, ``front_error`` (|front - front_ref|
  at the last compared frame over the reference's runout distance, a
  fraction), ``deposit_error`` (RMS of the final deposit height profile, m),
  ``past_error`` (largest mean absolute difference over time of the
  fraction of sand past fixed lines), ``inside`` (largest fraction of sand
  inside solids over time).

Errors are measured, not modelled: a scene unlike every study scene gets the
configurations' worst error over all of them.
"""

import json
import math
import os
from typing import Any, Mapping, NamedTuple, Sequence

from mpm import scene as scene_lib

# The MPM's rows of the committed study (docs/results/tradeoff), shipped.
FRONT_TABLE = os.path.join(os.path.dirname(__file__), "front_errors.json")

METRICS = ("front_error", "deposit_error", "past_error", "inside")


class Choice(NamedTuple):
  """What :func:`cheapest` picked.

  Attributes:
    point: the configuration's entry of the table's ``points``.
    error: its largest error (the asked metric) over the study scenes that
      match the scene.
    seconds: its wall time per trajectory (s).
    scenes: the names of the study scenes the error is taken over.
  """
  point: dict[str, Any]
  error: float
  seconds: float
  scenes: tuple[str, ...]


def load(path: str) -> dict[str, Any]:
  """A table written by ``experiments.tradeoff``."""
  with open(path) as f:
    table = json.load(f)
  for key in ("points", "rows"):
    if key not in table:
      raise ValueError(f"{path}: not a trade-off table (no {key!r})")
  return table


def _signature(obstacles: int, shapes: Sequence[str]) -> tuple:
  return obstacles, tuple(sorted(shapes))


def matching_scenes(table: Mapping[str, Any],
                    scene: scene_lib.Scene | None) -> tuple[str, ...]:
  """The study scenes with ``scene``'s obstacle count and shapes; all of
  them if ``scene`` is None or none matches."""
  names = sorted({r["scene"] for r in table["rows"]})
  if scene is None:
    return tuple(names)
  want = _signature(len(scene.obstacles), [o.shape for o in scene.obstacles])
  same = sorted({r["scene"] for r in table["rows"]
                 if _signature(r["obstacles"], r["shapes"]) == want})
  return tuple(same or names)


def point_errors(table: Mapping[str, Any], metric: str = "front_error",
                 scenes: Sequence[str] | None = None) -> dict[str, float]:
  """Each configuration's largest ``metric`` over ``scenes`` (default all);
  NaN (a broken run) counts as infinitely wrong."""
  if metric not in METRICS:
    raise scene_lib.InputError(f"metric {metric!r}; allowed: "
                               f"{', '.join(METRICS)}")
  worst = {}
  for r in table["rows"]:
    if scenes is not None and r["scene"] not in scenes:
      continue
    value = r[metric]
    value = math.inf if value is None or math.isnan(value) else value
    worst[r["point"]] = max(worst.get(r["point"], -math.inf), value)
  return worst


def cheapest(table: Mapping[str, Any], tolerance: float,
             scene: scene_lib.Scene | None = None,
             metric: str = "front_error", batched: bool = False) -> Choice:
  """The fastest configuration whose measured error meets ``tolerance``.

  Args:
    table: from :func:`load`.
    tolerance: the largest acceptable error, in the metric's unit (a
      fraction of the runout distance for ``front_error``).
    scene: the user's scene; errors are taken over the study scenes with its
      obstacle count and shapes (all of them if none matches).
    metric: one of ``METRICS``.
    batched: rank by the per-trajectory time of a batch of scenes (for a user
      who runs many); configurations without a batched time are left out.

  Raises:
    InputError: bad tolerance or metric, or no configuration meets the
      tolerance (the message names the most accurate one and its error).
      The table's reference is never a candidate.
  """
  if not (isinstance(tolerance, (int, float)) and tolerance > 0
          and math.isfinite(tolerance)):
    raise scene_lib.InputError(f"tolerance {tolerance!r}; allowed: a finite "
                               "number > 0")
  names = matching_scenes(table, scene)
  errors = point_errors(table, metric, names)
  key = "seconds_batched" if batched else "seconds"
  # The reference's errors are against itself (zero): not a measurement.
  reference = table.get("reference", {}).get("name")
  candidates = [p for p in table["points"]
                if p.get(key) is not None and p["name"] in errors
                and p["name"] != reference]
  meeting = [p for p in candidates if errors[p["name"]] <= tolerance]
  if not meeting:
    best = min(candidates, key=lambda p: errors[p["name"]])
    raise scene_lib.InputError(
        f"no configuration meets {metric} <= {tolerance:g} on "
        f"{len(names)} matching study scene(s); the most accurate, "
        f"{best['name']}, reaches {errors[best['name']]:.3g}")
  pick = min(meeting, key=lambda p: p[key])
  return Choice(pick, errors[pick["name"]], pick[key], names)


def at_spacing(scene: scene_lib.Scene, spacing: float) -> scene_lib.Scene:
  """``scene`` at another particle spacing: the same sand area (particle
  count scaled by (old / new)^2), grid spacing twice the particle spacing
  (the study's rule)."""
  d = scene.to_dict()
  old = scene.granular.spacing
  d["granular"]["spacing"] = spacing
  d["granular"]["num_particles"] = max(1, int(round(
      scene.granular.num_particles * (old / spacing)**2)))
  d["solver"]["dx"] = 2 * spacing
  return scene_lib.Scene.from_dict(d)


def mpm_table(table: Mapping[str, Any]) -> dict[str, Any]:
  """The MPM's points and rows of a study table, and where they came from
  (what ``front_errors.json`` holds). The reference spacing is left out:
  its error is zero by definition, not measured."""
  reference = table.get("reference", {}).get("name")
  names = {p["name"] for p in table["points"]
           if p["kind"] == "mpm" and p["name"] != reference}
  return {"points": [p for p in table["points"] if p["name"] in names],
          "rows": [r for r in table["rows"] if r["point"] in names],
          **{k: table[k] for k in ("reference", "command", "environment")
             if k in table}}


class Resolution(NamedTuple):
  """The spacing :func:`choose` picked for a front tolerance, and why.

  Attributes:
    spacing: particle spacing (m); the grid's is twice it.
    choice: the table's answer (its point, worst error and seconds).
    reason: one sentence a user can read.
  """
  spacing: float
  choice: Choice
  reason: str


def choose(scene: scene_lib.Scene, front_tolerance: float,
           table: Mapping[str, Any] | None = None) -> Resolution:
  """The cheapest measured MPM spacing whose worst front error, on the
  study scenes with ``scene``'s obstacles, is at most ``front_tolerance``
  (a fraction of the runout distance).

  Args:
    table: a study table (default: the shipped ``FRONT_TABLE``).

  Raises:
    InputError: a bad tolerance, or one no measured spacing meets (the
      message names the smallest tolerance the table meets).
  """
  table = mpm_table(load(FRONT_TABLE) if table is None else table)
  try:
    choice = cheapest(table, front_tolerance, scene)
  except scene_lib.InputError as e:
    raise scene_lib.InputError(f"front_tolerance = {front_tolerance!r}: "
                               f"{e}") from None
  spacing = float(choice.point["spacing"])
  want = _signature(len(scene.obstacles), [o.shape for o in scene.obstacles])
  alike = any(_signature(r["obstacles"], r["shapes"]) == want
              for r in table["rows"])
  over = (f"{len(choice.scenes)} study scene(s) with these obstacles"
          if alike else f"all {len(choice.scenes)} study scenes (none has "
          "these obstacles)")
  reason = (
      f"particle spacing {spacing * 1e3:g} mm (grid {2 * spacing * 1e3:g} "
      f"mm): the cheapest measured spacing whose worst front error, "
      f"{choice.error:.1%} of the runout over {over}, is within "
      f"{front_tolerance:.1%} ({choice.seconds:.2f} s per trajectory on the "
      "study's machine)")
  return Resolution(spacing, choice, reason)
