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

import csv
import glob
import logging as std_logging
import os
import shutil
import sys
import tempfile
import time
import warnings
from typing import Any, Sequence

from absl import logging
import orbax.checkpoint as ocp
from orbax.checkpoint import checkpoint_managers as cm

from mpm import io as mpm_io


class DamagedCheckpointError(mpm_io.FormatError):
  """A checkpoint's files are missing or unreadable (the message names the
  checkpoint and what is missing); entry points report it in one line."""
  # Exit without finalising: a failed read leaves orbax's reads pending in
  # other threads, which print tracebacks at interpreter exit.
  exit_at_once = True


# What every checkpoint holds (orbax's layout under <step>/): its metadata,
# the train state's tree and array store, the JSON items.
_REQUIRED = ("_CHECKPOINT_METADATA", "state/_METADATA", "state/manifest.ocdbt",
             "config/metadata", "stats/metadata")


def missing_files(step_dir: str) -> list[str]:
  """What ``step_dir`` (``<workdir>/checkpoints/<step>``) lacks of a
  complete checkpoint, relative to it; [] if nothing (the data files' own
  contents are checked only by reading them: ``restore``)."""
  if not os.path.isdir(step_dir):
    return ["the whole checkpoint"]
  missing = [f for f in _REQUIRED
             if not os.path.isfile(os.path.join(step_dir, f))]
  state = os.path.join(step_dir, "state")
  stores = [state] + sorted(glob.glob(os.path.join(state, "ocdbt.process_*")))
  for store in stores:
    rel = os.path.relpath(store, step_dir)
    if store != state and not os.path.isfile(
        os.path.join(store, "manifest.ocdbt")):
      missing.append(f"{rel}/manifest.ocdbt")
    data = os.path.join(store, "d")
    if os.path.isdir(store) and not (os.path.isdir(data) and os.listdir(data)):
      missing.append(f"{rel}/d/* (the arrays' data)")
  return missing


def check_intact(directory: str, step: int) -> None:
  """Raises DamagedCheckpointError naming ``directory/step`` and what it
  lacks, if anything (``missing_files``)."""
  path = os.path.join(directory, str(step))
  missing = missing_files(path)
  if missing:
    raise DamagedCheckpointError(
        f"checkpoint {path} is damaged: {', '.join(missing[:4])}"
        f"{f' and {len(missing) - 4} more' if len(missing) > 4 else ''} "
        "missing; use another checkpoint (or retrain)")


def _read(mngr: ocp.CheckpointManager, step: int, **items) -> dict:
  """``mngr.restore`` of ``items`` at ``step``, checked first; a failed
  read (a data file missing or truncated) as DamagedCheckpointError."""
  check_intact(str(mngr.directory), step)
  # When a read fails, orbax closes its event loop and tensorstore prints
  # 'RuntimeError: Event loop is closed' for every read still pending,
  # straight to file descriptor 2 (past sys.stderr and every hook): during
  # the restore, descriptor 2 is a scratch file.
  sys.stderr.flush()
  saved = os.dup(2)
  with tempfile.TemporaryFile() as scratch:
    os.dup2(scratch.fileno(), 2)
    try:
      restored = mngr.restore(step, args=ocp.args.Composite(**items))
    except (OSError, ValueError, KeyError, RuntimeError) as e:
      # Descriptor 2 stays the scratch file for the pending reads; Python's
      # own output goes where descriptor 2 went (until _settle_stderr).
      _UNSETTLED.append((sys.stderr, saved))
      sys.stderr = os.fdopen(saved, "w", buffering=1, closefd=False)
      _quiet_orbax_leftovers()
      first = (str(e).strip().splitlines() or [""])[0][:200]
      raise DamagedCheckpointError(
          f"checkpoint {os.path.join(str(mngr.directory), str(step))} "
          f"cannot be read ({type(e).__name__}: {first}); use another "
          "checkpoint (or retrain)") from e
    os.dup2(saved, 2)
    os.close(saved)
    scratch.seek(0)
    sys.stderr.write(scratch.read().decode(errors="replace"))
  return restored


def _quiet_orbax_leftovers() -> None:
  """After a failed read orbax leaves one pending read per array, each
  printed as 'Exception ignored in: <coroutine ...>' with its traceback
  when collected (and at exit): the error already says it all."""
  previous = sys.unraisablehook
  if getattr(previous, "quiets_orbax", False):
    return
  orbax_dir = os.path.dirname(os.path.dirname(ocp.__file__))

  def hook(unraisable):
    tb = unraisable.exc_traceback
    while tb is not None:
      if tb.tb_frame.f_code.co_filename.startswith(orbax_dir):
        return
      tb = tb.tb_next
    previous(unraisable)
  hook.quiets_orbax = True
  sys.unraisablehook = hook
  warnings.filterwarnings("ignore", "coroutine .* was never awaited",
                          RuntimeWarning)
  # The same reads' futures, logged by asyncio as never retrieved.
  std_logging.getLogger("asyncio").addFilter(
      lambda record: "exception was never retrieved" not in record.msg)


