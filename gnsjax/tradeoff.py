"""Which simulator to use: the speed/accuracy table of the Pareto study.

``python -m experiments.tradeoff`` measures every configuration (the MPM at
several resolutions, learned simulators) on the same held-out scenes against
the finest MPM and writes the table as JSON. This module reads such a table
and answers a user's question from it::

  from gnsjax import tradeoff
  table = tradeoff.load("docs/results/tradeoff/tradeoff.json")
  choice = tradeoff.cheapest(table, tolerance=0.1, scene=my_scene)
  choice.point["name"], choice.seconds, choice.error

The table (``tradeoff.json``):

- ``points``: one per configuration: ``name``, ``kind`` ("mpm" or "gns"),
  ``label``, ``seconds`` (median wall time per trajectory, one scene at a
  time, compilation excluded), ``seconds_batched`` (per trajectory when the
  study's scenes run as one vmapped batch, or None), ``compile_s``,
  ``training_s`` (a learned simulator's one-time training cost, or None).
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
from typing import Any, Mapping, NamedTuple, Sequence

from mpm import scene as scene_lib

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


def pareto_front(costs: Sequence[float], errors: Sequence[float]
                 ) -> list[bool]:
  """Whether each point is on the Pareto front: no other point is at most
  as costly and at most as wrong, and better in one of the two."""
  front = []
  for i, (c, e) in enumerate(zip(costs, errors)):
    dominated = any(
        c2 <= c and e2 <= e and (c2 < c or e2 < e)
        for j, (c2, e2) in enumerate(zip(costs, errors)) if j != i)
    front.append(not dominated and math.isfinite(c) and math.isfinite(e))
  return front


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
  """
  if not (isinstance(tolerance, (int, float)) and tolerance > 0
          and math.isfinite(tolerance)):
    raise scene_lib.InputError(f"tolerance {tolerance!r}; allowed: a finite "
                               "number > 0")
  names = matching_scenes(table, scene)
  errors = point_errors(table, metric, names)
  key = "seconds_batched" if batched else "seconds"
  candidates = [p for p in table["points"]
                if p.get(key) is not None and p["name"] in errors]
  meeting = [p for p in candidates if errors[p["name"]] <= tolerance]
  if not meeting:
    best = min(candidates, key=lambda p: errors[p["name"]])
    raise scene_lib.InputError(
        f"no configuration meets {metric} <= {tolerance:g} on "
        f"{len(names)} matching study scene(s); the most accurate, "
        f"{best['name']}, reaches {errors[best['name']]:.3g}")
  pick = min(meeting, key=lambda p: p[key])
  return Choice(pick, errors[pick["name"]], pick[key], names)
