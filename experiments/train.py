"""Trains the learned simulator (resumes a killed run from its checkpoint).

  python -m experiments.train --config=experiments/configs/small.py \
      --data=DATA_DIR --workdir=WORKDIR [--config.train.num_steps=...]

Across processes or hosts (docs/scaling.md), start one per host with the
same command plus ``--coordinator=HOST0:PORT --num_processes=N
--process_id=i`` (or under SLURM's srun, which sets the count and rank);
``--data`` and ``--workdir`` must be on a shared filesystem.
"""

import contextlib
import os
import socket
import time

from absl import flags
from absl import logging
import jax
from ml_collections import config_flags

from experiments import runtime
from gnsjax import distributed
from mpm import workers
# gnsjax.train and gnsjax.config are imported in main, after the distributed
# runtime starts: importing them (jax_md) initialises JAX's backend.

_CONFIG = config_flags.DEFINE_config_file("config", None, "Config file.",
                                          lock_config=True)
_DATA = flags.DEFINE_string("data", None, "Dataset directory (train.h5, ...).")
_WORKDIR = flags.DEFINE_string("workdir", None, "Run directory.")
_COORDINATOR = flags.DEFINE_string(
    "coordinator", None, "host:port of process 0, which runs the "
    "coordinator (default: $GNSJAX_COORDINATOR; none: one process).")
_NUM_PROCESSES = flags.DEFINE_integer(
    "num_processes", None, "Processes in the run (default: $SLURM_NTASKS or "
    "$GNSJAX_NUM_PROCESSES, else 1).")
_PROCESS_ID = flags.DEFINE_integer(
    "process_id", None, "This process's rank, 0..num_processes-1 (default: "
    "$SLURM_PROCID or $GNSJAX_PROCESS_ID).")
_COORDINATOR_WAIT_S = flags.DEFINE_float(
    "coordinator_wait_s", 60.0, "How long a process other than 0 waits for "
    "the coordinator to answer before giving up (s).", lower_bound=0.0)
_INIT_TIMEOUT_S = flags.DEFINE_integer(
    "init_timeout_s", 300, "How long all processes may take to connect (s).",
    lower_bound=1)
_HEARTBEAT_TIMEOUT_S = flags.DEFINE_integer(
    "heartbeat_timeout_s", 100, "After the start, a process silent this "
    "long is declared dead and all processes abort (s; JAX's default; "
    "raise it where a process may stall, e.g. an oversubscribed "
    "machine).", lower_bound=1)


def main(argv):
  del argv
  processes = distributed.settings(_COORDINATOR.value, _NUM_PROCESSES.value,
                                   _PROCESS_ID.value)
  distributed.check_supported(_CONFIG.value, processes.num_processes)
  runtime.existing_dir("data", _DATA.value, holding="train.h5")
  runtime.writable("workdir", _WORKDIR.value)
  if processes.process_id:  # process 0 holds the run directory's lock
    _train(processes)
    return
  with _one_trainer(_WORKDIR.value):
    _train(processes)


@contextlib.contextmanager
def _one_trainer(workdir):
  """Holds ``workdir/trainer.lock`` (an flock, released by the kernel
  however this process dies), naming this process in it; a second trainer
  into the same directory is refused, naming the first."""
  path = os.path.join(workdir, "trainer.lock")
  holder = ""
  if os.path.exists(path):
    with open(path) as f:
      holder = f.read().strip()
  os.makedirs(workdir, exist_ok=True)
  try:
    with workers.locked(path, ""):
      with open(path, "w") as f:
        f.write(f"pid {os.getpid()} on host {socket.gethostname()}, started "
                f"{time.strftime('%Y-%m-%d %H:%M:%S')}\n")
      yield
  except workers.GeneratorBusyError:
    raise runtime.InputError(
        f"--workdir={workdir}: another trainer is running in it "
        f"({holder or 'its pid unknown'}); wait for it to finish (or stop "
        "it), or use another --workdir") from None


def _train(processes):
  distributed.handshake(processes, _COORDINATOR_WAIT_S.value,
                        _INIT_TIMEOUT_S.value)
  runtime.enable_compilation_cache()
  distributed.initialize(processes, _INIT_TIMEOUT_S.value,
                         _HEARTBEAT_TIMEOUT_S.value)
  # pylint: disable=g-import-not-at-top
  from gnsjax import config as config_lib
  from gnsjax import train
  # pylint: enable=g-import-not-at-top
  try:
    config_lib.check_config(_CONFIG.value)
  except ValueError as e:
    raise runtime.InputError(f"--config: {e}") from e
  logging.info("devices: %s", jax.devices())
  metrics = train.train_and_evaluate(_CONFIG.value, _DATA.value,
                                     _WORKDIR.value)
  if jax.process_index() == 0:
    for k, v in sorted(metrics.items()):
      print(f"{k}: {v:.6g}")


if __name__ == "__main__":
  flags.mark_flags_as_required(["config", "data", "workdir"])
  runtime.run(main)
