"""Training across processes and hosts: settings, checks and start-up.

One process per host (or per accelerator), all started with the same
command but their own ``process_id``; process 0 runs the coordinator at
``coordinator`` (host:port). ``settings`` reads the flags, else the
variables a launcher sets (SLURM_NTASKS / SLURM_PROCID, or
GNSJAX_NUM_PROCESSES / GNSJAX_PROCESS_ID / GNSJAX_COORDINATOR);
``handshake`` checks, over a plain TCP connection to process 0 before
JAX's runtime starts, that the address works and that every process was
started with the same count and a distinct id (``jax.distributed.
initialize`` would otherwise wait minutes, then fail without saying why);
``initialize`` starts JAX's distributed runtime (CPU collectives over gloo)
and checks the count again.

Docs: docs/scaling.md.
"""

import dataclasses
import errno
import json
import os
import socket
import time
from typing import Mapping, Sequence

import jax
import numpy as np

from mpm import scene as mpm_scene

InputError = mpm_scene.InputError


@dataclasses.dataclass(frozen=True)
class Settings:
  """How this process takes part.

  Attributes:
    coordinator: "host:port" of process 0's coordinator (None alone).
    num_processes: processes in the run (1: alone, no runtime started).
    process_id: this process's rank, 0 <= process_id < num_processes.
  """
  coordinator: str | None = None
  num_processes: int = 1
  process_id: int = 0

  @property
  def multi(self) -> bool:
    return self.num_processes > 1


def _int(name: str, text: str) -> int:
  try:
    return int(text)
  except ValueError:
    raise InputError(f"{name}={text!r}; allowed: an integer") from None


def settings(coordinator: str | None = None,
             num_processes: int | None = None,
             process_id: int | None = None,
             environ: Mapping[str, str] | None = None) -> Settings:
  """This process's settings from the flags (None: not given), else from
  the environment (SLURM's, or GNSJAX_*).

  Raises:
    InputError: a value out of range, a flag without the others it needs,
      or a flag that contradicts the launcher's variable.
  """
  env = os.environ if environ is None else environ
  from_env = {}
  for key, names in (("num_processes", ("GNSJAX_NUM_PROCESSES",
                                        "SLURM_NTASKS")),
                     ("process_id", ("GNSJAX_PROCESS_ID", "SLURM_PROCID"))):
    for name in names:
      if env.get(name):
        from_env[key] = (name, _int(name, env[name]))
        break
  # A flag that disagrees with the launcher means a mistyped command line:
  # the processes would wait for each other forever.
  for key, flag in (("num_processes", num_processes),
                    ("process_id", process_id)):
    if flag is not None and key in from_env and from_env[key][1] != flag:
      name, value = from_env[key]
      raise InputError(f"--{key}={flag} but {name}={value}; allowed: the "
                       "same value (or leave the flag out)")
  if num_processes is None and "num_processes" in from_env:
    num_processes = from_env["num_processes"][1]
  if process_id is None and "process_id" in from_env:
    process_id = from_env["process_id"][1]
  if coordinator is None:
    coordinator = env.get("GNSJAX_COORDINATOR") or None
  if num_processes is None:
    if coordinator is not None or process_id is not None:
      given = "--coordinator" if coordinator is not None else "--process_id"
      raise InputError(f"{given} needs --num_processes (the number of "
                       "processes in the run); allowed: all three of "
                       "--coordinator, --num_processes, --process_id, or "
                       "none")
    return Settings()
  if num_processes < 1:
    raise InputError(f"--num_processes={num_processes}; allowed: >= 1")
  if num_processes == 1:
    if process_id not in (None, 0):
      raise InputError(f"--process_id={process_id}; allowed: 0 for "
                       "--num_processes=1")
    return Settings()
  if process_id is None:
    raise InputError(f"--num_processes={num_processes} needs --process_id; "
                     f"allowed: 0..{num_processes - 1}")
  if not 0 <= process_id < num_processes:
    raise InputError(f"--process_id={process_id}; allowed: "
                     f"0..{num_processes - 1} for --num_processes="
                     f"{num_processes}")
  if coordinator is None:
    raise InputError(f"--num_processes={num_processes} needs "
                     "--coordinator=host:port (process 0's host and a free "
                     "port), or GNSJAX_COORDINATOR")
  parse_address(coordinator)
  return Settings(coordinator, num_processes, process_id)


