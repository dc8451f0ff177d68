"""Tests for `gnsjax.distributed` and training across processes.

Two processes on localhost (CPU collectives over gloo) train with the same
global batch as one process, and must give its losses.
"""

import csv
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time

from absl.testing import absltest
from absl.testing import parameterized
import numpy as np
import pytest

from gnsjax import distributed
from gnsjax import train
from tests.gnsjax import fixtures

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(__file__)))
CACHE = os.path.join(ROOT, ".jax_cache")


def _losses(workdir):
  with open(os.path.join(workdir, "metrics.csv"), newline="") as f:
    return [(int(r["step"]), float(r["loss"])) for r in csv.DictReader(f)]


def _free_port() -> int:
  with socket.socket() as s:
    s.bind(("127.0.0.1", 0))
    return s.getsockname()[1]


def _train_argv(data: str, workdir: str, num_steps: int) -> list[str]:
  """experiments.train with the test config, made ``fixtures.tiny_config``
  on the command line."""
  spec = fixtures.SPEC
  return [sys.executable, "-m", "experiments.train",
          "--config=experiments/configs/test.py", f"--data={data}",
          f"--workdir={workdir}",
          f"--config.dataset.num_train={spec.num_train}",
          f"--config.dataset.num_test={spec.num_test}",
          f"--config.dataset.num_frames={spec.num_frames}",
          f"--config.dataset.seed={spec.seed}",
          f"--config.dataset.spacing={spec.spacing}",
          f"--config.dataset.connectivity_radius={spec.connectivity_radius}",
          "--config.model.num_message_passing_steps=1",
          "--config.train.node_bucket=32", "--config.eval.every_steps=0",
          f"--config.train.num_steps={num_steps}", "--config.log_every=1",
          "--config.checkpoint.every_steps=4"]


def _start_two(data, workdir, num_steps, port, log_dir,
               heartbeat_timeout_s=900):
  """The two processes of ``experiments.train``, logging into ``log_dir``.

  The heartbeat timeout is well above JAX's 100 s: in CI once, on a
  machine about 10 times slower than usual (the reference's first step
  took 409 s), both processes aborted (SIGABRT), as they do when one
  misses its heartbeats; the log's end kept only the stack dump.
  """
  env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu",
             GNSJAX_CACHE_DIR=CACHE)
  procs = []
  for i in range(2):
    log = open(os.path.join(log_dir, f"process{i}.log"), "a")
    procs.append(subprocess.Popen(
        _train_argv(data, workdir, num_steps) + [
            f"--coordinator=127.0.0.1:{port}", "--num_processes=2",
            f"--process_id={i}",
            f"--heartbeat_timeout_s={heartbeat_timeout_s}"],
        env=env, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT))
    log.close()
  return procs


def _tail(log_dir):
  """Each process's errors (glog's E and F lines: the cause of an abort,
  which a stack dump follows) and the end of its log."""
  texts = []
  for i in range(2):
    text = open(os.path.join(log_dir, f"process{i}.log")).read()
    errors = re.findall(r"^[EF]\d{4} .*$", text, re.MULTILINE)
    texts.append(f"process {i}:\n" + "\n".join(errors[-10:]) +
                 "\n...\n" + text[-1500:])
  return "\n".join(texts)


def _reference(data, workdir, num_steps):
  """The same run in one process (this one)."""
  config = fixtures.tiny_config(num_steps=num_steps)
  config.log_every = 1
  config.checkpoint.every_steps = 4
  train.train_and_evaluate(config, data, workdir)
  return _losses(workdir)


