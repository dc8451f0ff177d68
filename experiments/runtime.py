"""Process-wide settings shared by the entry points, and how they refuse
bad input: one line on stderr, exit code 2, nothing written.

Every entry point ends in ``runtime.run(main)`` (instead of
``app.run(main)``) and checks its flags before it creates anything; what
it refuses it raises as ``InputError`` (or ``app.UsageError``).
"""

import dataclasses
import math
import os
import platform
import sys
import typing
from typing import Any, Callable

from absl import app
from absl import flags
from absl import logging
import jax
from jax._src import xla_bridge  # no public backends_are_initialized

import mpm
from experiments import config_files
from experiments.studies import settings as settings_lib
from mpm import budget
from mpm import io as mpm_io

# A value given by the user is malformed or out of range (a flag, a scene
# key, a config entry); the message names it and what is allowed.
InputError = mpm.InputError

# What is reported in one line: bad input, and files that are missing or not
# in the format. Anything else is a bug and keeps its traceback.
BAD_INPUT = (InputError, mpm_io.FormatError, app.UsageError)
EXIT_BAD_INPUT = 2

_VERBOSE = flags.DEFINE_bool(
    "verbose", False, "Show INFO logs (the libraries' too), and on bad "
    "input the traceback, not only the one-line error.")
# The flags define_flags defines below belong to the entry point that calls
# it (they are its key flags: --helpshort lists them), not to this module.
flags.disclaim_key_flags()


def _refuse(error: Exception) -> None:
  print(f"error: {error}", file=sys.stderr)
  if getattr(error, "exit_at_once", False) or getattr(
      error.__cause__, "exit_at_once", False):
    # Reads left pending in other threads (orbax's, of a damaged
    # checkpoint) would print 'Event loop is closed' tracebacks at exit.
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(EXIT_BAD_INPUT)  # pylint: disable=protected-access
  sys.exit(EXIT_BAD_INPUT)


def _non_finite_floats() -> list[str]:
  """The float flags of this project's modules holding NaN or an infinity
  (absl's bounds let NaN through; no float setting of ours means one)."""
  bad = []
  ours = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
  for module, module_flags in flags.FLAGS.flags_by_module_dict().items():
    if not (module.startswith(("experiments", "gnsjax", "mpm")) or
            os.path.abspath(module).startswith(ours + os.sep)):
      continue
    for flag in module_flags:
      value = flag.value
      if isinstance(value, float) and not math.isfinite(value):
        bad.append(f"--{flag.name}={value}")
  return bad


def _parse_flags(argv: list[str]) -> list[str]:
  # --verbose shows in every entry point's --help, beside its own flags.
  flags.FLAGS.register_key_flag_for_module(sys.argv[0], flags.FLAGS["verbose"])
  verbose = "--verbose" in argv
  # ml_collections reports a bad config file or override in a traceback
  # (a missing file only once the config is read): one line instead.
  problem = config_files.check_files(flags.FLAGS, argv)
  if problem and not verbose:
    _refuse(InputError(problem))
  try:
    rest = flags.FLAGS(argv)
  except flags.Error as e:  # unknown flag, bad value, failed validator
    _refuse(e)
  except Exception as e:  # pylint: disable=broad-except
    if verbose or not config_files.is_involved(flags.FLAGS, argv):
      raise
    _refuse(InputError(config_files.explain(flags.FLAGS, argv, e)))
  bad = _non_finite_floats()
  if bad:
    _refuse(InputError(f"{', '.join(sorted(set(bad)))}: allowed: a finite "
                       "number"))
  return rest


def run(main: Callable[[list[str]], None]) -> None:
  """``app.run(main)``, bad input reported as ``error: <message>`` with exit
  code 2 (with its traceback under ``--verbose``)."""
  def checked(argv):
    # INFO logs (orbax's checkpoint chatter, absl's) only under --verbose.
    logging.set_verbosity(logging.INFO if _VERBOSE.value else
                          logging.WARNING)
    try:
      return main(argv)
    except BAD_INPUT as e:
      _remove_created()
      if _VERBOSE.value:
        raise
      _refuse(e)
    except SystemExit as e:
      if e.code not in (None, 0):
        _remove_created()
      raise
    except BaseException:
      _remove_created()
      raise
  app.run(checked, flags_parser=_parse_flags)


def existing_file(flag: str, path: str | None) -> str | None:
  """``path`` (None passes); InputError naming ``--flag`` if no such file."""
  if path is not None and not os.path.isfile(path):
    raise InputError(f"--{flag}={path}: no such file")
  return path


