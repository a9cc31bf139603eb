#!/usr/bin/env python
"""The grid's equivalent-source fits: one Jacobian for every damping, against harmonica's own.

Usage::

    python benchmarks/bench_grid_fit.py [--sizes 1000,2000,4000] [--repeats 3]

The grid's cross-validation (``gravsurvey.grid``) fits point sources to each fold's training
points with each of :data:`gravsurvey.grid.DAMPINGS` and predicts the held-out points, then
fits all points once and predicts the grid's cells. Timed here, on random line data of ``n``
thinned points (16 north-south lines, 5 block folds as ``grid_lines`` makes them, a grid of
0.25 line spacings), paired in each repeat:

- *reference*: harmonica's ``EquivalentSources(depth, damping).fit`` for every fold and
  damping (verde's ``least_squares``: a new Jacobian, scaled, and sklearn's ridge each time),
  its Jacobian and ``predict`` the numpy-broadcast Green's function (as the grid had them until
  2026-12-05: harmonica's numba kernels cannot be cached);
- *gravsurvey*: :func:`gravsurvey.grid.point_source_fit` (one Jacobian and normal matrix per
  fold, a Cholesky solve per damping) and :func:`gravsurvey.grid.point_source_predict` (scipy's
  compiled distance loop, all dampings' coefficients in one product).

Prints seconds (median of the repeats, each run's in brackets), the speed-up, and the largest
difference between the two predictions (relative to the data's spread).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from gravsurvey.grid import DAMPINGS, point_source_fit, point_source_predict  # noqa: E402
from gravsurvey.pool import single_threaded_blas  # noqa: E402


def line_points(n: int, seed: int = 0):
    """``n`` thinned points on 16 north-south lines 2 km apart, heights 800-900 m, a smooth
    field plus 0.2 of noise; and the grid cells (0.25 line spacings)."""
    rng = np.random.default_rng(seed)
    lines = 16
    per = n // lines
    e = np.repeat(np.arange(lines) * 2000.0, per) + rng.normal(0.0, 20.0, lines * per)
    north = np.tile(np.linspace(0.0, 60000.0, per), lines)
    up = rng.uniform(800.0, 900.0, e.size)
    v = np.sin(e / 9000.0) * np.cos(north / 13000.0) + 0.2 * rng.standard_normal(e.size)
    ge, gn = np.meshgrid(np.arange(0.0, e.max(), 500.0), np.arange(0.0, 60000.0, 500.0))
    cells = (ge.ravel(), gn.ravel(), np.full(ge.size, 850.0))
    return (e, north, up), v, cells


def folds(coords, k: int = 5, seed: int = 0):
    import verde as vd

    blocks = vd.BlockKFold(spacing=2000.0, n_splits=k, shuffle=True, random_state=seed)
    return list(blocks.split(np.column_stack(coords[:2])))


def numpy_jacobian(coordinates, points):
    """The Green's function by numpy broadcasting (the grid's until 2026-12-05)."""
    d2 = (coordinates[0][:, None] - points[0][None, :]) ** 2
    d2 += (coordinates[1][:, None] - points[1][None, :]) ** 2
    d2 += (coordinates[2][:, None] - points[2][None, :]) ** 2
    return 1.0 / np.sqrt(d2)


def numpy_predict(coordinates, points, coefs, block: int = 2_000_000):
    c = tuple(np.asarray(x, float).ravel() for x in coordinates[:3])
    out = np.empty(c[0].size)
    step = max(1, block // max(1, coefs.size))
    for i in range(0, out.size, step):
        out[i : i + step] = numpy_jacobian(tuple(x[i : i + step] for x in c), points) @ coefs
    return out


def reference(coords, v, cells, splits, depth):
    import harmonica as hm

    out = []
    for tr, te in splits:
        for damping in DAMPINGS:
            eqs = hm.EquivalentSources(depth=depth, damping=damping)
            eqs.jacobian = numpy_jacobian
            eqs.fit(tuple(c[tr] for c in coords), v[tr])
            out.append(numpy_predict(tuple(c[te] for c in coords), eqs.points_, eqs.coefs_))
    eqs = hm.EquivalentSources(depth=depth, damping=DAMPINGS[0])
    eqs.jacobian = numpy_jacobian
    eqs.fit(coords, v)
    out.append(numpy_predict(cells, eqs.points_, eqs.coefs_))
    return out


def ours(coords, v, cells, splits, depth):
    out = []
    for tr, te in splits:
        points, coefs = point_source_fit(tuple(c[tr] for c in coords), v[tr], depth, DAMPINGS)
        pred = point_source_predict(tuple(c[te] for c in coords), points, coefs)
        out.extend(pred[:, k] for k in range(len(DAMPINGS)))
    points, coefs = point_source_fit(coords, v, depth, DAMPINGS[:1])
    out.append(point_source_predict(cells, points, coefs[:, 0]))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1000,2000,4000")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    print("| points | cells | reference s | gravsurvey s | speed-up | largest difference / data std |")
    print("|---|---|---|---|---|---|")
    for n in (int(x) for x in args.sizes.split(",")):
        coords, v, cells = line_points(n)
        splits = folds(coords)
        depth = 1.5 * 2000.0
        times = {"reference": [], "ours": []}
        diff = 0.0
        with single_threaded_blas():
            for rep in range(args.repeats):
                # paired, alternating which goes first
                order = (("reference", reference), ("ours", ours))
                results = {}
                for name, func in order if rep % 2 == 0 else order[::-1]:
                    t0 = time.perf_counter()
                    results[name] = func(coords, v, cells, splits, depth)
                    times[name].append(time.perf_counter() - t0)
                diff = max(
                    diff,
                    max(float(np.max(np.abs(a - b))) for a, b in zip(results["reference"], results["ours"])),
                )
        ref, our = statistics.median(times["reference"]), statistics.median(times["ours"])
        runs = ", ".join(f"{a:.2f}/{b:.2f}" for a, b in zip(times["reference"], times["ours"]))
        print(
            f"| {v.size} | {cells[0].size} | {ref:.2f} | {our:.2f} | {ref / our:.1f}x ({runs}) | "
            f"{diff / float(np.std(v)):.1e} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
