"""Every entry point refuses bad input in one line with exit code 2, before
it creates anything (and before any compilation: each row takes seconds)."""

import glob
import json
import os
import shutil
import subprocess
import sys
import tempfile

from absl.testing import absltest
from absl.testing import parameterized
import numpy as np

import mpm
from mpm import io as mpm_io
from tests.experiments import entry_points_test
from tests.experiments import forked

ROOT = entry_points_test.ROOT
# The shipped model's checkpoint step (damaged in a copy below).
SHIPPED_STEP = max(os.listdir(os.path.join(
    ROOT, "experiments", "pretrained", "small", "checkpoints")), key=int)
SMALL = "--config=experiments/configs/small.py"
TEST = "--config=experiments/configs/test.py"
_TEST_SPEC = {"num_train": 3, "num_test": 7, "num_frames": 20, "seed": 0,
              "spacing": 0.01, "connectivity_radius": 0.03}


def run(*args):
  """Runs ``python -m args``; returns (returncode, stdout, stderr)."""
  env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu",
             GNSJAX_CACHE_DIR=os.path.join(ROOT, ".jax_cache"))
  proc = subprocess.run([sys.executable, "-m", *args], env=env, cwd=ROOT,
                        capture_output=True, text=True, timeout=120)
  return proc.returncode, proc.stdout, proc.stderr


def server() -> forked.Server:
  """``run``'s processes as forks of one that has imported the libraries
  (each row then starts in a fraction of a second; tests/experiments/
  forked.py)."""
  return forked.Server(ROOT, dict(
      os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu",
      GNSJAX_CACHE_DIR=os.path.join(ROOT, ".jax_cache")))


