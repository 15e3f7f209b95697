"""numba options of every compiled kernel (the geometry engine's and the solver's), and the guard that
keeps their on-disk caches in step with the engine's sources."""
from __future__ import annotations

import hashlib
from pathlib import Path

# No reference counting (numba's NRT) in kernels that allocate nothing: every slice would otherwise
# bump an atomic counter, which was half of a frame's time and, shared between the batch's threads,
# made them wait on each other. Only kernels that allocate (JIT_ALLOC) keep it. fastmath stays off:
# the live and the batch path must give bit-identical answers.
JIT = {"cache": True, "nogil": True, "fastmath": False, "_nrt": False}
JIT_ALLOC = {"cache": True, "nogil": True, "fastmath": False}

_ENGINE = Path(__file__).resolve().parent
# where kernels that call the engine from another file keep their caches (numba's in-tree default)
_DEPENDENT_CACHES = (_ENGINE / "__pycache__", _ENGINE.parent / "solver" / "__pycache__")


def _drop_stale_caches() -> None:
    """numba checks a cached kernel against its own file only: a kernel that calls the engine from
    another file (the solver's, arrays.py's) would go on running the engine's old code after an edit.
    So every cache of those files is dropped when an engine source changed since the last run."""
    sources = sorted(_ENGINE.glob("*.py"))
    stamp = hashlib.sha256(repr([(p.name, p.stat().st_mtime_ns, p.stat().st_size) for p in sources]).encode())
    stamp_file = _DEPENDENT_CACHES[0] / "engine-sources.stamp"
    try:
        if stamp_file.exists() and stamp_file.read_text() == stamp.hexdigest():
            return
        for folder in _DEPENDENT_CACHES:
            for cached in (*folder.glob("*.nbi"), *folder.glob("*.nbc")):
                cached.unlink(missing_ok=True)
        stamp_file.parent.mkdir(exist_ok=True)
        stamp_file.write_text(stamp.hexdigest())
    except OSError:  # a read-only install: its sources do not change
        pass


_drop_stale_caches()
