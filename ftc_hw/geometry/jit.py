"""numba options of every compiled kernel (the geometry engine's and the solver's)."""
from __future__ import annotations

# No reference counting (numba's NRT) in kernels that allocate nothing: every slice would otherwise
# bump an atomic counter, which was half of a frame's time and, shared between the batch's threads,
# made them wait on each other. Only kernels that allocate (JIT_ALLOC) keep it. fastmath stays off:
# the live and the batch path must give bit-identical answers.
JIT = {"cache": True, "nogil": True, "fastmath": False, "_nrt": False}
JIT_ALLOC = {"cache": True, "nogil": True, "fastmath": False}