class TwoProcessTrainingTest(fixtures.TinyRunTestCase):

  def assert_losses_equal(self, got, want):
    self.assertEqual([s for s, _ in got], [s for s, _ in want])
    np.testing.assert_allclose([l for _, l in got], [l for _, l in want],
                               rtol=1e-6)

  def test_two_processes_match_one(self):
    steps = 2
    # One after the other: three JAX processes compiling at once beside
    # pytest's other worker starve each other on a 2-core machine.
    want = _reference(self.data, os.path.join(self.dir, "one"), steps)
    workdir = os.path.join(self.dir, "two")
    procs = _start_two(self.data, workdir, steps, _free_port(), self.dir)
    codes = [p.wait(timeout=600) for p in procs]
    self.assertEqual(codes, [0, 0], _tail(self.dir))
    self.assert_losses_equal(_losses(workdir), want)
    # One log, one checkpoint (written once, by both processes' orbax), one
    # trainer's lock (process 0's).
    self.assertEqual(os.listdir(os.path.join(workdir, "checkpoints")), ["2"])
    self.assertCountEqual(
        os.listdir(workdir),
        ["checkpoints", "config.json", "metrics.csv", "stats.json",
         "tensorboard", "trainer.lock"])

  @pytest.mark.slow
  def test_kill_9_of_one_process_then_restart_of_both_resumes_exactly(self):
    steps = 12
    want = _reference(self.data, os.path.join(self.dir, "one"), steps)
    workdir = os.path.join(self.dir, "two")
    procs = _start_two(self.data, workdir, steps, _free_port(), self.dir)
    ckpts = os.path.join(workdir, "checkpoints")
    deadline = time.time() + 600
    while time.time() < deadline and procs[1].poll() is None:
      if os.path.isdir(ckpts) and any(d.isdigit() and int(d) >= 4
                                      for d in os.listdir(ckpts)):
        break
      time.sleep(0.1)
    procs[1].send_signal(signal.SIGKILL)
    procs[1].wait()
    # Its partner waits in a collective for the dead one; a launcher ends
    # the whole job, as this does.
    try:
      procs[0].wait(timeout=10)
    except subprocess.TimeoutExpired:
      procs[0].send_signal(signal.SIGKILL)
      procs[0].wait()
    restart_from = max(int(d) for d in os.listdir(ckpts) if d.isdigit())
    self.assertLess(restart_from, steps, "finished before the kill")
    procs = _start_two(self.data, workdir, steps, _free_port(), self.dir)
    codes = [p.wait(timeout=600) for p in procs]
    self.assertEqual(codes, [0, 0], _tail(self.dir))
    self.assert_losses_equal(_losses(workdir), want)  # no step twice


class HeartbeatTest(fixtures.TinyRunTestCase):

  @pytest.mark.slow
  def test_a_silent_process_ends_both_after_the_heartbeat_timeout(self):
    procs = _start_two(self.data, os.path.join(self.dir, "two"), 2,
                       _free_port(), self.dir, heartbeat_timeout_s=5)
    for p in procs:
      self.addCleanup(p.kill)
    log = os.path.join(self.dir, "process1.log")
    deadline = time.time() + 300
    while "Gloo" not in open(log).read():  # the runtime has started
      self.assertLess(time.time(), deadline, _tail(self.dir))
      self.assertIsNone(procs[1].poll(), _tail(self.dir))
      time.sleep(0.1)
    procs[1].send_signal(signal.SIGSTOP)
    try:
      code0 = procs[0].wait(timeout=60)  # 5 s of silence, not JAX's 100
    finally:
      procs[1].send_signal(signal.SIGCONT)
    self.assertEqual(code0, -signal.SIGABRT, _tail(self.dir))
    self.assertIn("stopped sending heartbeats", _tail(self.dir))
    self.assertFalse(os.path.exists(os.path.join(self.dir, "two",
                                                 "checkpoints", "2")))


