"""gravsurvey: airborne gravimetry by 3D inertial-navigation-method Kalman dynamic inversion.

Importing the package chooses where numba caches the compiled kernels, before any module
imports numba (see :func:`setup_numba_cache`).
"""

from __future__ import annotations

import os
import stat
import sys
import tempfile

__version__ = "0.1.0"

#: where the numba kernel cache went: "env" (NUMBA_CACHE_DIR set by the user), "user" (the
#: user cache folder), "temp" (a private temp folder) or "none" (nothing writable: no cache)
NUMBA_CACHE_KIND = "unset"


def _writable_dir(path: str, *, private: bool = False) -> bool:
    """Create ``path`` if needed and prove it writable (as numba does: a temporary file).

    ``private``: the folder must also belong to this user and be closed to others (mode
    0o700); numba's cache files are pickles, so a folder others can write would let them
    plant code (this matters for the shared temp folder).
    """
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
        if private and hasattr(os, "getuid"):
            st = os.stat(path)
            if st.st_uid != os.getuid() or st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
                return False
        tempfile.TemporaryFile(dir=path).close()
        return True
    except (OSError, ValueError):
        return False


def user_cache_dir() -> str:
    """``$XDG_CACHE_HOME/gravsurvey`` or ``~/.cache/gravsurvey`` (``%LOCALAPPDATA%`` on
    Windows, ``~/Library/Caches`` on macOS), as platformdirs would choose, without importing it."""
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA") or os.path.expanduser(r"~\AppData\Local")
    elif sys.platform == "darwin":
        base = os.path.expanduser("~/Library/Caches")
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache")
    return os.path.join(base, "gravsurvey")


def setup_numba_cache() -> str:
    """Point numba's kernel cache at a writable folder; returns the kind chosen.

    Order: a user's own writable ``NUMBA_CACHE_DIR``; ``<user cache>/numba``
    (:func:`user_cache_dir`); a private ``<tmp>/gravsurvey-numba-<uid>``; else no cache at all
    (kernels compile on every run, ~30-60 s, but nothing crashes). The package folder itself is
    never used, so a read-only install works. Must run before numba is imported, which is why
    it runs on ``import gravsurvey``.
    """
    global NUMBA_CACHE_KIND
    own = os.environ.get("NUMBA_CACHE_DIR")
    if own and _writable_dir(own):
        NUMBA_CACHE_KIND = "env"
        return NUMBA_CACHE_KIND
    candidates = [("user", os.path.join(user_cache_dir(), "numba"), False)]
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    candidates.append(("temp", os.path.join(tempfile.gettempdir(), f"gravsurvey-numba-{uid}"), True))
    for kind, path, private in candidates:
        if _writable_dir(path, private=private):
            os.environ["NUMBA_CACHE_DIR"] = path
            NUMBA_CACHE_KIND = kind
            return kind
    _disable_numba_cache()
    NUMBA_CACHE_KIND = "none"
    return NUMBA_CACHE_KIND


def _disable_numba_cache() -> None:
    # numba has no switch for this: with no writable locator, @njit(cache=True) raises
    # RuntimeError("cannot cache function ...") at import.  Make enable_caching a no-op, so the
    # kernels keep numba's in-memory NullCache (compiled once per process).
    os.environ.pop("NUMBA_CACHE_DIR", None)
    from numba.core import dispatcher

    setattr(dispatcher.Dispatcher, "enable_caching", lambda self: None)


setup_numba_cache()
