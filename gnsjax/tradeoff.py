"""Which simulator to use: the speed/accuracy table of the Pareto study.

``python -m experiments.tradeoff`` measures every configuration (the MPM at
several resolutions, learned simulators) on the same held-out scenes against
the finest MPM and writes the table as JSON. This module reads such a table
and answers a user's question from it::

  from gnsjax import tradeoff
  table = tradeoff.load("docs/results/tradeoff/tradeoff.json")
  choice = tradeoff.cheapest(table, tolerance=0.1, scene=my_scene)
  choice.point["name"], choice.seconds, choice.error

The table's format and the questions it answers live in ``mpm.resolution``
(the MPM asks the same of its own rows: ``mpm.simulate(scene,
front_tolerance=...)``); this module adds the Pareto front.
"""

import math
from typing import Sequence

from mpm.resolution import (METRICS, Choice, cheapest, load,
                            matching_scenes, point_errors)

__all__ = ["METRICS", "Choice", "cheapest", "load", "matching_scenes",
           "point_errors", "pareto_front"]


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