class SettingsTest(parameterized.TestCase):

  def test_alone_by_default(self):
    self.assertEqual(distributed.settings(environ={}), distributed.Settings())
    self.assertFalse(distributed.settings(environ={}).multi)

  def test_flags_and_environment(self):
    s = distributed.settings("h:1", 2, 1, environ={})
    self.assertEqual(s, distributed.Settings("h:1", 2, 1))
    slurm = {"SLURM_NTASKS": "4", "SLURM_PROCID": "3",
             "GNSJAX_COORDINATOR": "node1:12355"}
    self.assertEqual(distributed.settings(environ=slurm),
                     distributed.Settings("node1:12355", 4, 3))
    # The flag may repeat what the launcher says.
    self.assertEqual(distributed.settings("n:2", 4, environ=slurm),
                     distributed.Settings("n:2", 4, 3))

  @parameterized.named_parameters(
      ("id_out_of_range", ("h:1", 2, 2), {},
       "--process_id=2; allowed: 0..1 for --num_processes=2"),
      ("negative_id", ("h:1", 2, -1), {}, "--process_id=-1; allowed: 0..1"),
      ("no_id", ("h:1", 2, None), {}, "needs --process_id"),
      ("no_coordinator", (None, 2, 0), {}, "needs --coordinator=host:port"),
      ("no_count", ("h:1", None, 0), {}, "--coordinator needs --num_processes"),
      ("zero_processes", ("h:1", 0, 0), {}, "--num_processes=0; allowed: >= 1"),
      ("malformed_address", ("h", 2, 0), {}, "--coordinator=h; allowed: "
       "host:port"),
      ("port_out_of_range", ("h:70000", 2, 0), {}, "a port 1..65535"),
      ("count_against_slurm", ("h:1", 2, 0), {"SLURM_NTASKS": "4"},
       "--num_processes=2 but SLURM_NTASKS=4; allowed: the same value"),
      ("rank_against_slurm", ("h:1", 4, 0), {"SLURM_NTASKS": "4",
                                             "SLURM_PROCID": "1"},
       "--process_id=0 but SLURM_PROCID=1"),
      ("bad_variable", (None, None, None), {"GNSJAX_NUM_PROCESSES": "two"},
       "GNSJAX_NUM_PROCESSES='two'; allowed: an integer"),
  )
  def test_refused(self, args, environ, message):
    with self.assertRaises(distributed.InputError) as e:
      distributed.settings(*args, environ=environ)
    self.assertIn(message, str(e.exception))

  def test_unresolvable_coordinator(self):
    s = distributed.Settings("no-such-host.invalid:1234", 2, 1)
    with self.assertRaisesRegex(distributed.InputError,
                                "cannot resolve host 'no-such-host.invalid'"):
      distributed.handshake(s)

  def test_nothing_listening_fails_after_the_wait(self):
    s = distributed.Settings(f"127.0.0.1:{_free_port()}", 2, 1)
    start = time.monotonic()
    with self.assertRaisesRegex(distributed.InputError,
                                "nothing answers there after 0.3 s"):
      distributed.handshake(s, wait_s=0.3, connect_timeout_s=0.1)
    self.assertLess(time.monotonic() - start, 5)

  def test_process_0_needs_a_free_port_of_its_host(self):
    with socket.socket() as taken:
      taken.bind(("127.0.0.1", 0))
      taken.listen()
      port = taken.getsockname()[1]
      with self.assertRaisesRegex(distributed.InputError,
                                  "the port is in use"):
        distributed.handshake(distributed.Settings(f"127.0.0.1:{port}", 2, 0))
    s = distributed.Settings("192.0.2.1:12355", 2, 0)  # TEST-NET-1
    with self.assertRaisesRegex(distributed.InputError,
                                "not an address of this host"):
      distributed.handshake(s)


  def test_uneven_batch_is_refused(self):
    config = fixtures.tiny_config(batch_size=2)
    distributed.check_supported(config, 2)
    with self.assertRaisesRegex(distributed.InputError,
                                "batch_size = 2 with --num_processes=3"):
      distributed.check_supported(config, 3)

  @parameterized.named_parameters(
      ("pushforward", dict(pushforward_steps=1, pushforward_probability=0.5),
       "pushforward training runs on one process"),
      # It rolled the whole global batch out in each process and failed on
      # the first still window with an assertion of jax's.
      ("rest_pushforward", dict(rest_pushforward_steps=2,
                                rest_pushforward_probability=1.0),
       "rest pushforward runs on one process"),
      ("unrolled", dict(unroll_steps=2, unroll_probability=0.5),
       "unrolled training runs on one process"),
      ("device_windows", dict(device_windows=True),
       "on-device windows run on one process"),
  )
  def test_one_process_options_are_refused(self, train_keys, message):
    config = fixtures.tiny_config(**train_keys)
    distributed.check_supported(config, 1)
    with self.assertRaisesRegex(distributed.InputError, message):
      distributed.check_supported(config, 2)


