"""Weight averaging of trained runs: a "model soup" (Wortsman et al., 2022).

Runs that share an architecture, data and statistics, typically a model and
its fine-tunings from it, often sit in one basin of the loss, and the
weighted mean of their parameters can be more accurate than any of them.
On the small config the shipped model is the equal mean of the step-21500
model and its 6-step pushforward fine-tuning: 4.3e-3 m^2 over whole test
rollouts against 6.4e-3 for either (``docs/gns.md``).

``average_params`` is the arithmetic; ``write_average`` makes a run
directory of it (its sources: run directories, each at its latest
checkpoint, or ``DIR@STEP`` for one kept checkpoint, so that one run's
late checkpoints average into one model) that everything loading a run
accepts (``load_run``, evaluation, rollouts, ``config.train.init_from``,
and resuming training, which continues the last run's optimiser). Its
``averaged.json`` names the sources and weights.

A fine-tuning may add a velocity gate (``config.model.velocity_gate``) to
its parent, so runs with and without one average: the network they share
over all of them, the gate's head over the runs that have it (their
weights rescaled to sum to 1). A gated run then comes last, since the
average keeps the last run's config.
"""

import math
import os
from typing import Any, Mapping, Sequence

import jax
import numpy as np
import orbax.checkpoint as ocp

from gnsjax import checkpoint
from gnsjax import run as run_lib
from mpm import io as mpm_io
from mpm import scene as mpm_scene

InputError = mpm_scene.InputError

# The record of what an averaged run was made from, in its work directory.
RECORD = "averaged.json"


def check_weights(weights: Sequence[float], count: int) -> list[float]:
  """The weights as floats; InputError unless there are ``count`` of them,
  none negative, summing to 1 (within 1e-6)."""
  weights = [float(w) for w in weights]
  if len(weights) != count:
    raise InputError(f"{len(weights)} weights for {count} runs; give one "
                     "weight per run")
  if not all(math.isfinite(w) and w >= 0 for w in weights):
    raise InputError(f"weights must be finite and >= 0; got {weights}")
  if abs(sum(weights) - 1.0) > 1e-6:
    raise InputError(f"weights must sum to 1; got {weights} (sum "
                     f"{sum(weights):.6g})")
  return weights


def check_compatible(runs: Sequence[run_lib.Run], names: Sequence[str]
                     ) -> None:
  """InputError unless every run has the first one's model settings, data
  and training physics, and normalisation statistics (parameters of other
  shapes or meanings cannot be averaged). Their training noise may differ:
  the average keeps the last run's, as it keeps its optimiser."""
  first = runs[0]
  model = run_lib.model_config_dict(first.config.model)
  last = run_lib.model_config_dict(runs[-1].config.model)
  for run, name in zip(runs[1:], names[1:]):
    other = run_lib.model_config_dict(run.config.model)
    for key in sorted(set(model) | set(other)):
      if key in run_lib.ADDED_HEADS:
        continue
      if model.get(key) != other.get(key):
        raise InputError(f"{name}: model.{key} is {other.get(key)!r}, "
                         f"{names[0]} has {model.get(key)!r}; only runs of "
                         "one architecture can be averaged")
    for where, a, b in run_lib.physics_differences(first.config.to_dict(),
                                                   run.config.to_dict()):
      raise InputError(f"{name}: {where} is {b!r}, {names[0]} has {a!r}; "
                       "only runs of one problem can be averaged")
    if _inference_problem(run) != _inference_problem(first):
      raise InputError(f"{name}: its normalisation statistics differ from "
                       f"{names[0]}'s (other data, or another noise folded "
                       "in?); only runs of one problem can be averaged")
  for run, name in zip(runs, names):
    for key in run_lib.ADDED_HEADS:
      if run_lib.model_config_dict(run.config.model)[key] and not last[key]:
        raise InputError(f"{name} has model.{key} and {names[-1]} has "
                         f"not; list a run with model.{key} last (the "
                         "average keeps the last run's config)")


def _inference_problem(run: run_lib.Run) -> dict:
  # The training noise plays no part in a rollout (fine-tunings of one
  # parent at other noise levels average); the noise folded into the
  # statistics does, and stays.
  problem = run.problem.to_dict()
  del problem["noise_std"]
  return problem