# (name, module, argv, expected in the message). In argv, {d} is a fresh
# directory holding: tiny.json (a valid tiny scene), stiff.json (the same
# with E = 1e12 Pa), bad.json (an unknown obstacle shape), fine.json (the
# paper's box at a 20 um spacing), long.json (10^8 frames), syntax.py (a
# config file with a syntax error on line 2), damaged/ (a run whose
# checkpoint lost its data files), traj.h5 (a
# 3-frame trajectory), a_file (a plain file), ds/train.h5 (what --data
# needs), other/metadata.json (a finished dataset of another config),
# parts/parts/spec.json (an unfinished one). No
# row may create {d}/out, or anything else (item 9); every row answers in one
# line with exit code 2 (item 10).
ROWS = (
    # Item 2: --compare is read, and a missing one is named.
    ("render_missing_compare", "experiments.render",
     ["--traj={d}/traj.h5", "--compare={d}/missing.h5", "--out={d}/out"],
     "--compare={d}/missing.h5: no such file"),
    ("render_not_a_trajectory", "experiments.render",
     ["--traj={d}/tiny.json", "--out={d}/out"], "not a readable HDF5 file"),
    # Item 3: another config's dataset, finished or not.
    ("generate_into_another_dataset", "experiments.generate_dataset",
     [TEST, "--out={d}/other", "--config.dataset.num_train=2"],
     "holds a dataset of another config: its num_train 5 (this config: 2)"),
    ("generate_into_other_parts", "experiments.generate_dataset",
     [TEST, "--out={d}/parts"],
     "holds an unfinished dataset of another config: its num_frames 8"),
    ("generate_no_train", "experiments.generate_dataset",
     [TEST, "--out={d}/out", "--config.dataset.num_train=0"],
     "dataset.num_train = 0; allowed: an integer >= 1"),
    ("generate_malformed_shard", "experiments.generate_dataset",
     [TEST, "--out={d}/out", "--shard=2/2"],
     "--shard=2/2; allowed: i/N with integers N >= 1 and 0 <= i < N"),
    ("generate_shard_not_a_fraction", "experiments.generate_dataset",
     [TEST, "--out={d}/out", "--shard=half"], "--shard=half; allowed: i/N"),
    ("generate_shard_and_assemble", "experiments.generate_dataset",
     [TEST, "--out={d}/out", "--shard=0/2", "--assemble"],
     "--shard=0/2 with --assemble; allowed: one of them"),
    ("assemble_missing_parts", "experiments.generate_dataset",
     [TEST, "--out={d}", "--assemble"],
     "--assemble: 10 of 10 parts are missing in {d}/parts"),
    ("generate_without_config", "experiments.generate_dataset",
     ["--out={d}/out"], "--config is required to generate"),
    ("verify_missing", "experiments.generate_dataset",
     [TEST, "--out={d}/out", "--verify"],
     "--out={d}/out: no such directory"),
    # Item 4: an output that cannot be written is refused before simulating.
    ("simulate_out_under_a_file", "experiments.simulate",
     ["--scene={d}/tiny.json", "--out={d}/a_file/out/traj.h5"],
     "--out={d}/a_file/out/traj.h5: {d}/a_file is a file"),
    # Item 6: every flag named with its value and what is allowed.
    ("render_frames_not_integers", "experiments.render",
     ["--traj={d}/traj.h5", "--out={d}/out", "--frames=abc"],
     "--frames=['abc']: expected comma-separated frame indices"),
    ("render_frames_out_of_range", "experiments.render",
     ["--traj={d}/traj.h5", "--out={d}/out", "--frames=0,50"],
     "allowed: comma-separated frame indices in [0, 2]"),
    ("render_index", "experiments.render",
     ["--traj={d}/traj.h5", "--out={d}/out", "--index=1"],
     "index=1: {d}/traj.h5 holds 1 trajectories; allowed: 0..0"),
    ("rollout_max_trajectories", "experiments.rollout",
     ["--workdir={d}", "--data={d}", "--out={d}/out", "--max_trajectories=0"],
     "--max_trajectories=0"),
    ("rollout_missing_workdir", "experiments.rollout",
     ["--workdir={d}/run", "--data={d}", "--out={d}/out"],
     "--workdir={d}/run: no such directory"),
    ("evaluate_no_checkpoint", "experiments.evaluate",
     ["--workdir={d}", "--data={d}", "--out={d}/out"],
     "--workdir={d}: no checkpoints in it"),
    ("average_runs_weights", "experiments.average_runs",
     ["--workdirs=experiments/pretrained/small,experiments/pretrained/small",
      "--weights=0.5,0.4", "--out={d}/out"],
     "weights must sum to 1; got [0.5, 0.4]"),
    ("average_runs_missing_run", "experiments.average_runs",
     ["--workdirs=experiments/pretrained/small,{d}/run", "--out={d}/out"],
     "--workdirs={d}/run: no such directory"),
    ("train_missing_data", "experiments.train",
     [SMALL, "--data={d}/data", "--workdir={d}/out"],
     "--data={d}/data: no such directory"),
    # Training across processes: refused before anything starts.
    ("train_process_id_out_of_range", "experiments.train",
     [TEST, "--data={d}/ds", "--workdir={d}/out", "--coordinator=localhost:1",
      "--num_processes=2", "--process_id=2"],
     "--process_id=2; allowed: 0..1 for --num_processes=2"),
    ("train_coordinator_malformed", "experiments.train",
     [TEST, "--data={d}/ds", "--workdir={d}/out", "--coordinator=localhost",
      "--num_processes=2", "--process_id=1"],
     "--coordinator=localhost; allowed: host:port"),
    ("train_coordinator_unresolvable", "experiments.train",
     [TEST, "--data={d}/ds", "--workdir={d}/out",
      "--coordinator=no-such-host.invalid:12355", "--num_processes=2",
      "--process_id=1"],
     "cannot resolve host 'no-such-host.invalid'"),
    ("train_coordinator_unreachable", "experiments.train",
     [TEST, "--data={d}/ds", "--workdir={d}/out", "--coordinator=127.0.0.1:9",
      "--num_processes=2", "--process_id=1", "--coordinator_wait_s=0.5"],
     "--coordinator=127.0.0.1:9: nothing answers there after 0.5 s"),
    ("train_coordinator_not_this_host", "experiments.train",
     [TEST, "--data={d}/ds", "--workdir={d}/out",
      "--coordinator=192.0.2.1:12355", "--num_processes=2", "--process_id=0"],
     "'192.0.2.1' is not an address of this host"),
    ("train_processes_without_coordinator", "experiments.train",
     [TEST, "--data={d}/ds", "--workdir={d}/out", "--num_processes=2",
      "--process_id=0"], "--num_processes=2 needs --coordinator=host:port"),
    ("train_batch_over_processes", "experiments.train",
     [TEST, "--data={d}/ds", "--workdir={d}/out", "--coordinator=localhost:1",
      "--num_processes=3", "--process_id=0"],
     "config.train.batch_size = 2 with --num_processes=3; allowed: a "
     "multiple of the process count"),
    ("train_pushforward_over_processes", "experiments.train",
     [TEST, "--data={d}/ds", "--workdir={d}/out", "--coordinator=localhost:1",
      "--num_processes=2", "--process_id=0",
      "--config.train.pushforward_steps=2",
      "--config.train.pushforward_probability=0.5"],
     "pushforward training runs on one process only"),
    ("train_device_windows_over_processes", "experiments.train",
     [TEST, "--data={d}/ds", "--workdir={d}/out", "--coordinator=localhost:1",
      "--num_processes=2", "--process_id=0",
      "--config.train.device_windows=True"],
     "on-device windows run on one process only"),
    ("simulate_missing_scene", "experiments.simulate",
     ["--scene={d}/missing.json", "--out={d}/out/traj.h5"],
     "--scene={d}/missing.json: no such file"),
    ("simulate_scene_and_seed", "experiments.simulate",
     ["--scene={d}/tiny.json", "--seed=1", "--out={d}/out/traj.h5"],
     "exactly one of --scene and --seed"),
    ("simulate_bad_scene", "experiments.simulate",
     ["--scene={d}/bad.json", "--out={d}/out/traj.h5"],
     "obstacles[0].shape: unknown shape 'hexagon'"),
    ("demo_num_frames", "experiments.demo",
     ["--out={d}/out", "--num_frames=5"], "--num_frames=5"),
    ("ablation_variants", "experiments.ablation",
     ["--data={d}", "--out={d}/out", "--variants=previous,nope"],
     "--variants=nope: allowed: one of ['previous', 'stride3'"),
    ("benchmarks_what", "experiments.benchmarks",
     ["--what=nope", "--out={d}/out"], "--what=nope"),
    ("inverse_design_size", "experiments.inverse_design",
     ["--out={d}/out", "--simulator=mpm", "--workdir=", "--size=abc"],
     "--size=abc; allowed: comma-separated numbers"),
    ("inverse_design_size_count", "experiments.inverse_design",
     ["--out={d}/out", "--simulator=mpm", "--workdir=", "--size=0.03,0.04"],
     "--size=0.03,0.04: a semicircle needs ['radius']"),
    # Item 7: one range for --x0, below or above it.
    ("inverse_design_x0_low", "experiments.inverse_design",
     ["--out={d}/out", "--x0=0.3"], "--x0=0.3; allowed: [0.5, 1.3] m"),
    ("stability_unknown_case", "experiments.stability",
     ["--out={d}/out", "--only=nope"],
     "--only: unknown case(s) ['nope']; allowed: ['mpm_base'"),
    ("tradeoff_spacings", "experiments.tradeoff",
     ["--out={d}/out", "--spacings=0.01,abc"],
     "--spacings=0.01,abc; allowed: comma-separated numbers"),
    ("tradeoff_spacings_zero", "experiments.tradeoff",
     ["--out={d}/out", "--spacings=0.01,0"],
     "--spacings=0.0: allowed: > 0"),
    ("tradeoff_reference", "experiments.tradeoff",
     ["--out={d}/out", "--spacings=0.02,0.01", "--reference_spacing=0.015"],
     "--reference_spacing=0.015 is coarser than --spacings' 0.01; allowed"),
    ("tradeoff_gns", "experiments.tradeoff",
     ["--out={d}/out", "--gns=small"],
     "--gns item 'small'; allowed: NAME=WORKDIR"),
    ("tradeoff_gns_spacing", "experiments.tradeoff",
     ["--out={d}/out", "--spacings=0.02"],
     "--gns small: trained at spacing 0.01 m, which is not in --spacings"),
    ("convergence_spacings", "experiments.convergence",
     ["--out={d}/out", "--spacings=0.01,0"],
     "--spacings=0.0: allowed: > 0"),
    ("convergence_paper_scenes", "experiments.convergence",
     ["--out={d}/out", "--paper_scenes=0,x"],
     "--paper_scenes=0,x; allowed: comma-separated integers"),
    # Issue 25: the flag is named, not the scene's key it would set.
    ("convergence_height", "experiments.convergence",
     ["--out={d}/out", "--height=0"], "--height=0.0: allowed: > 0"),
    ("convergence_time", "experiments.convergence",
     ["--out={d}/out", "--time=-1"], "--time=-1.0: allowed: > 0"),
    ("convergence_aspect_ratios", "experiments.convergence",
     ["--out={d}/out", "--aspect_ratios=nan"],
     "--aspect_ratios=nan: allowed: a finite number"),
    ("inverse_design_x0_high", "experiments.inverse_design",
     ["--out={d}/out", "--x0=1.6"], "--x0=1.6; allowed: [0.5, 1.3] m"),
    # Issue 14: bad problems and designs, a missing budget.
    ("inverse_design_baffles_count", "experiments.inverse_design",
     ["--out={d}/out", "--problem=baffles", "--num_baffles=9",
      "--budget_s=10"],
     "--num_baffles=9; allowed: 2-8"),
    ("inverse_design_calibrate_truth", "experiments.inverse_design",
     ["--out={d}/out", "--problem=calibrate", "--truth=60,0.4",
      "--budget_s=10", "--method=cmaes"],
     "--truth: friction_angle_deg = 60: allowed range [20, 50]"),
    ("inverse_design_calibrate_start", "experiments.inverse_design",
     ["--out={d}/out", "--problem=calibrate", "--start=25",
      "--budget_s=10", "--method=cmaes"],
     "--start=25: allowed: two numbers, the friction angle (deg) and the "
     "basal friction"),
    ("inverse_design_calibrate_smoothed", "experiments.inverse_design",
     ["--out={d}/out", "--problem=calibrate", "--budget_s=10",
      "--method=adam_smoothed"],
     "allowed for --problem=calibrate: one or more of adam, cmaes, random, "
     "sweep"),
    ("inverse_design_two_overlapping", "experiments.inverse_design",
     ["--out={d}/out", "--problem=two_obstacles", "--xs=1.0,1.05",
      "--radii=0.04,0.04", "--budget_s=10"],
     "the obstacles overlap; allowed: base centres at least 0.08 m apart"),
    ("inverse_design_two_off_range", "experiments.inverse_design",
     ["--out={d}/out", "--problem=two_obstacles", "--xs=0.9,1.5",
      "--budget_s=10"],
     "--xs=0.9,1.5: obstacle 1 at x = 1.5; allowed: [0.5, 1.3] m"),
    ("inverse_design_two_radius", "experiments.inverse_design",
     ["--out={d}/out", "--problem=two_obstacles", "--radii=0.04,0.2",
      "--budget_s=10"],
     "obstacle 1 of radius 0.2; allowed: [0.02, 0.05] m"),
    ("inverse_design_no_budget", "experiments.inverse_design",
     ["--out={d}/out", "--method=cmaes"],
     "needs a budget; allowed: --budget_s > 0 and/or --budget_evals >= 1"),
    ("inverse_design_unknown_method", "experiments.inverse_design",
     ["--out={d}/out", "--method=adam,nope", "--budget_s=10"],
     "--method=adam,nope: allowed: one or more distinct of adam, "
     "adam_smoothed, cmaes, random, sweep"),
    ("inverse_design_odd_samples", "experiments.inverse_design",
     ["--out={d}/out", "--method=adam_smoothed", "--num_samples=3"],
     "--num_samples=3; allowed: an even number >= 2"),
    ("gradient_check_xs", "experiments.gradient_check",
     ["--out={d}/out", "--xs=0.52"],
     "--xs: [0.52] with --sigma=0.05: x +- sigma must lie in [0.5, 1.3] m"),
    # Round 3, item 8: no silent GIF for an mp4 (where ffmpeg is missing).
) + ((("render_mp4_without_ffmpeg", "experiments.render",
       ["--traj={d}/traj.h5", "--out={d}/out", "--format=mp4"],
       "--format=mp4 needs ffmpeg on PATH"),) if shutil.which("ffmpeg") is None
     else ()) + (
    # Round 3, item 4: config files and overrides, in one line.
    ("train_config_missing", "experiments.train",
     ["--config={d}/missing.py", "--data={d}/ds", "--workdir={d}/out"],
     "--config={d}/missing.py: no such file"),
    ("generate_config_syntax", "experiments.generate_dataset",
     ["--config={d}/syntax.py", "--out={d}/out"],
     "--config={d}/syntax.py: {d}/syntax.py, line 2: invalid syntax"),
    ("train_config_override_typo", "experiments.train",
     [TEST, "--config.train.num_step=5", "--data={d}/ds",
      "--workdir={d}/out"],
     "--config.train.num_step=5: config.train has no field 'num_step'; did "
     "you mean config.train.num_steps?"),
    ("generate_config_section_typo", "experiments.generate_dataset",
     [TEST, "--config.datset.spacing=0.02", "--out={d}/out"],
     "config has no field 'datset'; did you mean config.dataset?"),
    # Round 3, item 1: absurd sizes, refused before any work with the
    # estimate and what fits (the paper's box at 20 um: 3.6 TB).
    ("simulate_spacing_too_fine", "experiments.simulate",
     ["--scene={d}/fine.json", "--out={d}/out/traj.h5"],
     "granular.spacing = 2e-05, num_frames = 600: 362,250,000 particles"),
    ("simulate_too_many_frames", "experiments.simulate",
     ["--scene={d}/long.json", "--out={d}/out/traj.h5"],
     "num_frames = 100,000,000: 1,000 particles"),
    ("simulate_rest_speed_zero", "experiments.simulate",
     ["--scene={d}/tiny.json", "--out={d}/out/traj.h5", "--rest_speed=0"],
     "--rest_speed=0.0: allowed: (0, 10) m/s"),
    ("simulate_front_tolerance_unmet", "experiments.simulate",
     ["--scene={d}/tiny.json", "--out={d}/out/traj.h5",
      "--front_tolerance=0.001"],
     "front_tolerance = 0.001: no configuration meets front_error <= 0.001"),
    ("generate_unknown_rheology", "experiments.generate_dataset",
     [TEST, "--config.dataset.rheology=mui", "--out={d}/out"],
     "dataset.rheology = 'mui'; allowed: one of ['drucker_prager', "
     "'mu_i', 'mu_i_regularized', 'mu_i_compressible']"),
    ("convergence_unknown_rheology", "experiments.convergence",
     ["--out={d}/out", "--rheologies=drucker_prager,mui"],
     "--rheologies=mui: allowed: one of ['drucker_prager', 'mu_i', "
     "'mu_i_regularized', 'mu_i_compressible']"),
    ("convergence_regularized_without_a_well_posed_range",
     "experiments.convergence",
     ["--out={d}/out", "--rheologies=mu_i_regularized"],
     "--rheologies=mu_i_regularized with --friction_angle = 45: material: "
     "mu(I) with mu_s = 0.707"),
    ("generate_spacing_too_fine", "experiments.generate_dataset",
     [TEST, "--config.dataset.spacing=0.00002", "--out={d}/out"],
     "dataset.spacing = 2e-05, dataset.num_frames = 20: 93,750,000 "
     "particles"),
    ("generate_too_many_frames", "experiments.generate_dataset",
     [TEST, "--config.dataset.num_frames=100000000", "--out={d}/out"],
     "allowed: what fits, e.g. dataset.num_frames <= "),
    ("generate_too_many_workers", "experiments.generate_dataset",
     [TEST, "--config.dataset.num_train=100000", "--workers=100000",
      "--out={d}/out"], "allowed: what fits, e.g. --workers <= "),
    ("generate_batch_too_large", "experiments.generate_dataset",
     [TEST, "--config.dataset.num_train=100000", "--batch=100000",
      "--out={d}/out"], "allowed: what fits, e.g. --batch <= "),
    ("generate_batch_with_workers", "experiments.generate_dataset",
     [TEST, "--batch=4", "--workers=2", "--out={d}/out"],
     "--batch=4 with --workers=2; allowed: --batch > 1 only with "
     "--workers=1"),
    ("generate_too_large_for_the_disk", "experiments.generate_dataset",
     [TEST, "--config.dataset.num_train=1000000000", "--out={d}/out"],
     "dataset: 1,000,000,007 trajectories of 20 frames and up to 375 "
     "particles take up to"),
    # ... and the studies, before any work, naming their own flags.
    ("tradeoff_too_many_frames", "experiments.tradeoff",
     ["--out={d}/out", "--gns=", "--num_frames=100000000"],
     "--num_frames = 100,000,000: 2,800 particles"),
    ("tradeoff_batch_too_large", "experiments.tradeoff",
     ["--out={d}/out", "--gns=", "--scenes=5000"],
     "allowed: what fits, e.g. --scenes <= "),
    ("convergence_spacing_too_fine", "experiments.convergence",
     ["--out={d}/out", "--height=1", "--spacings=0.00005"],
     "--spacings = 5e-05, frames = 320: 400,000,000 particles"),
    ("inverse_design_too_many_frames", "experiments.inverse_design",
     ["--out={d}/out", "--num_frames=100000000"],
     "allowed: what fits, e.g. --num_frames <= "),
    ("inverse_design_batch_too_large", "experiments.inverse_design",
     ["--out={d}/out", "--method=cmaes", "--budget_evals=10",
      "--batch_size=1000000"], "allowed: what fits, e.g. --batch_size <= "),
    ("gradient_check_too_many_frames", "experiments.gradient_check",
     ["--out={d}/out", "--num_frames=100000000"],
     "allowed: what fits, e.g. --num_frames <= "),
    # 6000 scenes at once want 2.4 TB (no test machine has that); a plan
    # of 200000 scenes took 50 s to sample before the refusal.
    ("demo_too_many_workers", "experiments.demo",
     ["--out={d}/out", "--num_train=6000", "--workers=6000"],
     "allowed: what fits, e.g. --workers <= "),
    # Round 3, item 7: a run failing on its data removes what it created.
    ("train_unreadable_dataset", "experiments.train",
     [TEST, "--data={d}/ds", "--workdir={d}/out"],
     "{d}/ds/train.h5: not a readable HDF5 file"),
    # Round 3, item 5: a checkpoint whose data files were deleted.
    ("evaluate_damaged_checkpoint", "experiments.evaluate",
     ["--workdir={d}/damaged", "--data={d}", "--out={d}/out"],
     "--workdir={d}/damaged: checkpoint {d}/damaged/checkpoints/{step} is "
     "damaged: state/ocdbt.process_0/d/* (the arrays' data) missing"),
    ("rollout_damaged_checkpoint", "experiments.rollout",
     ["--workdir={d}/damaged", "--data={d}", "--out={d}/out"],
     "checkpoint {d}/damaged/checkpoints/{step} is damaged"),
    ("average_runs_damaged_checkpoint", "experiments.average_runs",
     ["--workdirs=experiments/pretrained/small,{d}/damaged",
      "--out={d}/out"],
     "--workdirs={d}/damaged: checkpoint {d}/damaged/checkpoints/{step} is "
     "damaged"),
    # Issue 29's sweep: an empty output path, too few runs to average, a
    # flag of another study than the one that runs, a zero step, a seed.
    ("simulate_out_empty", "experiments.simulate",
     ["--scene={d}/tiny.json", "--out="], "--out=: empty; allowed: a path"),
    ("render_out_empty", "experiments.render",
     ["--traj={d}/traj.h5", "--out="], "--out=: empty; allowed: a path"),
    ("train_workdir_empty", "experiments.train",
     [TEST, "--data={d}/ds", "--workdir="],
     "--workdir=: empty; allowed: a path"),
    ("average_runs_no_runs", "experiments.average_runs",
     ["--workdirs=", "--out={d}/out"],
     "--workdirs=: 0 run(s); allowed: two or more run directories"),
    ("inverse_design_unused_estimator", "experiments.inverse_design",
     ["--out={d}/out", "--method=cmaes", "--budget_s=10", "--estimator="],
     "--estimator=: allowed: one of"),
    ("inverse_design_unused_start", "experiments.inverse_design",
     ["--out={d}/out", "--method=cmaes", "--budget_s=10", "--start=nan"],
     "--start=nan: allowed: a finite number"),
    ("inverse_design_unused_num_baffles", "experiments.inverse_design",
     ["--out={d}/out", "--method=cmaes", "--budget_s=10",
      "--num_baffles=-1"], "--num_baffles=-1; allowed: 2-8"),
    ("inverse_design_unused_truth_empty", "experiments.inverse_design",
     ["--out={d}/out", "--method=cmaes", "--budget_s=10", "--truth="],
     "--truth is empty; allowed: a comma-separated list"),
    ("inverse_design_learning_rate_zero", "experiments.inverse_design",
     ["--out={d}/out", "--simulator=mpm", "--workdir=",
      "--learning_rate=0"], "--learning_rate=0.0: allowed: > 0"),
    ("inverse_design_learning_rate_huge", "experiments.inverse_design",
     ["--out={d}/out", "--simulator=mpm", "--workdir=",
      "--learning_rate=1e12"], "--learning_rate=1000000000000.0: allowed: "
     "<= 1"),
    ("inverse_design_sigma_huge", "experiments.inverse_design",
     ["--out={d}/out", "--method=cmaes", "--budget_s=10", "--sigma=1e12"],
     "--sigma=1000000000000.0: allowed: <= 1"),
    ("gradient_check_temperature_huge", "experiments.gradient_check",
     ["--out={d}/out", "--temperature=1e12"],
     "--temperature=1000000000000.0: allowed: <= 1"),
    ("convergence_nothing_to_measure", "experiments.convergence",
     ["--out={d}/out", "--aspect_ratios="],
     "--aspect_ratios is empty and so is --paper_scenes: nothing to measure"),
    ("validation_nothing_to_run", "experiments.validation",
     ["--out={d}/out", "--aspect_ratios=", "--incline_angles="],
     "--aspect_ratios and --incline_angles are both empty: nothing to run"),
    ("validation_strip_too_thin", "experiments.validation",
     ["--out={d}/out", "--incline_depth=0.002"],
     "--incline_depth=0.002 with --incline_dx=0.001: the strip is refused"),
    ("validation_unknown_rheology", "experiments.validation",
     ["--out={d}/out", "--rheologies=mui"],
     "--rheologies=mui: allowed: one of ['drucker_prager', 'mu_i']"),
    ("convergence_height_huge", "experiments.convergence",
     ["--out={d}/out", "--height=1e12"],
     "--height=1000000000000.0: allowed: <= 1"),
    ("convergence_time_huge", "experiments.convergence",
     ["--out={d}/out", "--time=1e12"],
     "--time=1000000000000.0: allowed: <= 10"),
    ("benchmarks_unused_sand_block_dir", "experiments.benchmarks",
     ["--what=mpm", "--quick", "--out={d}/out", "--sand_block_dir="],
     "--sand_block_dir=: only used by --what=gns (got --what=mpm)"),
    ("inverse_design_negative_seed", "experiments.inverse_design",
     ["--out={d}/out", "--method=cmaes", "--budget_s=10", "--seed=-1"],
     "--seed=-1: allowed: >= 0"),
    ("inverse_design_target_x", "experiments.inverse_design",
     ["--out={d}/out", "--method=cmaes", "--budget_s=10", "--target_x=-1"],
     "--target_x=-1.0: allowed: >= 0"),
    ("gradient_check_x_protect", "experiments.gradient_check",
     ["--out={d}/out", "--x_protect=1e12"],
     "--x_protect=1000000000000.0: allowed: <= 1.65"),
    # Item 8: a stiffness above the bound is refused with its cost.
    ("simulate_too_stiff", "experiments.simulate",
     ["--scene={d}/stiff.json", "--out={d}/out/traj.h5"],
     "allowed: (0, 1e+09] Pa: it would need at least 9,246 substeps per "
     "frame"),
)


