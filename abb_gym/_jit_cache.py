"""Keep numba's on-disk caches honest.

numba's ``cache=True`` re-checks only the file that defines a function, not the files of the
compiled functions it calls: after an edit of ``physics/model.py`` the cached
``integrators.run`` or ``envs/core`` kernels would silently keep the old physics.  So, before
any compiled module is imported, :func:`flush_if_sources_changed` fingerprints every
``abb_gym`` module that uses numba and, if the fingerprint differs from the one stored with the
caches, deletes all of the package's numba cache files (``*.nbi``, ``*.nbc``); they are
rebuilt on first use.  It never raises: a read-only install simply keeps its caches.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent
STAMP = PACKAGE / "__pycache__" / "numba-sources.sha1"


def sources_fingerprint() -> str:
    """SHA-1 over the sources of every module of the package that imports numba."""
    h = hashlib.sha1()
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        if b"numba" in text:
            h.update(str(path.relative_to(PACKAGE)).encode())
            h.update(text)
    return h.hexdigest()


def flush_if_sources_changed() -> bool:
    """Delete the package's numba caches if a compiled module changed; True if it did."""
    try:
        fingerprint = sources_fingerprint()
        if STAMP.exists() and STAMP.read_text() == fingerprint:
            return False
        for path in list(PACKAGE.rglob("*.nbi")) + list(PACKAGE.rglob("*.nbc")):
            path.unlink(missing_ok=True)
        STAMP.parent.mkdir(parents=True, exist_ok=True)
        STAMP.write_text(fingerprint)
        return True
    except OSError:  # pragma: no cover - read-only installation
        return False
