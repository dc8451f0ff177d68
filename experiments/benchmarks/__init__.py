"""Benchmarks of the MPM solver, the GNS, the dataset and inverse design.

Run as ``python -m experiments.benchmarks --what=mpm,gns,dataset,design,batch``
(``__main__.py``: flags, commands). Each benchmark is one library call,
``<name>_benchmark.run_benchmark(out_dir, ...)``, that writes
``<name>_benchmark.json`` and ``.md`` to ``out_dir`` and returns the results.
All of them time by the rules of ``timing`` (compilation apart, warm-up,
``block_until_ready``, medians of interleaved repeats, the machine recorded).

mpm (``mpm_benchmark``): microseconds per substep and seconds per 600-frame
trajectory of the paper scene (``scenes.PAPER_SCENE``), cost against
particle and obstacle count, vmapped batch throughput, and a Taichi (CPU)
peer of the same physics (``taichi_peer``), timed in the same run and
checked against the JAX solver. The peer needs the optional dependency:
``pip install -e .[bench]``.

gns (``gns_benchmark``, report in ``gns_report``): forward and training step
of the paper and small models on the shared sand block window
(``--sand_block_dir``) and on the paper scene, against the quoted
geoelements/gns and LagrangeBench times, the achieved FLOP rate against this
machine's matmul rate, the split first edge layer against the concatenated
form, and where the time goes by kind of operation (``op_profile``).

dataset (``dataset_benchmark``): wall time to generate 20 paper trajectories
with 2 and 1 worker processes, extrapolated to the paper's 1100, and windows
and padded batches read per second from ``--read_data``.

batch (``batch_benchmark``): particle-substeps per second of
``mpm.simulate_batch`` against scenes per batch, and the batch
``mpm.batch_sizing.batch_size_for`` picks on this device.

design (``design_benchmark``): the gradient of an objective w.r.t. an
obstacle's x against the forward rollout, for MPM and GNS: time ratio and
XLA memory.

gpu (``gpu_benchmark``): every accelerator figure in one command (MPM alone
and vmapped, the largest batch, the dataset; the paper GNS's rollout,
Table 2; training steps/s; agreement with a CPU), each beside this
project's CPU figure for the same code (the CPU reference, which the same
command measures on a CPU). It writes one ``gpu_<part>.json`` per part and
``gpu_benchmark.json`` / ``.md`` (``gpu_cpu_*`` on the CPU) instead of one
pair. ``gpu.sh`` runs it on a bare accelerator machine.
"""