def parse_address(text: str) -> tuple[str, int]:
  """``"host:port"`` (``"[v6]:port"``) -> (host, port); InputError else."""
  host, sep, port = text.rpartition(":")
  host = host.strip("[]")
  if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
    raise InputError(f"--coordinator={text}; allowed: host:port with a port "
                     "1..65535 (e.g. node001:12355)")
  return host, int(port)


# First line of every handshake message: a stranger on the port is refused.
_HANDSHAKE = "gnsjax-handshake/1"
# How much longer than process 0 the others wait for its verdict (s).
_VERDICT_MARGIN_S = 10.0


def _send(sock: socket.socket, message: dict) -> None:
  sock.sendall((json.dumps(dict(message, protocol=_HANDSHAKE)) + "\n"
                ).encode())


def _receive(sock: socket.socket, timeout_s: float) -> dict | None:
  """One JSON line from ``sock``; None if it is not a handshake message.

  Raises:
    TimeoutError: no complete line within ``timeout_s``.
  """
  sock.settimeout(timeout_s)
  data = b""
  while not data.endswith(b"\n"):
    chunk = sock.recv(4096)
    if not chunk:
      break
    data += chunk
    if len(data) > 65536:
      return None
  try:
    message = json.loads(data.decode())
  except (UnicodeDecodeError, json.JSONDecodeError):
    return None
  if not isinstance(message, dict) or message.get("protocol") != _HANDSHAKE:
    return None
  return message


def _listen(s: Settings, family, address, flag: str) -> socket.socket:
  sock = socket.socket(family, socket.SOCK_STREAM)
  try:
    sock.bind(address)
  except OSError as e:
    sock.close()
    why = {errno.EADDRINUSE: "the port is in use",
           errno.EADDRNOTAVAIL: f"{address[0]!r} is not an address of this "
                                "host, but process 0 runs the coordinator"
           }.get(e.errno, e.strerror)
    raise InputError(f"{flag}: {why}; allowed: this host's name or address "
                     "and a free port") from None
  sock.listen(max(8, s.num_processes))
  return sock


def _gather(s: Settings, server: socket.socket, timeout_s: float) -> None:
  """Process 0: a hello from every other process, then one answer to all.

  Every process hears the same verdict: "ok", or the first mismatch found
  (the moment it arrives, without waiting for the rest).
  """
  deadline = time.monotonic() + timeout_s
  connections, ids = [], set()
  error = None
  try:
    while len(ids) < s.num_processes - 1 and error is None:
      left = deadline - time.monotonic()
      if left <= 0:
        missing = sorted(set(range(1, s.num_processes)) - ids)
        error = (f"process(es) {missing} did not connect within "
                 f"{timeout_s:g} s; allowed: every process started with "
                 f"--num_processes={s.num_processes} and this --coordinator")
        break
      server.settimeout(left)
      try:
        conn, _ = server.accept()
      except TimeoutError:
        continue
      try:
        hello = _receive(conn, min(left, 10.0))
      except OSError:
        hello = None
      if hello is None:
        conn.close()  # not one of ours: ignore it
        continue
      connections.append(conn)
      n, i = hello.get("num_processes"), hello.get("process_id")
      if n != s.num_processes:
        error = (f"process {i} was started with --num_processes={n}, "
                 f"process 0 with --num_processes={s.num_processes}; "
                 "allowed: the same --num_processes in every process")
      elif i in ids or i == 0:
        error = (f"two processes were started with --process_id={i}; "
                 f"allowed: distinct ids 0..{s.num_processes - 1}")
      ids.add(i)
    for conn in connections:
      try:
        _send(conn, {"ok": error is None, "error": error})
        # Wait for the peer to close first, so the port is left free of
        # TIME_WAIT sockets for JAX's coordinator.
        _receive(conn, 5.0)
      except OSError:
        pass
  finally:
    for conn in connections:
      conn.close()
  if error is not None:
    raise InputError(f"--coordinator={s.coordinator}: {error}")


