"""Measure the input-fault tables of docs/reliability.md (not a test: a script).

    python tests/fault_table.py [cases_per_cell] [seed]
    python tests/fault_table.py csv [cases] [seed]      (CSV cut anywhere; doc: 400 14)

Same faults and oracle as tests/test_io_faults.py (the ``mcap`` package's streaming reader on
the undamaged file says which records, and so which messages, the damage left intact), many more
cases, counted per fault class and file kind: intact messages lost before / after the first
damaged byte, losses that were not reported, exceptions other than our DataError.
"""

from __future__ import annotations

import random
import sys
import tempfile
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from test_io_faults import FLIGHT_S, KINDS, everything, intact, records, sample  # noqa: E402
from test_io_support import static_flight  # noqa: E402

from gravsurvey.errors import DataError, DataWarning, GravsurveyError  # noqa: E402
from gravsurvey.io.ingest import load_flight  # noqa: E402
from gravsurvey.io.mcap import read_mcap  # noqa: E402
from gravsurvey.settings import ingest_options

FAULTS = ("flip", "zero", "garbage", "cut")


def damage(kind, fault, rng):
    raw = bytearray(sample(kind))
    n = len(raw)
    if fault == "flip":
        pos = sorted({rng.randrange(n * 8) for _ in range(rng.randint(1, 3))})
        for p in pos:
            raw[p // 8] ^= 1 << (p % 8)
        return bytes(raw), [(p // 8, p // 8 + 1) for p in pos]
    if fault == "zero":
        a = rng.randrange(n)
        b = min(n, a + rng.randint(1, 4096))
        raw[a:b] = bytes(b - a)
        return bytes(raw), [(a, b)]
    if fault == "garbage":
        a = rng.randrange(n)
        junk = bytes(rng.randrange(256) for _ in range(rng.randint(1, 64)))
        raw[a : a + len(junk)] = junk
        return bytes(raw[:n]), [(a, min(n, a + len(junk)))]
    cut = rng.randrange(n)
    return bytes(raw[:cut]), [(cut, n)]


def one(kind, data, dmg):
    first = min(a for a, _ in dmg)
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "d.mcap"
        p.write_bytes(data)
        exc = None
        try:
            c = read_mcap(p, keep_raw=True)
            got = Counter((c.channels[ch].topic, lt, bytes(b)) for ch, _, lt, _, b in c.raw if ch in c.channels)
        except DataError:
            c, got = None, Counter()
        except Exception as e:  # noqa: BLE001 - counted, that is the point
            c, got, exc = None, Counter(), type(e).__name__
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DataWarning)
                load_flight(ingest_options({"inputs": {"mcap": "d.mcap"}}, "f"), tmp)
        except GravsurveyError:
            pass
        except Exception as e:  # noqa: BLE001
            exc = exc or type(e).__name__
    # decoded IMU samples against the truth: corrupted ones kept (time and values not a
    # true sample) and the largest value error among samples kept at a true time
    corrupt, worst, dropped = 0, 0.0, 0
    if c is not None:
        d = static_flight(seconds=FLIGHT_S)
        truth = {int(t): k for k, t in enumerate(d["imu_t"])}
        for cid, blk in c.decoded.items():
            if c.channels[cid].topic != "/imu":
                continue
            dropped += getattr(blk, "value_check_dropped", 0)
            for j, t in enumerate(blk.time_ns):
                k = truth.get(int(t))
                f, w = blk.values["specific_force"][j], blk.values["angular_rate"][j]
                if k is None:
                    corrupt += 1
                    continue
                err = max(float(np.max(np.abs(f - d["f"][k]))), float(np.max(np.abs(w - d["w"][k]))))
                if not err == 0.0:
                    corrupt += 1
                    worst = max(worst, err) if np.isfinite(err) else float("inf")
    want = intact(kind, dmg)
    recs = records(kind)
    before = Counter(m for s, e, ms in recs if e <= first for m in ms) & want
    after = want - before
    lost_before = sum((before - got).values())
    lost_after = sum((after - got).values())
    total_lost = sum(everything(kind).values()) - sum(got.values())
    said = c is None or c.salvage is not None or any("unknown opcodes" in n or "no footer" in n for n in c.notes)
    return dict(
        intact_after=sum(after.values()),
        lost_before=lost_before,
        lost_after=lost_after,
        unreported=int(total_lost > 0 and not said),
        corrupt_kept=corrupt,
        dropped=dropped,
        worst=worst,
        exc=exc,
    )


def main(per_cell=50, seed=0):
    rng = random.Random(seed)
    rows = []
    for fault in FAULTS:
        for kind in KINDS:
            agg = Counter()
            excs = Counter()
            for _ in range(per_cell):
                r = one(kind, *damage(kind, fault, rng))
                agg.update({k: v for k, v in r.items() if k not in ("exc", "worst")})
                agg["worst"] = max(agg["worst"], r["worst"])
                if r["exc"]:
                    excs[r["exc"]] += 1
            rows.append((fault, kind, per_cell, agg, excs))
    print(
        "| fault | file | cases | intact messages after the damage | lost before | "
        "lost after | losses not reported | other exceptions | IMU samples dropped by "
        "damage checks | corrupted IMU samples kept | their largest error |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---|---:|---:|---:|")
    for fault, kind, n, a, e in rows:
        print(
            f"| {fault} | {kind} | {n} | {a['intact_after']} | {a['lost_before']} | "
            f"{a['lost_after']} | {a['unreported']} | {dict(e) or 0} | {a['dropped']} | "
            f"{a['corrupt_kept']} | {a['worst']:.3g} |"
        )


def csv_cut_table(cases=400, seed=14):
    """The IMU CSV of tests/test_io_csv_faults.py cut at ``cases`` random bytes: how each cut
    was read, against the values the file was written from."""
    from test_io_csv_faults import texts

    from gravsurvey.io.csv import read_csv_channel

    full = texts()["imu"].encode()
    d = static_flight(seconds=3.0)
    out = Counter()
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "imu.csv"
        for frac in rng.random(cases):
            cut = int(frac * len(full))
            p.write_bytes(full[:cut])
            complete = max(0, full[:cut].count(b"\n") - 1)
            notes, loss = [], []
            try:
                t, v = read_csv_channel(p, "imu", notes=notes, data_loss=loss)
            except DataError:
                out["refused (DataError naming file and line)"] += 1
                continue
            n = len(t)
            exact = (
                n <= complete + 1
                and np.array_equal(t, d["imu_t"][:n])
                and np.array_equal(v["specific_force"], d["f"][:n])
                and np.array_equal(v["angular_rate"], d["w"][:n])
            )
            if not exact:
                out["WRONG: a value read that the file was not written with"] += 1
            elif n < complete:
                out["complete lines lost"] += 1
            elif n > complete:
                out["complete lines + the cut line, read exactly"] += 1
            elif loss:
                out["complete lines exact; cut line dropped, reported as damage"] += 1
            elif notes:
                out["complete lines exact; cut line dropped with a warning"] += 1
            else:
                out["complete lines exact; cut at a line end, nothing to say"] += 1
    print(f"| outcome ({cases} cuts, seed {seed}) | cases |\n|---|---:|")
    for k, n in sorted(out.items()):
        print(f"| {k} | {n} |")


if __name__ == "__main__":
    if sys.argv[1:2] == ["csv"]:
        csv_cut_table(*(int(x) for x in sys.argv[2:4]))
    else:
        main(*(int(x) for x in sys.argv[1:3]))
