"""numba's on-disk cache as a cache: a damaged or unwritable one costs a recompile, never a run.

The compiled kernel (:mod:`observer.kernel`) is decorated with ``cache=True``: numba keeps the
machine code of each function in an index file (``NAME-LINE.pyXY.nbi``) and data files
(``NAME-LINE.pyXY.K.nbc``) beside the module (``__pycache__``) or in ``NUMBA_CACHE_DIR``.
numba itself turns a truncated index (``EOFError``), a truncated data file (an unpickling
error) or a cache folder it cannot write (``PermissionError``) into a traceback.

:func:`install` wraps numba's :class:`numba.core.caching.Cache` so that

* a cache entry that cannot be read is a :class:`CacheWarning` naming the folder, the
  function's index is emptied (numba's ``flush``: the next save writes it afresh) and the
  function is compiled again;
* a cache entry that cannot be written is a :class:`CacheWarning` naming the folder; the
  compiled function is used from memory for this process;
* a function for which numba finds no cache folder at all (``NUMBA_CACHE_DIR``, the
  module's ``__pycache__`` and the user's cache folder all unwritable: numba raises
  ``RuntimeError: cannot cache function ...: no locator available`` when the function is
  decorated, i.e. when the toolkit is imported) is a :class:`CacheWarning` and is compiled
  in memory, uncached.

Either way the result is the one a fresh compile gives: the cache holds no result, only
machine code numba can rebuild.
"""

from __future__ import annotations

import warnings

_INSTALLED = False
_UNCACHED: set[str] = set()
"""Source files whose functions found no cache folder (warned once each)."""


class CacheWarning(RuntimeWarning):
    """numba's cache could not be read or written; the kernel was compiled instead."""


def _where(cache) -> str:
    return str(getattr(cache, "_cache_path", None) or "numba's cache folder")


def _name(cache) -> str:
    name = str(getattr(cache, "_name", "a kernel function"))
    return name.split(" at ")[0].replace("<function ", "")


def install() -> None:
    """Wrap :meth:`numba.core.caching.Cache.load_overload` and ``save_overload`` (once per
    process; idempotent)."""
    global _INSTALLED
    if _INSTALLED:
        return
    from numba.core import caching

    load, save = caching.Cache.load_overload, caching.Cache.save_overload

    def load_overload(self, sig, target_context):
        try:
            return load(self, sig, target_context)
        except Exception as exc:        # noqa: BLE001  (a damaged pickle raises anything)
            warnings.warn(f"numba cache of {_name(self)} in {_where(self)} is damaged "
                          f"({type(exc).__name__}); compiling it again", CacheWarning, stacklevel=2)
            try:
                self.flush()            # an empty index: the next save writes a whole one
            except OSError:
                pass
            return None

    def save_overload(self, sig, data):
        try:
            return save(self, sig, data)
        except Exception as exc:        # noqa: BLE001  (an unwritable or damaged folder)
            warnings.warn(f"numba cache of {_name(self)} cannot be written in {_where(self)} "
                          f"({type(exc).__name__}: {exc}); the compiled code is kept in memory "
                          "for this run only", CacheWarning, stacklevel=2)
            return None

    caching.Cache.load_overload, caching.Cache.save_overload = load_overload, save_overload
    _guard_locator()
    _INSTALLED = True


def _guard_locator() -> None:
    """Wrap :meth:`numba.core.dispatcher.Dispatcher.enable_caching`: no cache folder for a
    function is a warning and a :class:`numba.core.caching.NullCache` (compile, keep in memory)."""
    from numba.core import caching, dispatcher

    enable = dispatcher.Dispatcher.enable_caching

    def enable_caching(self):
        try:
            enable(self)
        except RuntimeError as exc:     # numba's "no locator available": no writable folder
            if "no locator available" not in str(exc):
                raise
            source = self.py_func.__code__.co_filename
            if source not in _UNCACHED:            # one line per module, not per function
                _UNCACHED.add(source)
                warnings.warn(f"numba finds no writable cache folder for the functions of {source} "
                              "(NUMBA_CACHE_DIR, its __pycache__, the user's cache folder): they are "
                              "compiled for this run only", CacheWarning, stacklevel=3)
            self._cache = caching.NullCache()

    dispatcher.Dispatcher.enable_caching = enable_caching
