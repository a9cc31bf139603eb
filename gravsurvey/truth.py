"""Reference ("truth") profiles: a simulator's truth.csv or any CSV of time and disturbance.

``flights[i].truth`` is a path (a gravsurvey simulator truth.csv: ``time_ns`` and
``disturbance_mgal``, docs/formats.md) or a mapping that names the columns like the inputs do::

    truth:
      file: reference.csv
      columns: {time: t_unix, disturbance_mgal: dg}
      time_format: s          # ns (Unix ns, integer) | s (Unix seconds)
      delimiter: ","

The same :class:`TruthSpec` drives the preflight header check (``validate`` and ``run`` refuse a
missing column before processing, naming the key) and the reading after processing.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import ConfigError, DataError

__all__ = ["TRUTH_TIME_FORMATS", "TruthSpec", "check_truth_header", "read_truth_csv", "truth_at"]

#: ``ns``: integer Unix nanoseconds; ``s``: Unix seconds (float)
TRUTH_TIME_FORMATS = ("ns", "s")


@dataclass
class TruthSpec:
    """Where a reference profile is and how to read it.

    Attributes
    ----------
    path : Path
    columns : dict
        ``{"time": name, "disturbance_mgal": name}``: the file's column for each quantity.
    time_format : str
        One of :data:`TRUTH_TIME_FORMATS`.
    delimiter : str
    """

    path: Path
    columns: dict = field(default_factory=lambda: {"time": "time_ns", "disturbance_mgal": "disturbance_mgal"})
    time_format: str = "ns"
    delimiter: str = ","

    def __post_init__(self):
        self.path = Path(self.path)


def _spec(spec) -> TruthSpec:
    return spec if isinstance(spec, TruthSpec) else TruthSpec(Path(spec))


def _header(path: Path, delimiter: str) -> list[str]:
    with open(path, encoding="utf-8-sig", newline="") as fh:
        for line in fh:
            if line.strip() and not line.startswith("#"):
                return [h.strip() for h in next(csv.reader([line], delimiter=delimiter))]
    return []


def check_truth_header(spec, key: str) -> None:
    """The truth file exists, is UTF-8 text, and its header has the configured columns.

    Raises
    ------
    ConfigError
        Naming ``key`` (e.g. ``flights[0].truth``), the file and what is missing.
    """
    spec = _spec(spec)
    path = spec.path
    if not path.is_file():
        raise ConfigError(f"{key}: truth file not found: {path}")
    try:
        head = _header(path, spec.delimiter)
    except UnicodeDecodeError:
        raise ConfigError(f"{key}: {path}: not a text CSV (truth file, docs/formats.md)") from None
    except OSError as exc:
        raise ConfigError(f"{key}: {path}: cannot read: {exc.strerror}") from None
    missing = [c for c in spec.columns.values() if c not in head]
    if missing:
        hint = (
            ""
            if spec.columns != TruthSpec(path).columns
            else f" (other names: {key}: {{file: ..., columns: {{time: ..., disturbance_mgal: ...}}}})"
        )
        raise ConfigError(
            f"{key}: {path}: truth file lacks column(s) {', '.join(missing)}; "
            f"header has {', '.join(h for h in head if h) or 'nothing'}{hint}"
        )


def read_truth_csv(spec) -> dict:
    """Read a reference profile.

    Parameters
    ----------
    spec : TruthSpec or path
        A path reads a simulator truth.csv (``time_ns``, ``disturbance_mgal``, docs/formats.md).

    Returns
    -------
    dict
        ``time_ns`` (int64 Unix ns) and ``disturbance_mgal`` (float), plus every other column of
        the file under its own name (float, or object where not numeric).

    Raises
    ------
    DataError
        Missing file, no data rows, a missing column, a row of the wrong length, or a
        non-numeric time or disturbance value (naming the file and row).
    """
    spec = _spec(spec)
    path = spec.path
    if not path.is_file():
        raise DataError(f"{path}: truth file not found")
    with open(path, encoding="utf-8-sig", newline="") as fh:
        rows = list(csv.reader((line for line in fh if not line.startswith("#")), delimiter=spec.delimiter))
    rows = [r for r in rows if any(c.strip() for c in r)]
    if len(rows) < 2:
        raise DataError(f"{path}: truth file has no data rows")
    head = [h.strip() for h in rows[0]]
    for need in spec.columns.values():
        if need not in head:
            raise DataError(f"{path}: truth file lacks column {need!r}; has {', '.join(head)}")
    cols: dict = {h: [] for h in head}
    for ln, r in enumerate(rows[1:], start=2):
        if len(r) != len(head):
            raise DataError(f"{path}: data row {ln} has {len(r)} fields, header has {len(head)}")
        for h, v in zip(head, r):
            cols[h].append(v.strip())
    out = {}
    for h, v in cols.items():
        try:
            out[h] = np.array(v, dtype=float)
        except ValueError:
            out[h] = np.array(v, dtype=object)
    tname, gname = spec.columns["time"], spec.columns["disturbance_mgal"]
    for name in (tname, gname):
        if out[name].dtype == object:
            bad = next(i for i, x in enumerate(cols[name]) if not _is_number(x))
            raise DataError(f"{path}: column {name!r} row {bad + 2}: expected a number, got {cols[name][bad]!r}")
    if spec.time_format == "ns":
        try:
            out["time_ns"] = np.array(cols[tname], dtype=np.int64)
        except ValueError:
            out["time_ns"] = np.round(out[tname]).astype(np.int64)
    else:
        out["time_ns"] = np.round(out[tname] * 1e9).astype(np.int64)
    out["disturbance_mgal"] = out[gname]
    return out


def _is_number(x: str) -> bool:
    try:
        float(x)
    except ValueError:
        return False
    return True


def truth_at(truth: dict, unix_ns: np.ndarray) -> np.ndarray:
    """Truth disturbance interpolated to the given epochs.

    Parameters
    ----------
    truth : dict
        As :func:`read_truth_csv` returns: ``time_ns`` (int64) and ``disturbance_mgal``.
    unix_ns : ndarray of int64, shape (N,)
        Unix ns of the epochs.

    Returns
    -------
    ndarray, shape (N,)
        mGal; NaN outside the truth span.
    """
    t_ref = truth["time_ns"][0]
    tt = (truth["time_ns"] - t_ref).astype(float)
    x = (unix_ns - t_ref).astype(float)
    return np.interp(x, tt, truth["disturbance_mgal"], left=np.nan, right=np.nan)
