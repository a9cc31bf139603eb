#!/usr/bin/env python
"""Which numba kernels a run compiles (or loads from the cache), per signature, with CPU time.

Usage::

    python benchmarks/kernel_compiles.py CONFIG [--cache DIR] [--json OUT]

Runs ``gravsurvey run CONFIG`` in this process with ``Dispatcher.compile`` wrapped: every
call that compiles or loads a signature is timed (CPU, ``time.process_time``), exclusive of
the nested compilations of the kernels it calls.  With an empty ``--cache`` (default: a fresh
temporary folder) it lists the cold compilations, with a filled one the warm cache loads.
Prints a Markdown table, slowest first.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    out_json = None
    cache = None
    if "--json" in argv:
        i = argv.index("--json")
        out_json = argv[i + 1]
        del argv[i : i + 2]
    if "--cache" in argv:
        i = argv.index("--cache")
        cache = argv[i + 1]
        del argv[i : i + 2]
    config = argv[0]
    tmp = None
    if cache is None:
        tmp = tempfile.TemporaryDirectory(prefix="gravsurvey-kc-")
        cache = tmp.name
    os.environ["NUMBA_CACHE_DIR"] = cache
    t0 = time.process_time()
    w0 = time.perf_counter()
    import gravsurvey  # noqa: F401  (sets the cache folder before numba)
    from numba.core.dispatcher import Dispatcher

    records = []
    stack = []
    names: list = []
    orig = Dispatcher.compile

    def compile(self, sig):
        n_before = len(self.overloads)
        name = f"{self.py_func.__module__}.{self.py_func.__qualname__}"
        parent = names[-1] if names else None
        names.append(name)
        stack.append(0.0)
        c = time.process_time()
        try:
            return orig(self, sig)
        finally:
            incl = time.process_time() - c
            nested = stack.pop()
            names.pop()
            if stack:
                stack[-1] += incl
            if len(self.overloads) > n_before:
                hit = sum(self._cache_hits.values())
                records.append(
                    {
                        "kernel": name,
                        "parent": parent,
                        "sig": str(sig),
                        "incl": incl,
                        "excl": incl - nested,
                        "loaded": hit > 0 and self._cache_misses.get(sig, 0) == 0,
                        "t": time.perf_counter() - w0,
                    }
                )

    Dispatcher.compile = compile
    t_imp = time.process_time() - t0
    from gravsurvey.pipeline import run_survey

    t_imp2 = time.process_time() - t0
    with tempfile.TemporaryDirectory(prefix="gravsurvey-kc-out-") as out:
        c = time.process_time()
        w = time.perf_counter()
        run_survey(config, output_dir=out, force=True, plots=False)
        run_cpu = time.process_time() - c
        run_wall = time.perf_counter() - w
    records.sort(key=lambda r: -r["excl"])
    tot = sum(r["excl"] for r in records)
    print(
        f"imports {t_imp2:.2f} s CPU (gravsurvey {t_imp:.2f}); run {run_cpu:.2f} s CPU, {run_wall:.2f} s wall; "
        f"{len(records)} signatures, {tot:.2f} s CPU in compile/load; "
        f"{len({r['kernel'] for r in records})} kernels"
    )
    print("| kernel | signature | CPU s (excl.) | loaded |")
    print("|---|---|---|---|")
    for r in records:
        print(f"| {r['kernel']} | {r['sig'][:150]} | {r['excl']:.3f} | {r['loaded']} |")
    if out_json:
        Path(out_json).write_text(json.dumps(records, indent=1))
    if tmp is not None:
        tmp.cleanup()


if __name__ == "__main__":
    main()
