"""The kernel's ``jit``: numba's on-disk cache stamped by every file of this folder.

numba keys a cached function (``cache=True``) on its own source file: the index of
``compiled.next_impact`` is stale when compiled.py changes, not when a file it calls into
does, and a process would then load the old machine code of the callee, linked into the
caller. The kernel's functions call across its files (the certified search of
:mod:`.interval_search` serves both models' evaluators), so the locators here stamp every
function defined in this folder with the contents of all its ``.py`` files: an edit of
any of them recompiles every kernel function on the next load (tests/test_kernel.py,
``test_a_callees_edit_invalidates_its_callers_cache``).

The locators are numba's own (``NUMBA_CACHE_DIR``, ``__pycache__`` next to the source, the
user-wide directory), with only the source stamp replaced; they are put first in
numba's list of locator classes (``numba.core.caching.CacheImpl._locator_classes``, a
private name the test pins) when this module is imported, which every compiled module
of the folder does before it defines a function. ``NUMBA_CACHE_LOCATOR_CLASSES``, where
set, overrides the list and with it this stamp.
"""

from __future__ import annotations

import functools
import hashlib
import os

import numba
from numba.core import caching

__all__ = ["jit", "FOLDER", "folder_stamp"]

#: The folder whose files stamp every kernel function's cache.
FOLDER = os.path.dirname(os.path.abspath(__file__))


def folder_stamp(folder: str = FOLDER) -> str:
    """SHA-256 over the names and contents of the folder's ``.py`` files, in name order."""
    names = sorted(n for n in os.listdir(folder) if n.endswith(".py"))
    stats = tuple((n, os.stat(os.path.join(folder, n))) for n in names)
    return _hash(folder, tuple((n, s.st_mtime_ns, s.st_size) for n, s in stats))


@functools.lru_cache(maxsize=None)
def _hash(folder, listing):
    """The stamp of a folder listing (names, mtimes, sizes): read once per listing, as
    numba hashes a source file once per (mtime, size)."""
    digest = hashlib.sha256()
    for name, _mtime, _size in listing:
        digest.update(name.encode() + b"\0")
        with open(os.path.join(folder, name), "rb") as f:
            digest.update(f.read())
    return digest.hexdigest()


class _FolderStamp:
    """A numba source-file locator for the functions of :data:`FOLDER`, stamped by
    :func:`folder_stamp` instead of the function's own file."""

    @classmethod
    def from_function(cls, py_func, py_file):
        if os.path.dirname(os.path.abspath(py_file)) != FOLDER:
            return None  # another file: numba's own locators
        return super().from_function(py_func, py_file)

    def get_source_stamp(self):
        return folder_stamp()


#: numba's locators in numba's order, each stamped by the folder.
LOCATORS = tuple(type(f"Kernel{base.__name__}", (_FolderStamp, base), {"__module__": __name__})
                 for base in (caching.UserProvidedCacheLocator, caching.InTreeCacheLocator,
                              caching.UserWideCacheLocator))


def _register():
    """Put :data:`LOCATORS` first in numba's list (once per process: a second import of
    this module, e.g. a copy of the folder, adds its own)."""
    classes = caching.CacheImpl._locator_classes
    for cls in reversed(LOCATORS):
        classes.insert(0, cls)


_register()

#: numba's compiler for the kernel: machine code cached on disk (stamped by the folder),
#: no GIL held, NumPy's error model (a division by zero gives inf, not an exception).
jit = numba.njit(cache=True, nogil=True, error_model="numpy")