def average_params(params: Sequence[Any], weights: Sequence[float]) -> Any:
  """sum_i w_i params_i, leaf by leaf, in the first tree's dtypes.

  A subtree that only some of the trees hold (an added head) is the mean
  over those, their weights rescaled to sum to 1 (equal if all are 0).
  """
  return _average(list(params), check_weights(weights, len(params)))


def _average(trees: list[Any], weights: list[float]) -> Any:
  if not all(isinstance(tree, Mapping) for tree in trees):
    return sum(w * np.asarray(leaf, np.float64)
               for w, leaf in zip(weights, trees)
               ).astype(np.asarray(trees[0]).dtype)
  average = {}
  for key in dict.fromkeys(key for tree in trees for key in tree):
    having = [(tree[key], w) for tree, w in zip(trees, weights)
              if key in tree]
    total = sum(w for _, w in having)
    average[key] = _average(
        [tree for tree, _ in having],
        [w / total if total > 0 else 1.0 / len(having) for _, w in having])
  return average


def source_workdir(source: str) -> str:
  """The run directory of a source: ``DIR`` or ``DIR@STEP`` -> DIR."""
  return source.rpartition("@")[0] or source


def parse_source(source: str) -> tuple[str, int | None]:
  """``DIR`` -> (DIR, None: its latest checkpoint); ``DIR@STEP`` ->
  (DIR, STEP), InputError unless STEP is a checkpoint kept in DIR."""
  workdir, step = source_workdir(source), source.rpartition("@")[2]
  if workdir == source:
    return source, None
  mngr = checkpoint.manager(workdir, every_steps=1)
  kept = sorted(mngr.all_steps())
  mngr.close()
  if not step.isdigit() or int(step) not in kept:
    raise InputError(f"{source}: no checkpoint {step!r} in {workdir}; "
                     f"allowed: {', '.join(map(str, kept)) or 'none kept'}")
  return workdir, int(step)


def write_average(workdirs: Sequence[str], weights: Sequence[float],
                  out: str) -> run_lib.Run:
  """Writes the weighted mean of the runs' parameters as a run.

  Args:
    workdirs: two or more run directories (or shipped models), each at its
      latest checkpoint, or ``DIR@STEP`` for its checkpoint of that step.
    weights: one per run, >= 0, summing to 1.
    out: a new directory; its checkpoint has the last source's step,
      config, statistics, optimiser state and graph sizes, with averaged
      parameters.

  Returns:
    The averaged run, loaded back from ``out``.

  Raises:
    InputError: fewer than two runs, bad weights, runs that do not fit
      together, or ``out`` already holding checkpoints.
  """
  if len(workdirs) < 2:
    raise InputError(f"averaging needs two or more runs; got {len(workdirs)}")
  weights = check_weights(weights, len(workdirs))
  if os.path.isdir(os.path.join(out, "checkpoints")):
    raise InputError(f"{out} already holds checkpoints; choose a new "
                     "directory")
  sources = [parse_source(w) for w in workdirs]
  runs = [run_lib.load_run(w, step) for w, step in sources]
  check_compatible(runs, workdirs)
  params = average_params([r.params for r in runs], weights)

  # The last run's whole checkpoint, as stored (so resuming continues its
  # optimiser), with the averaged parameters in place of its own.
  source = checkpoint.manager(sources[-1][0], every_steps=1)
  step = runs[-1].step
  stored = source.restore(step, args=ocp.args.Composite(
      state=ocp.args.StandardRestore(), config=ocp.args.JsonRestore(),
      stats=ocp.args.JsonRestore()))
  capacities = checkpoint.read_graph_capacities(source, step)
  source.close()
  state = dict(stored["state"], params=jax.tree.map(np.asarray, params))
  os.makedirs(out, exist_ok=True)
  record = {"sources": [{"workdir": os.path.normpath(w), "step": r.step}
                        for (w, _), r in zip(sources, runs)],
            "weights": weights}
  mpm_io.write_json(os.path.join(out, RECORD), record)
  mngr = checkpoint.manager(out, every_steps=1)
  checkpoint.save(mngr, step, state, stored["config"], stored["stats"],
                  capacities or None, force=True)
  mngr.close()
  return run_lib.load_run(out)
