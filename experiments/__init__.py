"""Entry points, studies and benchmarks.

Importing the package caps the instruction set XLA compiles for
(``runtime.cap_cpu_isa``): before the entry point's own imports, in case one of them starts jax's
backend, after which the cap would come too late.
"""

from experiments import runtime as _runtime

_runtime.cap_cpu_isa()
