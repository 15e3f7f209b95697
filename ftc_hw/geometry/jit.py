"""numba options of every compiled kernel (the geometry engine's and the solver's), and the guard that
keeps on-disk caches in step with the sources their kernels call into."""
from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path

# No reference counting (numba's NRT) in kernels that allocate nothing: every slice would otherwise
# bump an atomic counter, which was half of a frame's time and, shared between the batch's threads,
# made them wait on each other. Only kernels that allocate (JIT_ALLOC) keep it. fastmath stays off:
# the live and the batch path must give bit-identical answers.
JIT = {"cache": True, "nogil": True, "fastmath": False, "_nrt": False}
JIT_ALLOC = {"cache": True, "nogil": True, "fastmath": False}

ENGINE_SOURCES = tuple(sorted(Path(__file__).resolve().parent.glob("*.py")))


def drop_stale_caches(folder: Path, sources: Iterable[Path]) -> None:
    """numba checks a cached kernel against its own file only: a kernel that calls kernels of other
    files would go on running their old code after an edit. So every numba cache in ``folder`` (a
    package's ``__pycache__``) is dropped when one of ``sources`` changed since the last call. Call it
    when the module is imported, before its kernels run."""
    stamp = hashlib.sha256(repr([(p.name, p.stat().st_mtime_ns, p.stat().st_size) for p in sources]).encode())
    stamp_file = folder / "kernel-sources.stamp"
    try:
        if stamp_file.exists() and stamp_file.read_text() == stamp.hexdigest():
            return
        for cached in (*folder.glob("*.nbi"), *folder.glob("*.nbc")):
            cached.unlink(missing_ok=True)
        folder.mkdir(exist_ok=True)
        stamp_file.write_text(stamp.hexdigest())
    except OSError:  # a read-only install: its sources do not change
        pass


drop_stale_caches(Path(__file__).resolve().parent / "__pycache__", ENGINE_SOURCES)  # arrays.py calls the others