def _hello(s: Settings, address, flag: str, wait_s: float,
           connect_timeout_s: float, timeout_s: float) -> None:
  """A process other than 0: connect (until ``wait_s`` pass), say who it
  is, and wait for process 0's verdict."""
  deadline = time.monotonic() + wait_s
  while True:
    try:
      conn = socket.create_connection(address[:2], timeout=connect_timeout_s)
      break
    except OSError as e:
      why = e.strerror or type(e).__name__
    if time.monotonic() >= deadline:
      raise InputError(
          f"{flag}: nothing answers there after {wait_s:g} s ({why}); "
          "allowed: the host:port where process 0 (started with "
          "--process_id=0) runs")
    time.sleep(min(1.0, connect_timeout_s))
  with conn:
    try:
      _send(conn, {"num_processes": s.num_processes,
                   "process_id": s.process_id})
      # Longer than process 0's own timeout, so that its verdict (which
      # names a missing process) arrives before this process gives up.
      verdict = _receive(conn, timeout_s + _VERDICT_MARGIN_S)
    except (TimeoutError, OSError) as e:
      raise InputError(f"{flag}: process 0 gave no answer within "
                       f"{timeout_s + _VERDICT_MARGIN_S:g} s ({e}); allowed: "
                       "every process started with the same "
                       "--num_processes") from None
  if verdict is None:
    raise InputError(f"{flag}: something other than process 0 of this run "
                     "answers there; allowed: the host:port where process 0 "
                     "(started with --process_id=0) runs")
  if not verdict.get("ok"):
    raise InputError(f"{flag}: {verdict.get('error')}")


def handshake(s: Settings, wait_s: float = 60.0, timeout_s: float = 300.0,
              connect_timeout_s: float = 2.0) -> None:
  """Fails fast, before JAX's runtime starts, on a run that cannot work.

  Process 0 listens on the coordinator's address (so the host must be one
  of its own and the port free) until every other process has said its
  ``num_processes`` and ``process_id``; the others connect (retrying for
  ``wait_s``: the processes need not start at the same moment) and wait
  for the verdict. A mismatched process count or a duplicate id is named to
  every process that connected as soon as it is seen; then the port is
  given back and ``initialize`` may start the coordinator there. (JAX's own
  runtime would wait its whole timeout, then fail without saying why.)

  Raises:
    InputError: naming the address and what is wrong.
  """
  if not s.multi:
    return
  host, port = parse_address(s.coordinator)
  flag = f"--coordinator={s.coordinator}"
  try:
    infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
  except socket.gaierror as e:
    raise InputError(f"{flag}: cannot resolve host {host!r} ({e.strerror}); "
                     "allowed: process 0's host name or address") from None
  family, _, _, _, address = infos[0]
  if s.process_id == 0:
    with _listen(s, family, address, flag) as server:
      _gather(s, server, timeout_s)
  else:
    _hello(s, address, flag, wait_s, connect_timeout_s, timeout_s)


def initialize(s: Settings, timeout_s: int = 300,
               heartbeat_timeout_s: int = 100) -> None:
  """Starts JAX's distributed runtime (nothing alone) and checks that it
  sees ``s.num_processes`` processes with this one at ``s.process_id``.

  Must run before JAX touches a device. On CPU the collectives go over
  gloo. A process whose heartbeats stop for ``heartbeat_timeout_s``
  (JAX's default 100 s: it died, or stalls) is declared dead, and every
  process aborts (SIGABRT).

  Raises:
    InputError: the processes did not all connect within ``timeout_s``
      (a process missing, or started with another --num_processes), or the
      runtime's count or rank differ from the flags.
  """
  if not s.multi:
    return
  from jax._src import xla_bridge  # pylint: disable=g-import-not-at-top
  if xla_bridge.backends_are_initialized():
    # A bug, not bad input: something (a computation, or a module that
    # computes at import) touched a device first.
    raise RuntimeError("distributed.initialize: JAX's backend is already "
                       "initialised; call it before importing gnsjax.train")
  jax.config.update("jax_cpu_collectives_implementation", "gloo")
  try:
    jax.distributed.initialize(
        s.coordinator, s.num_processes, s.process_id,
        initialization_timeout=timeout_s,
        heartbeat_timeout_seconds=heartbeat_timeout_s)
  except Exception as e:  # pylint: disable=broad-except
    # JAX raises its runtime's error types; the cause is in the text.
    first = str(e).strip().splitlines()[0] if str(e).strip() else repr(e)
    raise InputError(
        f"--coordinator={s.coordinator}: the {s.num_processes} processes "
        f"did not all connect within {timeout_s} s ({first[:200]}); allowed: "
        "every process started, all with the same --num_processes and "
        "--coordinator and distinct --process_id") from e
  if (jax.process_count(), jax.process_index()) != (s.num_processes,
                                                    s.process_id):
    raise InputError(
        f"--num_processes={s.num_processes} --process_id={s.process_id}, "
        f"but the runtime has {jax.process_count()} processes with this one "
        f"at {jax.process_index()}; allowed: the same --num_processes in "
        "every process")
  high, low = agree_max((s.num_processes, -s.num_processes))
  if (high, -low) != (s.num_processes, s.num_processes):
    raise InputError(
        f"--num_processes={s.num_processes}, but the processes were started "
        f"with {-low} to {high}; allowed: the same --num_processes in every "
        "process")


