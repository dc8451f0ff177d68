"""Inverse design: an obstacle's placement by gradients through GNS and MPM.

Layered on the public APIs of ``gnsjax`` and ``mpm``:

- ``placement``: ``Placement``, the designed obstacle of a scene, its free
  parameters (x, size) and their allowed ranges; ``MultiPlacement``,
  several obstacles at once (MPM only), kept apart by its projection.
- ``objectives``: avalanche objectives of a rollout [T, N, 2], each a smooth
  surrogate to differentiate beside its plain value.
- ``rollouts``: both simulators as pure, differentiable functions of the
  placement (``GNSRollout``, ``MPMRollout``: frozen pytrees whose settings
  are static), and their host drivers (``GNSDriver``, ``MPMDriver``;
  ``gns_driver`` loads a trained model's).
- ``optimize``: projected Adam, the brute-force sweep, central differences.
- ``smoothing``: gradients of the objective smoothed in the parameters at a
  user-set scale sigma (pathwise and score-function estimators, batched).
- ``baselines``: random search, grid sweep and CMA-ES under a budget, on
  the batched MPM.
- ``scenes``: the problems' scenes (the paper's heap with one obstacle, two
  semicircles, a row of baffles).
- ``calibration``: the sand's friction angle and the basal friction from an
  observed final deposit (imported on its own).

The studies built on these (optimise and verify, methods at equal budget,
the gradient check, the calibration) are in ``experiments.studies``; this
package imports neither ``gnsjax.train`` nor matplotlib.

The names most callers need are re-exported here::

  from gnsjax import design
  placement = design.Placement(scene)
  sim = design.MPMDriver(design.MPMRollout.create(placement))
  obj = design.objectives.make("passed_fraction", x_protect=0.4)
  value, grad, positions = sim.value_and_grad(obj.smooth, placement.initial())
"""

from gnsjax.design import objectives
from gnsjax.design import smoothing
from gnsjax.design.optimize import central_difference
from gnsjax.design.optimize import optimise
from gnsjax.design.optimize import sweep
from gnsjax.design.placement import MultiPlacement
from gnsjax.design.placement import Params
from gnsjax.design.placement import Placement
from gnsjax.design.placement import X_RANGE
from gnsjax.design.placement import with_obstacle
from gnsjax.design.rollouts import GNSDriver
from gnsjax.design.rollouts import GNSRollout
from gnsjax.design.rollouts import MPMDriver
from gnsjax.design.rollouts import MPMRollout
from gnsjax.design.rollouts import gns_positions
from gnsjax.design.rollouts import mpm_positions
from gnsjax.design.rollouts import mpm_window

__all__ = [
    "GNSDriver", "GNSRollout", "MPMDriver", "MPMRollout", "MultiPlacement",
    "Params",
    "Placement", "X_RANGE", "central_difference", "gns_positions",
    "mpm_positions", "mpm_window", "objectives", "optimise", "sweep",
    "with_obstacle",
]