# (sys.stderr, the descriptor 2 was) that a failed _read set aside.
_UNSETTLED = []


def _settle_stderr(wait_s: float = 2.0) -> None:
  """Once a failed read's pending reads are done, descriptor 2 and
  ``sys.stderr`` are what they were before it (``_read`` left them on a
  scratch file and a copy), for a process that goes on."""
  time.sleep(wait_s)
  while _UNSETTLED:
    stream, saved = _UNSETTLED.pop()
    sys.stderr.flush()
    os.dup2(saved, 2)
    os.close(saved)
    sys.stderr = stream


def set_aside_damaged(workdir: str) -> list[str]:
  """Moves each damaged checkpoint of ``workdir/checkpoints`` (``missing_
  files``, or whose arrays do not read) to ``workdir/damaged_checkpoints``,
  so that a resumed run starts from the newest intact one and orbax never
  sees them; returns one line per checkpoint moved (also logged)."""
  root = os.path.join(os.path.abspath(workdir), "checkpoints")
  steps = sorted((int(n) for n in os.listdir(root) if n.isdigit()),
                 reverse=True) if os.path.isdir(root) else []
  moved = []
  for step in steps:
    missing = missing_files(os.path.join(root, str(step)))
    if not missing:
      mngr = ocp.CheckpointManager(root)
      try:
        _read(mngr, step, state=ocp.args.StandardRestore())
        break  # the newest intact checkpoint
      except DamagedCheckpointError as e:
        missing = [str(e)]
        _settle_stderr()
      finally:
        mngr.close()
    aside = os.path.join(os.path.dirname(root), "damaged_checkpoints")
    os.makedirs(aside, exist_ok=True)
    shutil.move(os.path.join(root, str(step)), os.path.join(aside, str(step)))
    moved.append(f"skipped the damaged checkpoint at step {step} "
                 f"({', '.join(missing[:4])} missing), moved to "
                 f"{os.path.join(aside, str(step))}")
    logging.warning("%s", moved[-1])
  return moved


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
  restored = _read(mngr, step,
                   state=ocp.args.StandardRestore(abstract_state),
                   config=ocp.args.JsonRestore(),
                   stats=ocp.args.JsonRestore())
  return restored["state"], restored["config"], restored["stats"]


def read_config(mngr: ocp.CheckpointManager, step: int) -> dict:
  """The config stored with a checkpoint, without restoring arrays."""
  return _read(mngr, step, config=ocp.args.JsonRestore())["config"]


def read_stats(mngr: ocp.CheckpointManager, step: int) -> dict:
  """The normalisation statistics stored with a checkpoint."""
  return _read(mngr, step, stats=ocp.args.JsonRestore())["stats"]


def read_graph_capacities(mngr: ocp.CheckpointManager, step: int) -> dict:
  """The neighbour-list sizes stored with a checkpoint; {} for checkpoints
  written before they were stored."""
  if not os.path.isdir(os.path.join(mngr.directory, str(step),
                                    "graph_capacities")):
    return {}
  return _read(mngr, step, graph_capacities=ocp.args.JsonRestore()
               )["graph_capacities"]


def restore_params(mngr: ocp.CheckpointManager, abstract_params: Any,
                   step: int) -> Any:
  """Only the parameters of a checkpoint's train state (no optimiser), in
  the structure of ``abstract_params``."""
  import jax  # pylint: disable=g-import-not-at-top
  restored = _read(mngr, step, state=ocp.args.StandardRestore())["state"]
  return jax.tree.map(lambda like, value: jax.numpy.asarray(value, like.dtype),
                      abstract_params, restored["params"])


# The columns of a run's metrics.csv (gnsjax.train).
METRICS_FIELDS = ["step", "loss", "grad_norm", "learning_rate",
                  "steps_per_s", "wall_time_s"]


def resume_metrics_csv(path: str, step: int) -> float:
  """Drops the rows of a run's metrics.csv logged after ``step`` (its
  checkpoint: a killed run's rows, redone now) and returns the training
  time [s] up to it."""
  if not os.path.exists(path):
    return 0.0
  with open(path, newline="") as f:
    rows = [r for r in csv.DictReader(f) if int(r["step"]) <= step]
  tmp = f"{path}.tmp-{os.getpid()}"
  with open(tmp, "w", newline="") as f:
    writer = csv.DictWriter(f, fieldnames=METRICS_FIELDS,
                            extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
  os.replace(tmp, path)
  return float(rows[-1]["wall_time_s"]) if rows else 0.0