def check_supported(config, num_processes: int) -> None:
  """Refuses a training config (``experiments/configs``) that does not
  work split over ``num_processes`` processes.

  Raises:
    InputError: the batch does not split evenly, or the config asks for
      pushforward, rest pushforward, unrolled training or on-device
      windows, which run on one process only (they build graphs or gather
      windows from the whole batch).
  """
  tcfg = config.get("train")
  if tcfg is None or "batch_size" not in tcfg:
    return  # not a training config: check_config names what is missing
  if tcfg.batch_size % num_processes:
    raise InputError(f"config.train.batch_size = {tcfg.batch_size} with "
                     f"--num_processes={num_processes}; allowed: a multiple "
                     "of the process count")
  if num_processes == 1:
    return
  # (the key named, whether the option is on, what runs in one process,
  # the allowed value)
  one_process = (
      ("pushforward_probability",
       tcfg.pushforward_probability > 0 and tcfg.pushforward_steps > 0,
       "pushforward training runs", "0"),
      ("rest_pushforward_steps",
       tcfg.rest_pushforward_probability > 0 and
       tcfg.rest_pushforward_steps > 0, "the rest pushforward runs", "0"),
      ("unroll_probability",
       tcfg.unroll_probability > 0 and tcfg.unroll_steps > 0,
       "unrolled training runs", "0"),
      ("device_windows", tcfg.device_windows, "on-device windows run",
       "False"),
  )
  for key, used, what, allowed in one_process:
    if used:
      raise InputError(
          f"config.train.{key} = {tcfg[key]} with --num_processes="
          f"{num_processes}: {what} on one process only; allowed: "
          f"{key} = {allowed} (or one process)")


def agree_max(values: Sequence[int]) -> tuple[int, ...]:
  """The elementwise maximum of ``values`` over all processes (int32; the
  values themselves in one process). Every process must call it."""
  if jax.process_count() == 1:
    return tuple(int(v) for v in values)
  # pylint: disable-next=g-import-not-at-top
  from jax.experimental import multihost_utils
  gathered = multihost_utils.process_allgather(np.asarray(values, np.int32))
  return tuple(int(v) for v in np.max(np.asarray(gathered), axis=0))


def agree_any(flag: bool) -> bool:
  """Whether ``flag`` holds in any process."""
  return bool(agree_max((int(flag),))[0])


def process_rows(x: jax.Array) -> np.ndarray:
  """This process's rows of a batch-sharded global array, on the host."""
  shards = sorted(x.addressable_shards, key=lambda s: s.index[0].start or 0)
  return np.concatenate([np.asarray(s.data) for s in shards])


def from_process_0(value: float) -> float:
  """Process 0's ``value`` (a float or bool) in every process."""
  if jax.process_count() == 1:
    return value
  # pylint: disable-next=g-import-not-at-top
  from jax.experimental import multihost_utils
  got = multihost_utils.broadcast_one_to_all(np.float32(value))
  return type(value)(np.asarray(got).item())
