"""Per-flight result cache (``out/.cache``) in a format that cannot run code.

A flight's result is stored as two files:

- ``<flight>.npz``: its arrays, written with :func:`numpy.savez` and read with
  ``allow_pickle=False`` (object arrays, e.g. line names, are stored as fixed-width Unicode);
- ``<flight>.json``: the cache key, the SHA-256 of the ``.npz`` file, the array names and
  dtypes, and every other field as plain JSON.

Loading reads the JSON first (``json`` builds only dicts, lists, strings and numbers), compares
its key with the key of the current inputs and configuration, and checks the ``.npz`` file's
SHA-256 *before* any array is read: a stale, truncated, altered or planted cache is ignored and
the flight reprocessed, and nothing in the folder can execute code (pickle is never used).
Writes are atomic (temporary file + ``os.replace``); the ``.npz`` is written first, so a JSON
always refers to a complete array file.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
from pathlib import Path

import numpy as np

from .io.writers import atomic_write_bytes, file_sha256, to_jsonable

#: bump when the on-disk layout changes; part of every entry
CACHE_FORMAT = "gravsurvey-flight-cache/1"


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """SHA-256 of the package's own source: the name and bytes of every ``.py`` file under it.

    Part of every flight's cache key, so that results computed by other code - an update
    installed from a branch or a checkout under the same version number - are never reused
    as this code's (the version string alone did not change between such installs). Read once
    per process (90 files: 3 ms); an install without sources (byte code only)
    falls back to nothing beyond the version the key also holds.
    """
    h = hashlib.sha256()
    pkg = Path(__file__).resolve().parent
    for f in sorted(pkg.rglob("*.py")):
        h.update(f.relative_to(pkg).as_posix().encode() + b"\0")
        try:
            h.update(f.read_bytes())
        except OSError:
            h.update(b"unreadable")
        h.update(b"\0")
    return h.hexdigest()


def cache_paths(cache_dir, name: str) -> tuple[Path, Path]:
    """``(json_path, npz_path)`` of flight ``name`` in ``cache_dir``."""
    d = Path(cache_dir)
    return d / f"{name}.json", d / f"{name}.npz"


def save_result(cache_dir, name: str, key: str, result) -> None:
    """Store dataclass ``result`` under cache key ``key`` (atomic; arrays in .npz, rest JSON).

    Raises
    ------
    OSError
        The cache folder is not writable (the caller decides whether that matters).
    """
    jpath, npath = cache_paths(cache_dir, name)
    arrays, dtypes, fields = {}, {}, {}
    for f in dataclasses.fields(result):
        v = getattr(result, f.name)
        if isinstance(v, np.ndarray):
            if v.dtype == object:  # line names: strings only, stored as Unicode (no pickle)
                arrays[f.name] = np.array([str(x) for x in v], dtype=str)
            else:
                arrays[f.name] = v
            dtypes[f.name] = str(v.dtype)
        else:
            fields[f.name] = to_jsonable(v, keep_nonfinite=True)
    import io

    buf = io.BytesIO()
    np.savez(buf, **arrays)  # type: ignore[arg-type]  # numpy's stub types **kwds too narrowly
    atomic_write_bytes(npath, buf.getvalue())
    entry = {
        "format": CACHE_FORMAT,
        "key": key,
        "npz_sha256": file_sha256(npath),
        "dtypes": dtypes,
        "fields": fields,
    }
    atomic_write_bytes(jpath, json.dumps(entry, allow_nan=True).encode())


def load_result(cache_dir, name: str, key: str, cls):
    """The cached ``cls`` instance of flight ``name`` if its key is ``key``, else ``None``.

    ``None`` also for a missing, unreadable, foreign or altered cache; nothing is unpickled
    and the arrays are read only after the key and the array file's SHA-256 matched.
    """
    jpath, npath = cache_paths(cache_dir, name)
    try:
        entry = json.loads(jpath.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(entry, dict) or entry.get("format") != CACHE_FORMAT or entry.get("key") != key:
        return None
    dtypes, fields = entry.get("dtypes"), entry.get("fields")
    if not isinstance(dtypes, dict) or not isinstance(fields, dict):
        return None
    try:
        if file_sha256(npath) != entry.get("npz_sha256"):
            return None
        with np.load(npath, allow_pickle=False) as z:
            arrays = {k: z[k] for k in dtypes if k in z.files}
    except (OSError, ValueError, KeyError):
        return None
    if set(arrays) != set(dtypes):
        return None
    kwargs = dict(fields)
    for k, dt in dtypes.items():
        a = arrays[k]
        kwargs[k] = a.astype(object) if dt == "object" else a
    names = {f.name for f in dataclasses.fields(cls)}
    if set(kwargs) != names:
        return None
    return cls(**kwargs)
