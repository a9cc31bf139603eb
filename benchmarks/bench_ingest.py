#!/usr/bin/env python
"""Ingestion speed: our MCAP reader vs the mcap package's decoders, our CSV reader vs pandas and
numpy (and its own line-by-line path), same files, same run.

Files: a simulated flight written by the simulator's writers (ROS 2 CDR and JSON MCAP, zstd
chunks, IMU + altimeter + GNSS), and the real ROS 2 recording ``robot_localization_test1.mcap``
when ``../shared/external`` is present.  For each file and reader: messages decoded per second
(all messages of the decodable sensor topics, best of ``repeats`` runs), and the ratio to us.

Readers:

* ``gravsurvey``: :func:`gravsurvey.io.mcap.read_mcap` (record scan in numba, bulk numpy CDR
  decoding, one ``json.loads`` per chunk's batch);
* ``mcap_ros2``: ``make_reader(..., decoder_factories=[mcap_ros2 DecoderFactory])
  .iter_decoded_messages()`` (one Python object per message);
* ``mcap+json.loads``: ``iter_decoded_messages`` with a JSON decoder factory (``json.loads``
  per message);
* ``mcap raw iteration``: ``iter_messages`` without decoding (the floor of any reader on top of
  the mcap package).

Run: ``python benchmarks/bench_ingest.py [--quick]``; the suite runner imports :func:`run`.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

EXTERNAL = REPO.parent / "shared" / "external"


def _flight(path: Path, seconds: float, imu_hz: float = 100.0):
    from gravsurvey.simulate.logs import SensorLogs, write_flight_logs

    rng = np.random.default_rng(1)
    start = 1_750_000_000_000_000_000
    n, m = int(seconds * imu_hz), int(seconds)
    ti = start + np.round(np.arange(n) * 1e9 / imu_hz).astype(np.int64)
    ta = start + np.arange(m, dtype=np.int64) * 10**9
    logs = SensorLogs(
        start,
        ti,
        rng.normal(0, 1, (n, 3)) + [0, 0, 9.8],
        rng.normal(0, 1e-4, (n, 3)),
        ta,
        1000 + rng.normal(0, 1, m),
        ta.copy(),
        45 + rng.normal(0, 1e-5, m),
        135 + rng.normal(0, 1e-5, m),
        1000 + rng.normal(0, 1, m),
    )
    files = write_flight_logs(path, "BENCH", ["mcap_json", "mcap_ros2", "csv"], logs)
    return {"json": files[0], "ros2": files[1], "csv": next(f for f in files[2:] if Path(f).name == "imu.csv")}


#: CSV readers, each run in a fresh process (its peak memory is the process's):
#: name -> the statement that reads ``path`` and leaves the sample count in ``n``.
CSV_READERS = {
    "gravsurvey": "from gravsurvey.io.csv import read_csv_channel as r; n = len(r(path, 'imu')[0])",
    "gravsurvey line by line": (
        "import gravsurvey.io.csv as c; c.PLAIN_READ_MIN_BYTES = 2**62; n = len(c.read_csv_channel(path, 'imu')[0])"
    ),
    "pandas.read_csv": "import pandas as pd; n = len(pd.read_csv(path, comment='#'))",
    "numpy.loadtxt": (
        "import numpy as np; n = len(np.loadtxt((ln for ln in open(path) if not ln.startswith(('#', 'time'))), "
        "delimiter=','))"
    ),
}


def _csv_in_process(stmt, path, repeats):
    """Best seconds over ``repeats`` fresh processes, their largest peak RSS (MiB), samples."""
    import subprocess

    code = (
        "import resource, sys, time\n"
        f"path = {str(path)!r}\n"
        "t = time.perf_counter()\n"
        f"{stmt}\n"
        "dt = time.perf_counter() - t\n"
        "print(n, dt, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)\n"
    )
    best, peak, n = float("inf"), 0.0, 0
    for _ in range(repeats):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO)
        a, b, c = out.stdout.split()
        n, best, peak = int(a), min(best, float(b)), max(peak, float(c))
    return n, best, peak


def _ours(path, topics):
    from gravsurvey.io.mcap import read_mcap

    c = read_mcap(path, topics=topics)
    return sum(len(b.time_ns) for b in c.decoded.values())


def _mcap_ros2(path, topics):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    n = 0
    with open(path, "rb") as fh:
        r = make_reader(fh, decoder_factories=[DecoderFactory()])
        for _ in r.iter_decoded_messages(topics=list(topics.values())):
            n += 1
    return n


class _JsonFactory:
    """mcap DecoderFactory: json.loads for message encoding ``json``."""

    def decoder_for(self, message_encoding, schema):
        return json.loads if message_encoding == "json" else None


def _mcap_json(path, topics):
    from mcap.reader import make_reader

    n = 0
    with open(path, "rb") as fh:
        r = make_reader(fh, decoder_factories=[_JsonFactory()])
        for _ in r.iter_decoded_messages(topics=list(topics.values())):
            n += 1
    return n


def _mcap_raw(path, topics):
    from mcap.reader import make_reader

    n = 0
    with open(path, "rb") as fh:
        for _ in make_reader(fh).iter_messages(topics=list(topics.values())):
            n += 1
    return n


def _time(fn, *args, repeats):
    best, n = float("inf"), 0
    for _ in range(repeats):
        t = time.perf_counter()
        n = fn(*args)
        best = min(best, time.perf_counter() - t)
    return n, best


def run(quick: bool = False) -> list[dict]:
    """Benchmark rows: file, encoding, reader, messages, seconds, msgs_per_s, ours_speedup.

    ``quick``: a 200 s flight at 100 Hz (20k IMU messages), 2 repeats; else 3600 s
    (360k IMU messages), 3 repeats.
    """
    from gravsurvey.io.mcap import read_mcap

    seconds, repeats = (200.0, 2) if quick else (3600.0, 3)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        files = _flight(Path(tmp), seconds)
        sim_topics = {"imu": "/imu", "altimeter": "/altimeter", "gnss": "/gnss"}
        cases = [
            (
                "simulated flight",
                "ros2",
                files["ros2"],
                sim_topics,
                [("mcap_ros2", _mcap_ros2), ("mcap raw iteration", _mcap_raw)],
            ),
            (
                "simulated flight",
                "json",
                files["json"],
                sim_topics,
                [("mcap+json.loads", _mcap_json), ("mcap raw iteration", _mcap_raw)],
            ),
        ]
        real = EXTERNAL / "ros2-imu" / "robot_localization_test1.mcap"
        if real.is_file():
            cases.append(
                (
                    "robot_localization_test1 (real)",
                    "ros2",
                    real,
                    {"imu": "/imu/data", "gnss": "/fix"},
                    [("mcap_ros2", _mcap_ros2), ("mcap raw iteration", _mcap_raw)],
                )
            )
        size_mb = Path(files["csv"]).stat().st_size / 1e6
        ours = None
        for name, stmt in CSV_READERS.items():
            n, t, peak = _csv_in_process(stmt, files["csv"], repeats)
            ours = ours or (n, t)
            if n != ours[0]:
                raise RuntimeError(f"{name} read {n} rows of {files['csv']}, we read {ours[0]}")
            rows.append(
                {
                    "file": f"simulated flight ({size_mb:.0f} MB)",
                    "encoding": "csv",
                    "reader": name,
                    "messages": n,
                    "seconds": t,
                    "msgs_per_s": n / t,
                    "ours_speedup": t / ours[1],
                    "peak_mib": peak,
                }
            )
        read_mcap(files["ros2"])  # load the numba kernels before timing
        for label, enc, path, topics, peers in cases:
            n0, t0 = _time(_ours, path, topics, repeats=repeats)
            rows.append(
                {
                    "file": label,
                    "encoding": enc,
                    "reader": "gravsurvey",
                    "messages": n0,
                    "seconds": t0,
                    "msgs_per_s": n0 / t0,
                    "ours_speedup": 1.0,
                }
            )
            for name, fn in peers:
                n, t = _time(fn, path, topics, repeats=repeats)
                if n != n0:
                    raise RuntimeError(f"{name} read {n} messages of {path}, we read {n0}")
                rows.append(
                    {
                        "file": label,
                        "encoding": enc,
                        "reader": name,
                        "messages": n,
                        "seconds": t,
                        "msgs_per_s": n / t,
                        "ours_speedup": t / t0,
                    }
                )
    return rows


def format_rows(rows) -> str:
    out = [
        "| file | enc | reader | messages | s | msgs/s | ours x faster | peak MiB (csv: the reading process) |",
        "|---|---|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        peak = f"{r['peak_mib']:.0f}" if "peak_mib" in r else "-"
        out.append(
            f"| {r['file']} | {r['encoding']} | {r['reader']} | {r['messages']} | "
            f"{r['seconds']:.4f} | {r['msgs_per_s']:.4g} | {r['ours_speedup']:.1f} | {peak} |"
        )
    return "\n".join(out)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    print(format_rows(run(ap.parse_args().quick)))
