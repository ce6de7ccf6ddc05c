"""Keep numba's on-disk kernel cache in step with every source a kernel inlines.

numba keys a cached kernel on the file of the jitted function only (its modification time
and size): ``_kernel.rk4_run`` inlines the Masing and virgin-curve functions of
``masing.py`` and ``virgin.py``, so after an edit to either, the cache still serves the
old machine code, and the old physics (the friction models' loops in ``sim/friction``
inline the templates of ``sim/friction/_periodic.py`` the same way).  Here the cache is
keyed on a SHA-256 of every ``*.py`` of the package and its subpackages (the kernels
inline from anywhere in it; hashing them costs about a millisecond): when it differs from
the one stored beside the cache, every ``*.nbi``/``*.nbc`` of the package's
``__pycache__`` folders is deleted and numba compiles afresh.

Called by ``bench warmup`` (and so by a simulated run that finds the kernels cold) and by
the tests' set-up (``tests/conftest.py``).  Only the in-tree cache (``__pycache__`` beside
the sources, numba's default) is managed; with ``NUMBA_CACHE_DIR`` set, clear that by hand
after editing ``sim/``.  See docs/decisions/0028-hardening.md.
"""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path

log = logging.getLogger(__name__)

SIM_DIR = Path(__file__).resolve().parent
STAMP_NAME = "kernels.sha256"


def sources_hash(package_dir: Path = SIM_DIR) -> str:
    """SHA-256 over the paths and contents of the ``*.py`` files of the package and its subpackages."""
    h = hashlib.sha256()
    root = Path(package_dir)
    for p in sorted(root.rglob("*.py")):
        h.update(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


def invalidate_stale_kernels(package_dir: Path = SIM_DIR) -> bool:
    """Delete the package's cached kernels if its sources changed since they were cached;
    returns True if it did.  A read-only install (nothing can be written) is left alone."""
    cache = Path(package_dir) / "__pycache__"
    stamp = cache / STAMP_NAME
    now = sources_hash(package_dir)
    try:
        if stamp.read_text() == now:
            return False
    except OSError:
        pass
    try:
        removed = 0
        for p in list(Path(package_dir).rglob("__pycache__/*.nbi")) + list(Path(package_dir).rglob("__pycache__/*.nbc")):
            p.unlink(missing_ok=True)
            removed += 1
        cache.mkdir(exist_ok=True)
        stamp.write_text(now)
    except OSError as e:
        log.warning("could not invalidate the kernel cache in %s: %s", cache, e)
        return False
    if removed:
        log.info("sources of %s changed: %d cached kernel files removed", package_dir, removed)
    return True
