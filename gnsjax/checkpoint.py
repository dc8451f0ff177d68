"""Checkpoints of a training run (orbax), with its config and statistics.

Each checkpoint holds the train state (step, parameters, optimiser state,
random key), the resolved config and the normalisation statistics, so any one
of them restores on its own, and the neighbour lists' sizes, so a resumed
run computes exactly what an uninterrupted one does. Saved every
``every_steps`` steps and at named steps (the paper's V1-V4 at 0.5M, 1M,
1.5M and 2M), keeping the latest
``keep`` plus every named one. Writes are atomic (orbax writes to a temporary
directory and renames it).
"""

import os
from typing import Any, Sequence

import orbax.checkpoint as ocp
from orbax.checkpoint import checkpoint_managers as cm


def manager(workdir: str, every_steps: int, named_steps: Sequence[int] = (),
            keep: int = 3) -> ocp.CheckpointManager:
  """The CheckpointManager of ``workdir/checkpoints``."""
  named = sorted(int(s) for s in named_steps)
  options = ocp.CheckpointManagerOptions(
      save_decision_policy=cm.AnySavePolicy([
          cm.FixedIntervalPolicy(every_steps),
          cm.SpecificStepsPolicy(named)]),
      preservation_policy=cm.AnyPreservationPolicy([
          cm.LatestN(keep), cm.CustomSteps(named)]),
      # Synchronous: a returned save is on disk, so a kill cannot lose it.
      enable_async_checkpointing=False)
  return ocp.CheckpointManager(os.path.join(os.path.abspath(workdir),
                                            "checkpoints"), options=options)


def save(mngr: ocp.CheckpointManager, step: int, state: Any, config: dict,
         stats: dict, graph_capacities: dict | None = None,
         force: bool = False) -> bool:
  """Saves if the policy says so (or ``force``); returns whether it did.

  ``graph_capacities`` (``Trainer.graph_capacities``) are the neighbour
  lists' sizes, which a resumed run needs to compute what this one would.
  """
  items = dict(state=ocp.args.StandardSave(state),
               config=ocp.args.JsonSave(config),
               stats=ocp.args.JsonSave(stats))
  if graph_capacities is not None:
    items["graph_capacities"] = ocp.args.JsonSave(graph_capacities)
  return mngr.save(step, args=ocp.args.Composite(**items), force=force)


def restore(mngr: ocp.CheckpointManager, abstract_state: Any,
            step: int | None = None) -> tuple[Any, dict, dict]:
  """(state, config, stats) of ``step`` (default: the latest)."""
  step = mngr.latest_step() if step is None else step
  if step is None:
    raise FileNotFoundError(f"{mngr.directory}: no checkpoint to restore")
  restored = mngr.restore(step, args=ocp.args.Composite(
      state=ocp.args.StandardRestore(abstract_state),
      config=ocp.args.JsonRestore(),
      stats=ocp.args.JsonRestore()))
  return restored["state"], restored["config"], restored["stats"]


def read_config(mngr: ocp.CheckpointManager, step: int) -> dict:
  """The config stored with a checkpoint, without restoring arrays."""
  return mngr.restore(step, args=ocp.args.Composite(
      config=ocp.args.JsonRestore()))["config"]


def read_stats(mngr: ocp.CheckpointManager, step: int) -> dict:
  """The normalisation statistics stored with a checkpoint."""
  return mngr.restore(step, args=ocp.args.Composite(
      stats=ocp.args.JsonRestore()))["stats"]


def read_graph_capacities(mngr: ocp.CheckpointManager, step: int) -> dict:
  """The neighbour-list sizes stored with a checkpoint; {} for checkpoints
  written before they were stored."""
  if not os.path.isdir(os.path.join(mngr.directory, str(step),
                                    "graph_capacities")):
    return {}
  return mngr.restore(step, args=ocp.args.Composite(
      graph_capacities=ocp.args.JsonRestore()))["graph_capacities"]


def restore_params(mngr: ocp.CheckpointManager, abstract_params: Any,
                   step: int) -> Any:
  """Only the parameters of a checkpoint's train state (no optimiser), in
  the structure of ``abstract_params``."""
  import jax  # pylint: disable=g-import-not-at-top
  restored = mngr.restore(step, args=ocp.args.Composite(
      state=ocp.args.StandardRestore()))["state"]
  return jax.tree.map(lambda like, value: jax.numpy.asarray(value, like.dtype),
                      abstract_params, restored["params"])