class BadInputTest(parameterized.TestCase):

  @classmethod
  def setUpClass(cls):
    super().setUpClass()
    cls._tmp = tempfile.TemporaryDirectory()
    d = cls.dir = cls._tmp.name
    cls.server = server()
    tiny = dict(entry_points_test.TINY_SCENE)
    for name, scene in (
        ("tiny", tiny),
        ("stiff", {**tiny, "material": {"youngs_modulus": 1e12}}),
        ("fine", {"granular": {"box": [1.25, 0.5, 1.46, 1.19],
                               "spacing": 0.00002}}),
        ("long", {"num_frames": 100_000_000}),
        ("bad", {**tiny, "obstacles": [{"shape": "hexagon", "x": 0.2}]})):
      with open(os.path.join(d, f"{name}.json"), "w") as f:
        json.dump(scene, f)
    scene = mpm.Scene.from_dict(tiny)
    mpm_io.write_trajectories(os.path.join(d, "traj.h5"), [mpm_io.Trajectory(
        np.full((3, 4, 2), 0.3, np.float32), np.zeros((1, 2), np.float32),
        np.zeros(1, np.int32), scene)])
    with open(os.path.join(d, "a_file"), "w") as f:
      f.write("not a directory")
    # The shipped model with its arrays' data files deleted.
    shutil.copytree(os.path.join(ROOT, "experiments", "pretrained", "small"),
                    os.path.join(d, "damaged"))
    for path in glob.glob(os.path.join(d, "damaged", "checkpoints", SHIPPED_STEP,
                                       "state", "ocdbt.process_0", "d", "*")):
      os.remove(path)
    with open(os.path.join(d, "syntax.py"), "w") as f:
      f.write("def get_config():\n  return {'a': 1,,}\n")
    # A directory that passes --data's check (the training rows fail later).
    os.makedirs(os.path.join(d, "ds"))
    with open(os.path.join(d, "ds", "train.h5"), "w") as f:
      f.write("not read")
    os.makedirs(os.path.join(d, "other"))
    mpm_io.write_json(os.path.join(d, "other", "metadata.json"),
                      {"spec": dict(_TEST_SPEC, num_train=5)})
    os.makedirs(os.path.join(d, "parts", "parts"))
    mpm_io.write_json(os.path.join(d, "parts", "parts", "spec.json"),
                      dict(_TEST_SPEC, num_frames=8))

  @classmethod
  def tearDownClass(cls):
    cls.server.close()
    cls._tmp.cleanup()
    super().tearDownClass()

  @parameterized.named_parameters(*ROWS)
  def test_refused(self, module, argv, expected):
    before = sorted(os.listdir(self.dir))
    code, stdout, stderr = self.server.run(
        module, *[a.format(d=self.dir) for a in argv])
    self.assertEqual(code, 2, f"{stdout}\n{stderr}")
    # One line, the message naming what was wrong; no traceback.
    self.assertEqual(stderr.strip(), stderr.strip().splitlines()[0], stderr)
    self.assertStartsWith(stderr, "error: ")
    self.assertIn(expected.format(d=self.dir, step=SHIPPED_STEP), stderr)
    self.assertEqual(sorted(os.listdir(self.dir)), before)
    self.assertFalse(os.path.exists(os.path.join(self.dir, "other", "parts")))
    self.assertEqual(os.listdir(os.path.join(self.dir, "parts", "parts")),
                     ["spec.json"])

  def test_one_trainer_per_run_directory(self):
    # Round 3, item 6: a trainer holds the run directory (here a process
    # that takes the trainer's lock and waits: no training is needed).
    workdir = os.path.join(self.dir, "locked_run")
    env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu")
    holder = subprocess.Popen(
        [sys.executable, "-c",
         "import sys, time\n"
         "from experiments import train\n"
         "with train._one_trainer(sys.argv[1]):\n"
         "  print('locked', flush=True)\n"
         "  time.sleep(120)\n", workdir],
        env=env, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    self.addCleanup(holder.kill)
    self.assertEqual(holder.stdout.readline().strip(), "locked")
    argv = (TEST, f"--data={self.dir}/ds", f"--workdir={workdir}")
    code, _, stderr = self.server.run("experiments.train", *argv)
    self.assertEqual(code, 2, stderr)
    self.assertEqual(len(stderr.strip().splitlines()), 1, stderr)
    self.assertIn(f"--workdir={workdir}: another trainer is running in it "
                  f"(pid {holder.pid} on host ", stderr)
    self.assertEqual(os.listdir(workdir), ["trainer.lock"])
    # Killed with -9, it holds nothing: the rerun gets past the lock (and
    # fails later, on the dataset that is not one).
    holder.kill()
    holder.wait()
    code, _, stderr = self.server.run("experiments.train", *argv)
    self.assertEqual(code, 2, stderr)
    self.assertNotIn("another trainer", stderr)
    self.assertIn("train.h5", stderr)

  def test_verbose_shows_the_traceback(self):
    code, _, stderr = run("experiments.simulate",
                          f"--scene={self.dir}/bad.json",
                          f"--out={self.dir}/out/traj.h5", "--verbose")
    self.assertNotEqual(code, 0)
    self.assertIn("Traceback", stderr)
    self.assertIn("mpm.scene.InputError: obstacles[0].shape", stderr)
    self.assertFalse(os.path.exists(f"{self.dir}/out"))


if __name__ == "__main__":
  absltest.main()