def existing_dir(flag: str, path: str, holding: str = "") -> str:
  """``path``; InputError naming ``--flag`` unless it is a directory (that
  holds the file ``holding``, if given)."""
  if not os.path.isdir(path):
    raise InputError(f"--{flag}={path}: no such directory")
  if holding and not os.path.exists(os.path.join(path, holding)):
    present = sorted(os.listdir(path))[:8]
    raise InputError(f"--{flag}={path}: no {holding} in it (it holds "
                     f"{present})")
  if holding == "checkpoints":
    _latest_checkpoint_intact(flag, path)
  return path


def _latest_checkpoint_intact(flag: str, workdir: str) -> None:
  """InputError naming ``--flag`` if the run's latest checkpoint (the one
  loaded) is missing files, before anything is created."""
  from gnsjax import checkpoint  # pylint: disable=g-import-not-at-top
  root = os.path.join(workdir, "checkpoints")
  steps = [int(n) for n in os.listdir(root) if n.isdigit()]
  if not steps:
    raise InputError(f"--{flag}={workdir}: no checkpoint in {root}")
  try:
    checkpoint.check_intact(root, max(steps))
  except checkpoint.DamagedCheckpointError as e:
    raise InputError(f"--{flag}={workdir}: {e}") from e


def writable(flag: str, path: str, *, directory: bool = True) -> str:
  """Checks that ``path`` can be created or written (a directory, or a file
  if not ``directory``) without creating anything.

  Raises:
    InputError: naming ``--flag`` and why not.
  """
  if not path:
    raise InputError(f"--{flag}=: empty; allowed: a path")
  if os.path.exists(path) and os.path.isdir(path) != directory:
    raise InputError(f"--{flag}={path}: exists and is not a "
                     f"{'directory' if directory else 'file'}")
  created = _first_missing(os.path.abspath(path))
  parent = os.path.dirname(created)
  if not os.path.isdir(parent):
    raise InputError(f"--{flag}={path}: {parent} is a file, not a directory")
  if not os.access(parent, os.W_OK | os.X_OK):
    raise InputError(f"--{flag}={path}: {parent} is not writable")
  # What this run would create: removed if it fails (run's cleanup).
  if not os.path.exists(created):
    _CREATED.append(created)
  return path


def _first_missing(path: str) -> str:
  """``path`` (absolute), or its outermost ancestor that does not exist
  yet: the first thing writing it creates (``path`` itself if it exists)."""
  while not os.path.exists(os.path.dirname(path)):
    path = os.path.dirname(path)
  return path


def existing_ancestor(path: str) -> str:
  """``path`` (absolute) if it exists, else its nearest existing ancestor."""
  path = os.path.abspath(path)
  return path if os.path.exists(path) else os.path.dirname(
      _first_missing(path))


# Outputs that did not exist when checked (``writable``): a run that fails
# removes them, unless they hold what a rerun resumes from.
_CREATED: list[str] = []


def _resumable(path: str) -> bool:
  """Whether ``path`` holds a checkpoint (a training, the ablation's) or a
  finished part of a dataset, which the same command continues from."""
  for folder, dirs, files in os.walk(path):
    name = os.path.basename(folder)
    if ((name == "checkpoints" and any(d.isdigit() for d in dirs)) or
        (name == "parts" and files)):
      return True
  return False


def _remove_created() -> None:
  import shutil  # pylint: disable=g-import-not-at-top
  for path in _CREATED:
    if _resumable(path):
      continue
    if os.path.isdir(path):
      shutil.rmtree(path, ignore_errors=True)
    elif os.path.exists(path):
      os.remove(path)


# XLA:CPU (jaxlib 0.10.1) adds the tuning features +prefer-no-gather and
# +prefer-no-scatter to every program it compiles for an AVX-512 host, and
# its loader of cached programs checks every "+" feature against the host's
# CPU features, where tuning features never appear: each program loaded
# from the compilation cache logged two errors ("Loading XLA:CPU AOT result.
# Target machine feature +prefer-no-gather is not supported on the host
# machine ...") and ran all the same. Programs compiled for AVX2 carry no
# such features. On the development machine (Zen 4) AVX2 is no slower: the
# MPM substep 10% faster, the GNS steps the same (docs/performance.md).
CPU_MAX_ISA = "AVX2"


