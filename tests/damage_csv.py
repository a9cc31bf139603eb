"""Write damaged copies of sample_data/markov_csv for the consistency tests (no /work/shared)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data" / "markov_csv"
FILES = ("imu", "altimeter", "gnss", "truth")
NS = 10**9


def read(path):
    """(comment lines, header, rows as lists of strings)."""
    lines = Path(path).read_text().splitlines()
    com = [ln for ln in lines if ln.startswith("#")]
    body = [ln for ln in lines if not ln.startswith("#") and ln.strip()]
    return com, body[0], [r.split(",") for r in body[1:]]


def write(path, com, head, rows):
    Path(path).write_text("\n".join(com + [head] + [",".join(r) for r in rows]) + "\n")


def copy_sample(dst, config_extra: str = "", initial: dict | None = None) -> Path:
    """Copy the sample survey to ``dst``; append YAML text; return the config path."""
    dst = Path(dst)
    shutil.copytree(SAMPLE, dst)
    cfg = dst / "survey.yaml"
    text = cfg.read_text()
    if initial is not None:
        import re

        if "\n  initial:" not in text:  # the sample starts from the data: add the block
            text = re.sub(r"(\n  triad: [^\n]*)", "\\g<1>\n  initial:", text, count=1)
        for k, v in initial.items():
            if re.search(rf"\n    {k}: ", text):
                text = re.sub(rf"(\n    {k}: )[^\n]*", rf"\g<1>{v}", text)
            else:
                text = text.replace("\n  initial:", f"\n  initial:\n    {k}: {v}", 1)
    cfg.write_text(text + config_extra)
    return cfg


def edit(dst, name, fn):
    """Apply ``fn(head_list, rows) -> rows`` to F01/<name>.csv (rows: lists of str)."""
    p = Path(dst) / "F01" / f"{name}.csv"
    com, head, rows = read(p)
    rows = fn(head.split(","), rows)
    write(p, com, head, rows)


def t0_ns(dst):
    _, _, rows = read(Path(dst) / "F01" / "imu.csv")
    return int(rows[0][0])


def shift_after(dst, t_rel_s, shift_s, names=FILES):
    """Add ``shift_s`` to the time of every row after ``t_rel_s`` (a gap in those channels)."""
    t0 = t0_ns(dst)

    def fn(head, rows):
        for r in rows:
            if int(r[0]) > t0 + t_rel_s * NS:
                r[0] = str(int(r[0]) + int(shift_s * NS))
        return rows

    for n in names:
        edit(dst, n, fn)


def drop_between(dst, name, a_s, b_s):
    """Remove the rows of one channel between a_s and b_s (s after the start)."""
    t0 = t0_ns(dst)
    edit(dst, name, lambda h, rows: [r for r in rows if not (t0 + a_s * NS < int(r[0]) < t0 + b_s * NS)])


def hold_between(dst, name, a_s, b_s):
    """Every value of one channel between a_s and b_s repeats the last row before a_s (a stalled
    receiver or logger); the time stamps go on."""
    t0 = t0_ns(dst)

    def fn(head, rows):
        held = None
        for i, r in enumerate(rows):
            if t0 + a_s * NS <= int(r[0]) < t0 + b_s * NS:
                held = held or rows[i - 1][1:]
                r[1:] = held
        return rows

    edit(dst, name, fn)


def restart_clock(dst, name, at_s, back_s):
    """From ``at_s`` on, the channel's clock reads ``back_s`` less (a clock restart)."""
    shift_after(dst, at_s, -back_s, names=(name,))


def map_columns(dst, name, fn_by_col):
    """Replace values: {column: f(float ndarray) -> ndarray}."""

    def fn(head, rows):
        for col, f in fn_by_col.items():
            j = head.index(col)
            vals = f(np.array([float(r[j]) for r in rows]))
            for r, v in zip(rows, vals):
                r[j] = repr(float(v))
        return rows

    edit(dst, name, fn)


def swap_columns(dst, name, a, b):
    def fn(head, rows):
        i, j = head.index(a), head.index(b)
        for r in rows:
            r[i], r[j] = r[j], r[i]
        return rows

    edit(dst, name, fn)