def _handshakes(counts_and_ids, timeout_s=30.0):
  """Runs ``handshake`` for (num_processes, process_id) pairs at once (the
  first is process 0); returns each one's error text (None: passed) and the
  seconds until the last one ended."""
  port = _free_port()
  results = [None] * len(counts_and_ids)

  def one(k, n, i):
    try:
      distributed.handshake(
          distributed.Settings(f"127.0.0.1:{port}", n, i), wait_s=10,
          timeout_s=timeout_s, connect_timeout_s=0.2)
    except distributed.InputError as e:
      results[k] = str(e)

  start = time.monotonic()
  threads = [threading.Thread(target=one, args=(k, n, i))
             for k, (n, i) in enumerate(counts_and_ids)]
  for t in threads:
    t.start()
  for t in threads:
    t.join(60)
  return results, time.monotonic() - start, port


class HandshakeTest(absltest.TestCase):
  """Process 0 and the others agree on the run before JAX's runtime starts
  (threads on localhost stand in for processes)."""

  def test_agreeing_processes_pass_and_leave_the_port_free(self):
    results, _, port = _handshakes([(3, 0), (3, 1), (3, 2)])
    self.assertEqual(results, [None, None, None])
    with socket.socket() as s:  # JAX's coordinator can listen there now
      s.bind(("127.0.0.1", port))

  def test_mismatched_process_counts_fail_fast_everywhere(self):
    for counts in ([(2, 0), (3, 1)], [(3, 0), (2, 1)]):
      results, seconds, _ = _handshakes(counts)
      self.assertLess(seconds, 10, "waited for a timeout")
      for text in results:
        self.assertIn(f"process 1 was started with --num_processes="
                      f"{counts[1][0]}, process 0 with --num_processes="
                      f"{counts[0][0]}", text)
        self.assertIn("allowed: the same --num_processes", text)

  def test_duplicate_ids_fail(self):
    results, seconds, _ = _handshakes([(3, 0), (3, 1), (3, 1)])
    self.assertLess(seconds, 10)
    for text in results:
      self.assertIn("two processes were started with --process_id=1", text)

  def test_a_missing_process_is_named_after_the_timeout(self):
    results, _, _ = _handshakes([(3, 0), (3, 2)], timeout_s=0.5)
    self.assertIn("process(es) [1] did not connect within 0.5 s", results[0])
    self.assertIn("process(es) [1] did not connect", results[1])

  def test_a_stranger_on_the_port_is_ignored(self):
    port = _free_port()
    errors = []

    def process_0():
      try:
        distributed.handshake(distributed.Settings(f"127.0.0.1:{port}", 2, 0),
                              timeout_s=20)
      except distributed.InputError as e:
        errors.append(str(e))

    thread = threading.Thread(target=process_0)
    thread.start()
    deadline = time.monotonic() + 10
    while True:
      try:
        stranger = socket.create_connection(("127.0.0.1", port), timeout=1)
        break
      except OSError:
        self.assertLess(time.monotonic(), deadline)
        time.sleep(0.05)
    with stranger:
      stranger.sendall(b"GET / HTTP/1.0\r\n\r\n")
    distributed.handshake(distributed.Settings(f"127.0.0.1:{port}", 2, 1),
                          wait_s=5)
    thread.join(30)
    self.assertEqual(errors, [])


class EntryPointTest(fixtures.TinyRunTestCase):

  def test_mismatched_process_count_fails_fast_and_writes_nothing(self):
    port = _free_port()
    workdir = os.path.join(self.dir, "run")
    env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu",
               GNSJAX_CACHE_DIR=CACHE)
    # A batch that splits over 2 and over 3 processes: only the count is
    # wrong.
    procs = [subprocess.Popen(
        _train_argv(self.data, workdir, 2) + [
            "--config.train.batch_size=6", f"--coordinator=127.0.0.1:{port}",
            f"--num_processes={n}", f"--process_id={i}"],
        env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True) for n, i in ((2, 0), (3, 1))]
    for p in procs:
      self.addCleanup(p.kill)
    outputs = [p.communicate(timeout=120)[0] for p in procs]
    self.assertEqual([p.returncode for p in procs], [2, 2], outputs)
    for out in outputs:
      self.assertIn("process 1 was started with --num_processes=3, process "
                    "0 with --num_processes=2", out)
    self.assertFalse(os.path.exists(workdir))


if __name__ == "__main__":
  absltest.main()
