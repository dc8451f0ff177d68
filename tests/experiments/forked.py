"""``python -m module args`` as forks of one process that has imported the
libraries the entry points share (run it as ``python -m
tests.experiments.forked``; ``Server`` starts and drives it).

A fresh ``python -m`` of an entry point spends 1-8 CPU seconds importing
jax, flax, orbax, matplotlib and the project before it reads its first flag;
a fork of this server starts with them imported. Each run is still a new
process, forked before jax's backend starts (nothing in ``PRELOAD`` starts it,
which the server checks; jax_md is imported without its ``__init__``,
``gnsjax/neighbors.py``), running the module as ``python -m`` does (``runpy``, ``__main__``),
with its own argv, stdout and stderr, and the same exit code: sys.exit's, 1
after an uncaught exception (shown by ``sys.excepthook``).

Protocol: one JSON line per request on stdin, ``[module, argv]``; one JSON
line per reply on stdout, ``[returncode, stdout, stderr]``.
"""

import atexit
import importlib
import json
import os
import runpy
import signal
import subprocess
import sys
import tempfile

# Imported once by the server; none starts jax's backend (checked).
PRELOAD = (
    "numpy", "scipy.signal", "sympy", "e3nn_jax", "h5py", "matplotlib.pyplot",
    "jax", "jax.numpy", "flax.linen", "optax", "orbax.checkpoint", "jraph",
    "cma", "tensorboardX", "tqdm", "absl.app", "absl.flags", "absl.logging",
    "ml_collections.config_flags", "mpm", "mpm.dataset", "mpm.io",
    "mpm.sampler", "gnsjax.checkpoint", "gnsjax.data", "gnsjax.distributed",
    "gnsjax.features", "gnsjax.metrics", "gnsjax.models",
    "gnsjax.simulator", "gnsjax.graph", "gnsjax.batching", "gnsjax.rollout",
    "gnsjax.run", "gnsjax.train", "gnsjax.config", "gnsjax.design.scenes",
    "experiments.studies.evaluation", "experiments.studies.stability",
    "experiments.studies.tradeoff", "experiments.studies.convergence",
    "experiments.studies.design", "experiments.studies.design_comparison",
    "experiments.studies.gradient_check", "experiments.studies.calibration",
    "experiments.studies.ablation", "experiments.studies.demo",
    "experiments.runtime", "experiments.file_jobs",
    "experiments.figures", "experiments.configs.paper",
    "experiments.configs.small", "experiments.configs.test",
    "experiments.timing", "experiments.studies.settings",
    "experiments.benchmarks.scenes")
# Per run: a guard against a hang, not a time limit. The demo's refusal of
# too many workers measures one scene first and took 88 s alone on a slow
# day of this 2-core CPU (2026-12-01), over 120 s under load.
TIMEOUT_S = 300


def _exit_code(code) -> int:
  """The exit status Python gives ``sys.exit(code)``."""
  if code is None:
    return 0
  if isinstance(code, int):
    return code
  print(code, file=sys.stderr)
  return 1


def _child(module: str, argv: list[str], out: int, err: int) -> None:
  """Runs ``module`` as ``python -m`` would, then exits (never returns)."""
  code = 70
  try:
    signal.alarm(TIMEOUT_S)
    devnull = os.open(os.devnull, os.O_RDONLY)
    for fd, target in ((devnull, 0), (out, 1), (err, 2)):
      os.dup2(fd, target)
    sys.stdout, sys.stderr = sys.__stdout__, sys.__stderr__
    sys.argv = [module, *argv]
    try:
      runpy.run_module(module, run_name="__main__", alter_sys=True)
      code = 0
    except SystemExit as e:
      code = _exit_code(e.code)
    except BaseException:  # pylint: disable=broad-except
      sys.excepthook(*sys.exc_info())
      code = 1
    atexit._run_exitfuncs()  # pylint: disable=protected-access
    sys.stdout.flush()
    sys.stderr.flush()
  finally:
    os._exit(code)


def _run(module: str, argv: list[str]) -> list:
  with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:
      _child(module, argv, out.fileno(), err.fileno())
    _, status = os.waitpid(pid, 0)
    texts = []
    for f in (out, err):
      f.seek(0)
      texts.append(f.read().decode(errors="replace"))
  return [os.waitstatus_to_exitcode(status), *texts]


def serve() -> None:
  for name in PRELOAD:
    importlib.import_module(name)
  from jax._src import xla_bridge  # pylint: disable=g-import-not-at-top
  if xla_bridge.backends_are_initialized():
    raise RuntimeError("a preloaded module started jax's backend: forks of "
                       "this process could hang in XLA")
  replies = sys.stdout
  sys.stdout = sys.stderr  # what the preloaded modules print stays apart
  for line in sys.stdin:
    replies.write(json.dumps(_run(*json.loads(line))) + "\n")
    replies.flush()


class Server:
  """The server as a subprocess of the tests: ``run(module, *args)``."""

  def __init__(self, root: str, env: dict[str, str]):
    self._proc = subprocess.Popen(
        [sys.executable, "-m", "tests.experiments.forked"], env=env,
        cwd=root, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)

  def run(self, module: str, *args: str) -> tuple[int, str, str]:
    """(returncode, stdout, stderr) of ``python -m module args``."""
    self._proc.stdin.write(json.dumps([module, list(args)]) + "\n")
    self._proc.stdin.flush()
    reply = self._proc.stdout.readline()
    if not reply:
      raise RuntimeError(f"the fork server exited ({self._proc.wait()})")
    code, stdout, stderr = json.loads(reply)
    return code, stdout, stderr

  def close(self) -> None:
    self._proc.stdin.close()
    self._proc.wait(timeout=60)


if __name__ == "__main__":
  serve()
