"""Process machinery for long jobs that write files: worker processes that
die with their parent, locks that the kernel releases when their holder
dies, and the removal of temporary files whose writer is gone.

Used by dataset generation (``mpm.dataset``); imports only the standard
library and jax (a worker's compilation cache).
"""

import concurrent.futures
import contextlib
import ctypes
import glob
import multiprocessing
import os
import signal
import socket
import sys
import threading
import time
from typing import Callable, Sequence

import jax

from mpm import io as mpm_io

_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with_parent(parent_pid: int, poll_s: float = 0.5) -> None:
  """Ends this worker process when the process ``parent_pid`` dies.

  Linux: the kernel sends SIGKILL at the parent's death (PR_SET_PDEATHSIG).
  Elsewhere a daemon thread polls ``os.getppid()``: an orphan is reparented.
  """
  if sys.platform.startswith("linux"):
    try:
      libc = ctypes.CDLL(None, use_errno=True)
      ok = libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError):
      ok = False
    if ok:
      if os.getppid() != parent_pid:  # it died before prctl took effect
        os._exit(1)  # pylint: disable=protected-access
      return

  def watch():
    while os.getppid() == parent_pid:
      time.sleep(poll_s)
    os._exit(1)  # pylint: disable=protected-access

  threading.Thread(target=watch, name="parent-watchdog", daemon=True).start()


def _init_worker(cache_dir: str | None, parent_pid: int) -> None:
  die_with_parent(parent_pid)
  if cache_dir:
    jax.config.update("jax_compilation_cache_dir", cache_dir)


def pid_alive(pid: int) -> bool:
  try:
    os.kill(pid, 0)
  except ProcessLookupError:
    return False
  except PermissionError:
    return True  # someone else's process
  return True


def remove_stale_temps(parts_dir: str) -> None:
  """Removes temp files (``mpm_io.temp_path``) whose writer is gone.

  Only this host's are judged (a pid means nothing on another host); the
  others' are left to their writers, and to ``assemble``.
  """
  here = socket.gethostname()
  for path in glob.glob(os.path.join(parts_dir, "*.tmp-*")):
    host, pid = mpm_io.temp_writer(path)
    if host not in (None, here.replace("/", "_")):
      continue
    if pid is None or not pid_alive(pid):
      with contextlib.suppress(FileNotFoundError):
        os.remove(path)  # half-written by a killed run


class GeneratorBusyError(RuntimeError):
  """Another generator holds the dataset directory."""


@contextlib.contextmanager
def locked(path: str, busy: str, shared: bool = False):
  """Holds a POSIX ``flock`` on ``path`` (a directory, or a file created
  for it), exclusive or ``shared``; GeneratorBusyError(``busy``) if it is
  taken. The kernel releases it when the holder dies, however it dies.
  """
  try:
    import fcntl  # pylint: disable=g-import-not-at-top
  except ImportError:  # not POSIX: no lock
    yield
    return
  if os.path.isdir(path):
    fd = os.open(path, os.O_RDONLY)
  else:
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
  try:
    try:
      fcntl.flock(fd, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX)
                  | fcntl.LOCK_NB)
    except BlockingIOError:
      raise GeneratorBusyError(busy) from None
    yield
  finally:
    os.close(fd)


def map_in_processes(fn: Callable, items: Sequence, workers: int,
                     compilation_cache: str | None,
                     on_done: Callable) -> None:
  """Calls ``fn(item)`` for every item in ``workers`` spawned processes
  (JAX is not fork-safe) that die with this one, sharing compiled programs
  through ``compilation_cache``; ``on_done(result)`` as each finishes."""
  context = multiprocessing.get_context("spawn")
  with concurrent.futures.ProcessPoolExecutor(
      workers, mp_context=context, initializer=_init_worker,
      initargs=(compilation_cache, os.getpid())) as pool:
    futures = [pool.submit(fn, it) for it in items]
    for future in concurrent.futures.as_completed(futures):
      on_done(future.result())
