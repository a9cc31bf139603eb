"""JSON deliverables: numpy-aware conversion (:func:`to_jsonable`) and ``summary.json`` writing."""

from __future__ import annotations

import json
import math
import os

import numpy as np

from .atomic import atomic_write_text


def to_jsonable(obj, keep_nonfinite: bool = False):
    """Convert numpy scalars/arrays, tuples, sets, paths to JSON types; NaN/inf -> None.

    With ``keep_nonfinite`` NaN and inf stay floats (Python's json writes them as
    NaN/Infinity: the result cache, which must give back what it stored).

    Raises
    ------
    TypeError
        An object JSON cannot represent (the message names its type).
    """
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if keep_nonfinite or math.isfinite(x) else None
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v, keep_nonfinite) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [to_jsonable(v, keep_nonfinite) for v in obj]
    if isinstance(obj, np.ndarray):
        return [to_jsonable(v, keep_nonfinite) for v in obj.tolist()]
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if isinstance(obj, np.datetime64):
        return str(obj)
    raise TypeError(f"cannot write {type(obj).__name__} to JSON")


def write_json(path, obj) -> None:
    """Write ``obj`` as indented UTF-8 JSON (numpy types converted, NaN -> null), atomically."""
    atomic_write_text(path, json.dumps(to_jsonable(obj), indent=2, allow_nan=False, ensure_ascii=False) + "\n")
