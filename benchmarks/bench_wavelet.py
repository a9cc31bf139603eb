#!/usr/bin/env python
"""Speed of the wavelet post-processor (issue 5): full criterion search on one line.

Usage::

    python benchmarks/bench_wavelet.py [--quick]

Prints a Markdown table: method, N, seconds (best of repeats), and the complexity of the search.
``run(quick) -> list[dict]`` is what ``benchmarks/run.py`` calls.  Timings are reported, never
asserted.  Target (issue 5): N = 100,000 samples, full criterion search, under 1 s.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from gravsurvey import wavelet as W  # noqa: E402
from gravsurvey.errors import DataWarning  # noqa: E402

COMPLEXITY = {
    "ti_cosphi": "O(N log N) DCT + O(K N) for Phi at all K levels",
    "ti_cosphi+context": "as ti_cosphi, plus 2 DCTs over N + 2^(n+4) samples (gate, filter)",
    "cosphi": "K(s+1) syntheses O(N L K s) + Gram O(N (K s)^2) + search O(sweeps K^3 s^2)",
    "visushrink": "O(N L)",
    "sure": "O(N L + N log N)",
    "bayes": "O(N L)",
    "butterworth": "O(N log N)",
    "gaussian": "O(N log N)",
}


def _line(n, seed=0):
    """A smooth anomaly + band-limited noise like the smoother's error, 1 Hz, m/s^2."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    g = 1e-5 * (30 * np.sin(2 * np.pi * t / 3600) + 20 * np.sin(2 * np.pi * t / 1500 + 1))
    w = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n)
    w *= np.exp(-0.5 * ((np.log(np.maximum(f, 1e-9)) - np.log(1 / 200.0)) / 0.5) ** 2)
    e = np.fft.irfft(w, n)
    return g + 4e-5 * e / np.std(e)


def _time(fn, repeats):
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def run(quick: bool = False) -> list[dict]:
    """Rows: method, wavelet, N, K (levels searched), seconds (best of repeats), complexity."""
    sizes = (14_401, 100_000) if quick else (14_401, 100_000, 100_003)
    repeats = 2 if quick else 3
    rows = []
    W.postprocess(_line(2048), 1.0, 50.0, "cosphi", wavelet="db10")  # numba compile outside timing
    for n in sizes:
        z = _line(n)
        cases = [
            ("ti_cosphi", "db10"),
            ("ti_cosphi", "auto"),
            ("cosphi", "db10"),
            ("visushrink", "db10"),
            ("sure", "db10"),
            ("bayes", "db10"),
            ("butterworth", None),
            ("gaussian", None),
        ]
        cases.append(("ti_cosphi+context", "db10"))
        # the line cut from the middle of a flight twice its length (context=(z_full, a, b))
        z_full = _line(2 * n, seed=1)
        a = n // 2
        for method, wav in cases:
            kw = {"filter_length_s": 500.0} if wav is None else {"wavelet": wav}
            if method == "ti_cosphi+context":
                kw["context"] = (z_full, a, a + n)

            def call(method=method, kw=kw, z=z, z_full=z_full, a=a, n=n):
                zz = z_full[a : a + n] if "context" in kw else z
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", DataWarning)
                    return W.postprocess(zz, 1.0, 50.0, method.split("+")[0], **kw)

            sec = _time(call, repeats)
            _, info = call()
            rows.append(
                {
                    "method": method,
                    "wavelet": wav or "-",
                    "N": n,
                    "K": W.n_levels(n),
                    "level_n": info.get("n"),
                    "seconds": sec,
                    "complexity": COMPLEXITY[method],
                }
            )
    return rows


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    rows = run("--quick" in argv)
    print("| method | wavelet | N | K | chosen n | seconds | complexity |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['method']} | {r['wavelet']} | {r['N']} | {r['K']} | {r['level_n']} | "
            f"{r['seconds']:.3f} | {r['complexity']} |"
        )


if __name__ == "__main__":
    main()
