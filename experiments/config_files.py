"""What is wrong with a ``--config=FILE`` and its ``--config.a.b=V``
overrides, in one line: the file missing, the file and line of a syntax or
other error in it, an unknown field and the nearest valid name.

ml_collections reports each of these as a 40-60 line traceback (a missing
file only once the config is first read); ``runtime`` calls
:func:`check_files` before absl parses the flags and :func:`explain` when
the parse fails.
"""

import difflib
import importlib.util
import os
import re
import traceback

from ml_collections.config_flags import config_flags  # the module


def _config_flag_names(flag_values) -> list[str]:
  return sorted({f.name for f in flag_values._flags().values()  # pylint: disable=protected-access
                 if config_flags.is_config_flag(f)})


def _given(name: str, argv: list[str]) -> str | None:
  """The value of ``--name`` in ``argv`` (the last one), or None."""
  value = None
  for i, arg in enumerate(argv):
    match = re.match(rf"^--?{re.escape(name)}(=(.*))?$", arg)
    if match:
      value = (match.group(2) if match.group(1) is not None else
               argv[i + 1] if i + 1 < len(argv) else "")
  return value


def _where(error: BaseException, path: str) -> str:
  """' (line N)' of the innermost frame of ``error`` in the file ``path``."""
  line = None
  for frame, lineno in traceback.walk_tb(error.__traceback__):
    if os.path.abspath(frame.f_code.co_filename) == os.path.abspath(path):
      line = lineno
  return "" if line is None else f", line {line}"


def _load(path: str):
  """``get_config()`` of the config file ``path[:arg]``."""
  path, *arg = path.split(":", 1)
  spec = importlib.util.spec_from_file_location("_checked_config", path)
  module = importlib.util.module_from_spec(spec)
  spec.loader.exec_module(module)
  return module.get_config(*arg)


def check_files(flag_values, argv: list[str]) -> str | None:
  """The one-line problem of a given config file (missing, empty, not
  Python, failing when run), or None if every one loads."""
  for name in _config_flag_names(flag_values):
    given = _given(name, argv)
    if given is None:
      continue
    path = given.split(":", 1)[0]
    if not path:
      return f"--{name}=: empty; allowed: a config file, e.g. " \
             "experiments/configs/small.py"
    if not os.path.isfile(path):
      return f"--{name}={given}: no such file"
    try:
      with open(path) as f:
        compile(f.read(), path, "exec")
    except SyntaxError as e:
      return (f"--{name}={given}: {path}, line {e.lineno}: {e.msg}: "
              f"{(e.text or '').strip()!r}")
    except (OSError, UnicodeDecodeError, ValueError) as e:
      return f"--{name}={given}: cannot read {path}: {e}"
    try:
      config = _load(given)
    except Exception as e:  # pylint: disable=broad-except
      first = str(e).strip().splitlines()[0] if str(e).strip() else ""
      return (f"--{name}={given}: {path}{_where(e, path)}: "
              f"{type(e).__name__}: {first}")
    if config is None:
      return f"--{name}={given}: get_config() in {path} returned None"
  return None


def _unknown_field(config, dotted: str) -> str | None:
  """'config.a has no field b; nearest: c' for the first missing key of
  ``dotted`` (a.b.c) in ``config``, or None if the path exists."""
  node, where = config, []
  for key in dotted.split("."):
    keys = list(node.keys()) if hasattr(node, "keys") else []
    if key not in keys:
      owner = ".".join(["config"] + where)
      near = difflib.get_close_matches(key, [str(k) for k in keys], n=1)
      hint = (f"; did you mean {owner}.{near[0]}?" if near else
              f"; allowed: {sorted(str(k) for k in keys)}" if keys else
              f" ({owner} is a value, not a group)")
      return f"{owner} has no field {key!r}{hint}"
    node, where = node[key], where + [key]
  return None


def explain(flag_values, argv: list[str], error: Exception) -> str:
  """One line for a failed parse of ``argv`` that involves a config flag:
  the unknown override field and the nearest valid name, or the error."""
  for name in _config_flag_names(flag_values):
    given = _given(name, argv)
    overrides = [a for a in argv if re.match(rf"^--?(no)?{name}\.", a)]
    if given is None or not overrides:
      continue
    try:
      config = _load(given)
    except Exception:  # pylint: disable=broad-except
      continue  # check_files reports it
    for arg in overrides:
      dotted = re.sub(rf"^--?(no)?{name}\.", "", arg.split("=", 1)[0])
      problem = _unknown_field(config, dotted)
      if problem:
        return f"{arg}: {problem}"
  text = str(error).strip().strip("'\"").replace("\\n", " ")
  first = text.splitlines()[0] if text else ""
  return f"{type(error).__name__}: {first}"


def is_involved(flag_values, argv: list[str]) -> bool:
  """Whether ``argv`` gives a config flag (or an override of one)."""
  return any(_given(n, argv) is not None or
             any(re.match(rf"^--?(no)?{n}\.", a) for a in argv)
             for n in _config_flag_names(flag_values))

