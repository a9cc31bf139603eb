"""``gravsurvey check``: compare a run's outputs with a reference run within tolerances."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from .errors import DataError

_KEY_COLS = ("flight", "line", "time_unix_ns")
#: compared when in the reference; a column of the reference missing from the result is a difference
#: (``kalman_mgal``: 3D-INM smoothed estimate; ``unfiltered_mgal``: classic reduction before its low-pass)
_VALUE_COLS = ("disturbance_mgal", "kalman_mgal", "unfiltered_mgal", "lat_deg", "lon_deg", "height_m")
#: per-column tolerance scale relative to --tol-mgal (positions: degrees ~ 1e-7 = 1 cm, height 1 cm)
_ABS_TOL = {"lat_deg": 1e-7, "lon_deg": 1e-7, "height_m": 0.01}


def _read_profiles(path: Path) -> dict:
    if not path.is_file():
        raise DataError(f"{path}: not found (is this a gravsurvey output directory?)")
    with open(path, newline="") as fh:
        rows = list(csv.reader(line for line in fh if not line.startswith("#")))
    if not rows:
        raise DataError(f"{path}: empty")
    head = rows[0]
    cols = {h: [r[i] for r in rows[1:]] for i, h in enumerate(head)}
    for k in _KEY_COLS + ("disturbance_mgal",):
        if k not in cols:
            raise DataError(f"{path}: column {k!r} missing")
    return cols


def _check_complete(d: Path, role: str) -> dict:
    """The summary of output directory ``d`` after checking it is complete and unaltered.

    A gravsurvey run publishes ``summary.json`` last, listing the SHA-256 of every other
    output (``output_sha256``): a directory without it, or with a listed file missing or
    changed, is not a (complete) run and cannot serve as either side of a comparison.

    Raises
    ------
    DataError
        Naming the directory, its role (result or reference) and the first problem.
    """
    from .io.writers import file_sha256

    if not d.is_dir():
        raise DataError(f"{d}: {role} directory not found")
    sp = d / "summary.json"
    if not sp.is_file():
        raise DataError(
            f"{sp}: missing; the {role} is not a complete gravsurvey output "
            "(summary.json is written last by every successful run)"
        )
    try:
        summary = json.loads(sp.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise DataError(f"{sp}: unreadable {role} summary: {exc}") from None
    listed = summary.get("output_sha256") if isinstance(summary, dict) else None
    if not isinstance(listed, dict) or "profiles.csv" not in listed:
        raise DataError(f"{sp}: no output_sha256 list with profiles.csv; the {role} is incomplete")
    for name, digest in sorted(listed.items()):
        fp = d / name
        if not fp.is_file():
            raise DataError(f"{fp}: missing; listed in the {role}'s summary.json (incomplete {role})")
        if file_sha256(fp) != digest:
            raise DataError(f"{fp}: changed since the {role} run wrote it (SHA-256 differs from summary.json)")
    return summary


def _floats(v):
    return np.array([float(x) if x not in ("", "nan", "NaN") else np.nan for x in v])


def compare_runs(result_dir, reference_dir, *, tol_mgal: float = 0.05, tol_rms_mgal: float = 0.02) -> list[str]:
    """Differences beyond tolerance between two output directories, as readable lines.

    An empty list means the result agrees with the reference: every output file of the
    reference exists in the result; same flights, lines and epochs in ``profiles.csv``; every
    ``disturbance_mgal`` and ``kalman_mgal`` or ``unfiltered_mgal`` (whichever the reference
    has; a reference column missing from the result is a difference) within ``tol_mgal``; positions within 1 cm;
    per-line RMS vs truth and the crossover RMS in ``summary.json`` within ``tol_rms_mgal``.

    Raises
    ------
    DataError
        Either directory is not a complete, unaltered gravsurvey output (no ``summary.json``,
        or a file it lists is missing or changed): nothing to compare against (exit 1).
    """
    res, ref = Path(result_dir), Path(reference_dir)
    sum_ref = _check_complete(ref, "reference")
    sum_res = _check_complete(res, "result")
    diffs = [
        f"{name}: in the reference, missing from the result"
        for name in sorted(set(sum_ref["output_sha256"]) - set(sum_res["output_sha256"]))
    ]
    a = _read_profiles(res / "profiles.csv")
    b = _read_profiles(ref / "profiles.csv")
    ka = list(zip(*(a[k] for k in _KEY_COLS)))
    kb = list(zip(*(b[k] for k in _KEY_COLS)))
    if ka != kb:
        set_a, set_b = set(ka), set(kb)
        only_a, only_b = len(set_a - set_b), len(set_b - set_a)
        diffs.append(
            f"profiles.csv: epochs differ: {len(ka)} rows vs {len(kb)} in the reference "
            f"({only_a} only in result, {only_b} only in reference)"
        )
        return diffs
    for col in _VALUE_COLS:
        if col in b and col not in a:
            diffs.append(f"profiles.csv: column {col} of the reference missing from the result")
            continue
        if col not in b:
            continue
        va, vb = _floats(a[col]), _floats(b[col])
        tol = _ABS_TOL.get(col, tol_mgal)
        nan_mismatch = np.isnan(va) != np.isnan(vb)
        d = np.abs(va - vb)
        bad = nan_mismatch | (d > tol)
        if bad.any():
            i = int(np.flatnonzero(bad)[np.argmax(np.nan_to_num(d[bad], nan=np.inf))])
            diffs.append(
                f"profiles.csv {col}: {int(bad.sum())} of {len(va)} values differ by more than {tol:g}; "
                f"worst at flight {ka[i][0]} line {ka[i][1] or '-'} t={ka[i][2]}: {va[i]:.4f} vs {vb[i]:.4f}"
            )
    # both summaries exist and were checked by _check_complete
    sa, sb = sum_res, sum_ref
    pairs = [
        ("crossovers.rms_mgal", sa.get("crossovers", {}).get("rms_mgal"), sb.get("crossovers", {}).get("rms_mgal")),
        ("rms_vs_truth_mgal", sa.get("rms_vs_truth_mgal"), sb.get("rms_vs_truth_mgal")),
    ]
    for fname, fb in sb.get("flights", {}).items():
        fa = sa.get("flights", {}).get(fname)
        if fa is None:
            diffs.append(f"summary.json: flight {fname} missing from the result")
            continue
        for lname, lb in fb.get("lines", {}).items():
            la = fa.get("lines", {}).get(lname, {})
            pairs.append(
                (
                    f"flights.{fname}.lines.{lname}.rms_vs_truth_mgal",
                    la.get("rms_vs_truth_mgal"),
                    lb.get("rms_vs_truth_mgal"),
                )
            )
    for key, x, y in pairs:
        if x is None and y is None:
            continue
        if x is None or y is None or abs(x - y) > tol_rms_mgal:
            diffs.append(f"summary.json {key}: {x} vs reference {y} (tolerance {tol_rms_mgal:g} mGal)")
    return diffs
