"""Where numba keeps abb-gym's compiled kernels, and keeping those caches honest.

**Location.**  :func:`install_locator` puts one folder first in numba's search for a cache
location: ``abb_gym/_kernels/`` inside the package (a package of its own, so that the wheel
ships the caches that ``abb-gym build-kernels`` made: :mod:`abb_gym.kernels`).  numba names
each cache file after the module's file name, the function and its line, so one flat folder
holds them all (``tests/test_packaging.py`` checks that no two compiled modules share a file
name).  When the installed package is not writable, numba's own per-user cache is used, and
``NUMBA_CACHE_DIR``, when set, wins over both.

**Freshness.**  numba checks the source file of a cached function, not the files of the
compiled functions it calls: after an edit of ``physics/model.py`` the cached
``integrators.run`` or ``envs/kernel`` kernels would silently keep the old physics.  So,
before any compiled module is imported, :func:`flush_if_sources_changed` fingerprints every
``abb_gym`` module that imports numba and, if the fingerprint differs from the one stored with
the caches, deletes them; they are rebuilt on first use.  It never raises.  The same
fingerprint, not numba's file modification time, stamps each cache file, so caches built
before ``make wheel`` stay valid in an installed wheel, whose files carry new times.
"""
from __future__ import annotations

import hashlib
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent
KERNELS = PACKAGE / "_kernels"
STAMP = KERNELS / "numba-sources.sha1"

# a compiled module imports numba through abb_gym._numba (which imports numba itself)
_IMPORTS_NUMBA = re.compile(rb"^\s*(from numba\b|import numba\b|from \.+_numba import)",
                            re.MULTILINE)


_fingerprint: str | None = None


def sources_fingerprint() -> str:
    """SHA-1 over the sources of every module of the package that imports numba (computed
    once per process: the sources of a running process are the ones it imported)."""
    global _fingerprint
    if _fingerprint is not None:
        return _fingerprint
    h = hashlib.sha1()
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        if _IMPORTS_NUMBA.search(text):
            h.update(str(path.relative_to(PACKAGE)).encode())
            h.update(text)
    _fingerprint = h.hexdigest()
    return _fingerprint


def cache_files() -> list[Path]:
    """The compiled-kernel cache files in the package's cache folder."""
    return sorted(list(KERNELS.glob("*.nbi")) + list(KERNELS.glob("*.nbc")))


def flush_if_sources_changed() -> bool:
    """Delete the package's numba caches if a compiled module changed; True if it did."""
    try:
        fingerprint = sources_fingerprint()
        if STAMP.exists() and STAMP.read_text() == fingerprint:
            return False
        for path in cache_files():
            path.unlink(missing_ok=True)
        STAMP.write_text(fingerprint)
        return True
    except OSError:  # pragma: no cover - read-only installation
        return False


def install_locator() -> bool:
    """Make numba cache abb-gym's functions in :data:`KERNELS` (call before any module with
    compiled functions is imported: numba picks the location when it decorates).  Returns
    False if numba's cache internals are not the expected ones (numba's defaults then apply)."""
    try:
        from numba.core import caching
        from numba.core.caching import _CacheLocator, _SourceFileBackedLocatorMixin
        cache_impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl  # 0.68 renamed
    except (ImportError, AttributeError):  # pragma: no cover - a numba without these internals
        return False

    class PackageCacheLocator(_SourceFileBackedLocatorMixin, _CacheLocator):
        """abb-gym's functions are cached in ``abb_gym/_kernels`` (module docstring)."""

        def __init__(self, py_func, py_file):
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno

        def get_cache_path(self):
            return str(KERNELS)

        def get_source_stamp(self):
            # numba stamps a cache with the source file's mtime and size; an installed wheel
            # has new mtimes, which would make the shipped caches stale.  The content
            # fingerprint of every compiled module is the honest stamp (and covers the
            # callees that numba's own stamp misses)
            return sources_fingerprint()

        @classmethod
        def from_function(cls, py_func, py_file):
            from numba.core import config
            if config.CACHE_DIR:  # NUMBA_CACHE_DIR set: the user's choice wins
                return None
            try:
                Path(py_file).resolve().relative_to(PACKAGE)
            except (ValueError, OSError):
                return None
            # None (numba's next locator) when KERNELS is not writable: the mixin tries
            return super().from_function(py_func, py_file)

    classes = cache_impl._locator_classes
    if not any(c.__name__ == "PackageCacheLocator" for c in classes):
        classes.insert(0, PackageCacheLocator)
    return True
