"""The 8-wide vector intrinsics (gravsurvey.inm.simd) against numpy, lane by lane."""

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from gravsurvey.inm.simd import vadd, vcol, vdiv, vget, vjoin, vload, vmul, vset, vsplat, vstore, vsub


@njit
def _ops(a, out):
    x = vload(a, 8, 8)  # row 1
    y = vcol(a, 2, 8, 8)  # column 2
    vstore(out, 0, vadd(x, y))
    vstore(out, 8, vsub(x, y))
    vstore(out, 16, vmul(x, y))
    vstore(out, 24, vdiv(x, y))
    vstore(out, 32, vmul(vsplat(a[0, 0], 8), y))
    vstore(out, 40, vset(x, 3, vget(y, 5)))
    return vget(x, 7)


@njit
def _ops6(a, out):
    x = vload(a, 16 + 2, 6)  # row 2, columns 2..7
    y = vcol(a, 8 + 3, 8, 6)  # column 3, rows 1..6
    vstore(out, 1, vadd(vmul(x, y), vsplat(0.5, 6)))


def test_vector_ops_equal_numpy_lane_by_lane():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(8, 8))
    a[1, 4] = 0.0
    a[1, 6] = -0.0
    out = np.full((6, 8), np.nan)
    last = _ops(a, out)
    x, y = a[1], a[:, 2]
    expected = np.stack([x + y, x - y, x * y, x / y, a[0, 0] * y, np.where(np.arange(8) == 3, y[5], x)])
    assert np.array_equal(out.view(np.uint64), expected.view(np.uint64))
    assert last == x[7]


def test_partial_width_vectors_touch_only_their_lanes():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(8, 8))
    out = np.full(8, -7.0)
    _ops6(a, out)
    expected = np.full(8, -7.0)
    expected[1:7] = a[2, 2:8] * a[1:7, 3] + 0.5
    assert np.array_equal(out, expected)


def test_offsets_address_rows_of_a_3d_array():
    @njit
    def copy_rows(src, dst, k):
        for i in range(4):
            vstore(dst, 32 * k + 8 * i, vload(src, 32 * k + 8 * i, 8))

    src = np.arange(3 * 4 * 8, dtype=float).reshape(3, 4, 8)
    dst = np.zeros_like(src)
    copy_rows(src, dst, 2)
    assert np.array_equal(dst[2], src[2]) and not dst[:2].any()


def test_non_contiguous_arrays_are_refused_at_compile_time():
    @njit
    def first_row(a):
        return vget(vload(a, 0, 8), 0)

    a = np.ones((8, 8))
    assert first_row(a) == 1.0
    with pytest.raises(TypingError):
        first_row(np.asfortranarray(a))


@njit
def _join(a, b, out, cut):
    vstore(out, 0, vjoin(vload(a, 0, 8), vload(b, 0, 8), cut))
    vstore(out, 8, vjoin(vload(a, 8, 6), vload(b, 8, 6), cut - 8))


@pytest.mark.parametrize("cut", [-3, 0, 1, 5, 8, 9, 13, 14, 20])
def test_join_takes_lanes_below_the_cut_from_the_first_vector(cut):
    a = np.arange(1.0, 15.0)
    b = -np.arange(1.0, 15.0)
    b[3] = -0.0
    out = np.full(14, np.nan)
    _join(a, b, out, cut)
    expected = np.where(np.arange(14) < cut, a, b)
    assert np.array_equal(out.view(np.uint64), expected.view(np.uint64))