def cap_cpu_isa() -> None:
  """Compiles for at most AVX2 on x86-64 (``--xla_cpu_max_isa``, added to
  ``$XLA_FLAGS`` unless it sets a maximum ISA already), so that programs
  loaded from the compilation cache log no false feature mismatch.

  XLA reads ``$XLA_FLAGS`` once, when jax starts its backend: this has no
  effect after the first computation, and is then left out, so that child processes compile as this one.
  ``experiments/__init__.py`` calls it, before any entry point's imports.
  """
  flags_now = os.environ.get("XLA_FLAGS", "")
  if (platform.machine().lower() not in ("x86_64", "amd64")
      or "xla_cpu_max_isa" in flags_now
      or xla_bridge.backends_are_initialized()):
    return
  os.environ["XLA_FLAGS"] = (
      f"{flags_now} --xla_cpu_max_isa={CPU_MAX_ISA}".strip())


def enable_compilation_cache(path: str | None = None) -> str:
  """Caches compiled XLA programs on disk, so reruns skip compilation
  (and caps the instruction set for them, ``cap_cpu_isa``).

  Returns:
    The cache directory (``$GNSJAX_CACHE_DIR`` or ~/.cache/gnsjax/jax).
  """
  cap_cpu_isa()
  path = path or os.environ.get("GNSJAX_CACHE_DIR") or os.path.join(
      os.path.expanduser("~"), ".cache", "gnsjax", "jax")
  jax.config.update("jax_compilation_cache_dir", path)
  jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
  return path


# ------------------------------------------------------------ settings ---

_DEFINE = {bool: flags.DEFINE_bool, int: flags.DEFINE_integer,
           float: flags.DEFINE_float, str: flags.DEFINE_string}


def define_flags(settings_cls: type | tuple[type, ...],
                 flag_values: flags.FlagValues = flags.FLAGS,
                 **defaults) -> dict[str, Any]:
  """One flag per field of a study's ``Settings`` (``studies.settings``),
  with the field's name, default and help; ``defaults`` replace a field's
  default for this entry point only. Fields marked ``flag=False`` get none.

  An entry point that runs one of several studies passes their classes
  together: a field that several of them hold (by inheritance from one
  settings group) gets one flag, from the first class that flags it.

  Returns:
    field name -> its FlagHolder, for :func:`settings_from_flags`.
  """
  classes = (settings_cls if isinstance(settings_cls, tuple) else
             (settings_cls,))
  holders = {}
  for cls in classes:
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
      if not f.metadata.get("flag", True) or f.name in holders:
        continue
      kind, sequence, _ = settings_lib.element_type(hints[f.name])
      _FIELDS[f.name] = (kind, sequence, f.metadata)
      default = defaults.get(f.name, f.default)
      help_text = f.metadata.get("help", "")
      if f.metadata.get("choices"):
        help_text += f" One of {', '.join(f.metadata['choices'])}."
      if sequence:
        holders[f.name] = flags.DEFINE_list(
            f.name, None if default is None else [str(v) for v in default],
            help_text, flag_values=flag_values)
      else:
        holders[f.name] = _DEFINE[kind](f.name, default, help_text,
                                        flag_values=flag_values)
  return holders


# Flag name -> (scalar type, is a sequence, metadata) of its field.
_FIELDS: dict[str, tuple[type, bool, Any]] = {}


def _parse(name: str, given: list[str], kind: type) -> tuple:
  try:
    return tuple(kind(v.strip()) for v in given
                 if v.strip() or kind is not str)
  except ValueError:
    allowed = {int: "integers", float: "numbers"}.get(kind, "values")
    raise InputError(f"--{name}={','.join(given)}; allowed: comma-separated "
                     f"{allowed}") from None


def settings_from_flags(settings_cls: type, holders: dict[str, Any],
                        **values):
  """The ``Settings`` the flags (and ``values``, for fields without a flag)
  describe, checked; raises InputError naming the flag. Holders of flags
  that are not fields of ``settings_cls`` (another study's) are left out."""
  hints = typing.get_type_hints(settings_cls)
  flagged = {f.name for f in dataclasses.fields(settings_cls)
             if f.metadata.get("flag", True)}
  for name, holder in holders.items():
    if name not in flagged:
      # Another study's flag, given: checked all the same (a bad value is
      # refused even where this study does not read it).
      if holder.present and holder.value is not None and name in _FIELDS:
        kind, sequence, meta = _FIELDS[name]
        value = (_parse(name, holder.value, kind) if sequence else
                 holder.value)
        settings_lib.check_value(name, value, kind, sequence, meta)
      continue
    kind, sequence, _ = settings_lib.element_type(hints[name])
    value = holder.value
    if sequence and value is not None:
      value = _parse(name, value, kind)
    values[name] = value
  settings = settings_cls(**values)
  # Refused above if it cannot fit; a job of hours is said before it starts.
  warning = budget.plan_warning(settings.simulation_seconds)
  if warning:
    print(warning, file=sys.stderr)
  return settings
