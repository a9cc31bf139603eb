#!/usr/bin/env python
"""What identification costs per flight-hour (issue 12 item 7): default against identification off.

Usage::

    python benchmarks/bench_identification.py [--seeds 1507,1500,1103,1800,1804,1814] [--quick]
        [--rounds 2] [--base OTHER_CHECKOUT] [--cache DIR] [--json out.json]

Each seed is a flight of the unseen-flight generator (``gravsurvey.simulate.unseen``, as in
``bench_unseen.py``; ``--quick`` caps it at 40 min and 50 Hz), simulated once into the cache.
Per round and flight, each variant runs as its own process (``run_flight`` of
``bench_unseen.py``: the whole ``pipeline.run_survey``, outputs and plots written), in turn:

* ``default``: the configuration the simulator writes (only what a user knows), i.e. the
  model identified from the flight, and on a GNSS-aided strapdown flight the accelerometer noise
  chosen by likelihood (two or three whole estimates);
* ``off``: the same with ``model: {identify: false}`` (the configuration's fixed model: no
  spectral fits, no first pass, one estimate): the reference the issue's bound is stated on;
* ``base`` (with ``--base``): the default run by another checkout (e.g. a worktree at the
  commit before a change), paired with this one's.

One process per checkout runs first and is not counted, so that its numba cache is filled.  Prints a
Markdown table, per flight: its length, the estimates the default ran, the mean time of each
variant over the rounds (s) and its range, and the ratios default / off (the issue asks for at
most 2) and default / base.  The estimates' RMS against truth is printed beside (the same in
``default`` and ``base`` where a change only saves work).  Timings are reported, never asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SEEDS = (1507, 1500, 1103, 1800, 1804, 1814)
OFF = {"identify": False}


def _worker(repo: str, seed: int, quick: bool, cache: str, variant: str) -> dict:
    """One run in this process (``--worker``): time, RMS and the estimates the default ran."""
    sys.path.insert(0, str(Path(repo) / "benchmarks"))
    sys.path.insert(0, str(repo))
    from bench_unseen import prepare_flight, run_flight

    from gravsurvey.simulate.unseen import draw_flight_spec, limit_spec

    spec = draw_flight_spec(seed)
    if quick:
        spec = limit_spec(spec, 2400.0, 50.0)
    row = run_flight(spec, cache, ("default",), "altimeter", OFF if variant == "off" else None)
    folder = prepare_flight(spec, cache)
    out = folder / ("out_default_model" if variant == "off" else "out_default") / "summary.json"
    estimates = 1
    if variant != "off" and out.is_file():
        ident = json.loads(out.read_text())["flights"]["F01"]["estimator"].get("identification", {})
        choice = ident.get("accel_noise_mps2")
        if isinstance(choice, dict):
            estimates = len(choice.get("log_likelihood", {})) or 1
    return {
        "seed": seed,
        "variant": variant,
        "name": spec["name"],
        "hours": float(spec["duration_s"]) / 3600.0,
        "triad": spec["triad"],
        "seconds": row.get("default_s"),
        "rms_mgal": row.get("default_rms"),
        "estimates": estimates,
        "error": row.get("default_error"),
    }


def _run(repo: Path, seed: int, quick: bool, cache: Path, variant: str) -> dict:
    """:func:`_worker` in a fresh process of ``repo``'s code."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", str(repo), str(seed), str(cache), variant]
    if quick:
        cmd.append("--quick")
    env = {**os.environ, "PYTHONPATH": str(repo)}
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if p.returncode != 0:
        raise SystemExit(f"bench_identification: {variant} run of seed {seed} failed:\n{p.stderr[-2000:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def run(seeds=SEEDS, quick=False, rounds=2, base=None, cache=None) -> list[dict]:
    """Rows of the table (one per flight): times per variant over ``rounds`` rounds."""
    cache = Path(cache) if cache else REPO / "benchmarks" / ".unseen_cache"
    variants = ["default", "off"] + (["base"] if base else [])
    for repo in [REPO] + ([Path(base)] if base else []):
        _run(repo, seeds[0], quick, cache, "default")  # fills that checkout's numba cache; not counted
    got: dict = {}
    for _ in range(rounds):
        for seed in seeds:
            for v in variants:
                r = _run(Path(base) if v == "base" else REPO, seed, quick, cache, "default" if v == "base" else v)
                got.setdefault(seed, {}).setdefault(v, []).append(r)
    rows = []
    for seed in seeds:
        per = got[seed]
        first = per["default"][0]
        row = {k: first[k] for k in ("seed", "name", "hours", "triad", "estimates")}
        for v, runs in per.items():
            secs = [r["seconds"] for r in runs if r["seconds"] is not None]
            row[f"{v}_s"] = statistics.fmean(secs) if secs else None
            row[f"{v}_s_range"] = [min(secs), max(secs)] if secs else None
            row[f"{v}_rms_mgal"] = runs[0]["rms_mgal"]
            row[f"{v}_error"] = runs[0]["error"]
        row["default_over_off"] = row["default_s"] / row["off_s"] if row["default_s"] and row["off_s"] else None
        if base:
            row["default_over_base"] = (
                row["default_s"] / row["base_s"] if row["default_s"] and row.get("base_s") else None
            )
        rows.append(row)
    return rows


def _f(v, nd=2):
    return "-" if v is None else f"{v:.{nd}f}"


def print_table(rows, base=False) -> None:
    head = "| flight | h | estimates | default s | off s | default / off |"
    line = "|---|---|---|---|---|---|"
    if base:
        head += " base s | default / base |"
        line += "---|---|"
    print(head + (" RMS default / off / base, mGal |" if base else " RMS default / off, mGal |"))
    print(line + "---|")
    for r in rows:
        rng = r["default_s_range"] or [None, None]
        text = (
            f"| {r['name']} {r['triad']} | {_f(r['hours'])} | {r['estimates']} | {_f(r['default_s'], 1)} "
            f"({_f(rng[0], 1)}-{_f(rng[1], 1)}) | {_f(r['off_s'], 1)} | {_f(r['default_over_off'])} |"
        )
        if base:
            text += f" {_f(r.get('base_s'), 1)} | {_f(r.get('default_over_base'))} |"
        rms = f" {_f(r['default_rms_mgal'], 3)} / {_f(r['off_rms_mgal'], 3)}"
        if base:
            rms += f" / {_f(r.get('base_rms_mgal'), 3)}"
        print(text + rms + " |")
    ratios = [r["default_over_off"] for r in rows if r["default_over_off"] is not None]
    if ratios:
        print(
            f"\ndefault / off: median {statistics.median(ratios):.2f}, worst {max(ratios):.2f} (issue 12 item 7: <= 2)"
        )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default=",".join(str(s) for s in SEEDS))
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--base", default=None, help="another checkout whose default run is paired with this one's")
    ap.add_argument("--cache", default=None)
    ap.add_argument("--json", default=None)
    ap.add_argument("--worker", nargs=4, metavar=("REPO", "SEED", "CACHE", "VARIANT"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        repo, seed, cache, variant = a.worker
        print(json.dumps(_worker(repo, int(seed), a.quick, cache, variant)))
        return 0
    rows = run([int(s) for s in a.seeds.split(",") if s], a.quick, a.rounds, a.base, a.cache)
    print_table(rows, base=bool(a.base))
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
