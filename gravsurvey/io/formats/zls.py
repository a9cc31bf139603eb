"""ZLS (LaCoste & Romberg-ZLS) airborne/marine gravimeter fixed-width files.

One line per second, fixed-width ASCII (layout as DGP's ZLS reader documents it), files named
``YYYY_HH.DDD`` holding an hour each::

    width  10  4    3   2    2      2      8       8              7               8
    field  line year day hour minute second gravity spring_tension cross_coupling beam
    width  8   8  8  8   8   8     8     8    8    8         6
    field  vcc al ax ve2 ax2 xacc2 lacc2 xacc lacc par_port platform_period

Columns: ``gravity`` (m/s^2; the meter's gravity output, with its offset), ``spring_tension``
(m/s^2, counter units = mGal), ``cross_coupling`` (m/s^2), ``beam`` and the monitors ``vcc al
ax ve2 ax2 xacc2 lacc2 xacc lacc`` (meter units), ``platform_period`` (s); ``meta['line_names']``
the distinct line names and ``meta['par_port']`` the first parallel-port status word (hex text).
The files hold no position: pair them with a navigation file.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from gravsurvey.errors import DataError

from .common import MGAL, FormatTable, LineTally, doy_to_ns, read_lines

WIDTHS = (10, 4, 3, 2, 2, 2, 8, 8, 7, 8, 8, 8, 8, 8, 8, 8, 8, 8, 8, 8, 6)
NAMES = (
    "line",
    "year",
    "day",
    "hour",
    "minute",
    "second",
    "gravity",
    "spring_tension",
    "cross_coupling",
    "beam",
    "vcc",
    "al",
    "ax",
    "ve2",
    "ax2",
    "xacc2",
    "lacc2",
    "xacc",
    "lacc",
    "par_port",
    "platform_period",
)
_MGAL_COLS = ("gravity", "spring_tension", "cross_coupling")
_NUM_COLS = NAMES[6:19] + ("platform_period",)
LINE_LENGTH = sum(WIDTHS)


def _read_one(path, tally: LineTally, out: dict, names: set, ports: list):
    bounds = np.cumsum((0,) + WIDTHS)
    for n, ln in enumerate(read_lines(path), start=1):
        if not ln.strip():
            continue
        tally.n_lines += 1
        if len(ln.rstrip()) < bounds[-2] + 1 or len(ln.rstrip()) > LINE_LENGTH + 2:
            tally.bad(n, f"line length {len(ln.rstrip())}, expected {LINE_LENGTH}", ln)
            continue
        f = [ln[bounds[i] : bounds[i + 1]] for i in range(len(WIDTHS))]
        try:
            t = doy_to_ns(int(f[1]), int(f[2]), int(f[3]), int(f[4]), f[5].strip())
            nums = [float(f[NAMES.index(c)]) for c in _NUM_COLS]
        except ValueError as exc:
            tally.bad(n, f"unparsable field ({exc})", ln)
            continue
        if not all(np.isfinite(nums)):
            tally.bad(n, "non-finite number", ln)
            continue
        out["time"].append(t)
        for c, v in zip(_NUM_COLS, nums):
            out[c].append(v)
        names.add(f[0].strip())
        if not ports:
            ports.append(f[19].strip())


def read_zls(paths) -> FormatTable:
    """Read one or more ZLS files (a file, a directory of ``YYYY_HH.DDD`` files, or a list).

    Parameters
    ----------
    paths : path-like or sequence of path-like
        A directory is read in file-name order (hour files sort by time).

    Returns
    -------
    FormatTable
        ``format='zls'``, concatenated in the order read; columns in the module docstring.
        Lines of the wrong length or with unparsable fields are skipped and counted (per file
        in ``notes``).

    Raises
    ------
    DataError
        A path that does not exist, an empty directory, or a file in which fewer than half
        the lines are ZLS records (names the file and first bad line).
    """
    if isinstance(paths, (str, os.PathLike)):
        p = Path(paths)
        if p.is_dir():
            files = sorted(q for q in p.iterdir() if q.is_file() and not q.name.startswith("."))
            if not files:
                raise DataError(f"{p}: directory holds no ZLS files")
        else:
            files = [p]
    else:
        files = [Path(q) for q in paths]
    out = {"time": [], **{c: [] for c in _NUM_COLS}}
    names: set = set()
    ports: list = []
    notes, n_lines, skipped = [], 0, {}
    for f in files:
        tally = LineTally(f)
        before = len(out["time"])
        _read_one(f, tally, out, names, ports)
        tally.check_enough(len(out["time"]) - before, "ZLS")
        notes += tally.notes()
        n_lines += tally.n_lines
        for k, v in tally.counts.items():
            skipped[k] = skipped.get(k, 0) + v
    cols = {c: np.asarray(out[c], float) * (MGAL if c in _MGAL_COLS else 1.0) for c in _NUM_COLS}
    units = {c: ("m/s^2" if c in _MGAL_COLS else "meter units") for c in _NUM_COLS}
    units["platform_period"] = "s"
    return FormatTable(
        source=", ".join(os.fspath(f) for f in files),
        format="zls",
        time_ns=np.asarray(out["time"], dtype=np.int64),
        columns=cols,
        units=units,
        n_lines=n_lines,
        n_skipped=sum(skipped.values()),
        skipped=skipped,
        notes=notes,
        meta={"line_names": sorted(names), "par_port": ports[0] if ports else "", "files": len(files)},
    )
