"""Linear Kalman filter (Joseph form) and Rauch-Tung-Striebel smoother kernels.

Epoch convention (the same as filterpy's ``batch_filter`` followed by
``KalmanFilter.rts_smoother``): epoch 0 updates the prior ``(x0, P0)`` with
``z[0]``; epoch ``k >= 1`` first predicts with ``phi[k]`` (transition from
``k-1`` to ``k``) and ``q[k]``, then updates with ``z[k]``.  ``phi[0]`` and
``q[0]`` are not used.

Measurements: ``z`` has shape ``(N, m)``; a NaN component is missing and is
left out of that epoch's update (so epochs without data are pure
predictions).  ``h`` is ``(N, m, n)`` and ``r`` ``(N, m, m)``.

Both a numba kernel (``kalman_filter``/``rts_smoother``) and a pure-numpy
reference (``kalman_filter_ref``/``rts_smoother_ref``) are provided; tests
check one against the other and both against filterpy.

Speed notes: no fastmath anywhere (results are bit-for-bit reproducible across machines).  For
n = 8 and a diagonal R each epoch is one call of a generated step (:mod:`gravsurvey.inm._unrolled`)
that keeps every covariance row in an 8-wide vector (:mod:`gravsurvey.inm.simd`): 0.6 us per
epoch for filter + smoother against 1.4 us for the generic loops below (14,401 epochs), and the
same numbers to the last bit (tested).  For n = 14 (the GNSS-aided model a default run uses) the
steps are hand-written vector loops (:mod:`gravsurvey.inm.kalman14`: rows as 8 + 6 lanes, zero
coefficients of phi and h skipped, upper triangles only, the smoother's gains computed block-wise
in a forward sweep), also bit-for-bit the generic loops' numbers (~6 s of compilation, in place of the generic
loops' for n = 14; generated 14-state steps took ~27 s, :mod:`gravsurvey.inm.codegen`); the generic
loops still take their 14 x 14 products and triangular solves from generated vector loops
(``matmul14``, ``tri_solve14``; the Van Loan discretisation uses ``matmul14`` too).  The
fixed-size steps sit in their own compiled loops (:func:`_filter_loop8`, :func:`_rts_loop8`,
:func:`_filter_loop14`, :func:`_rts_loop14`) so that other state sizes never compile them, and
the full-R update uses no ``np.linalg`` (:func:`_update`): both for the cold start.  Every other
size (16 with the accelerometer biases, the platform default; 18 with the horizontal
disturbance) takes the generic loops (any n, any R; for 16 with the generated ``matmul16``,
``tri_solve16``): scalar measurement updates in O(n^2); small products in scalar-accumulator
column blocks (:func:`_matmul`).  Outputs: one 2-MiB-aligned allocation by numpy, not inside the
kernels (:func:`_outputs`: page faults); ``phi[k+1] P_f[k]`` from the prediction reused by the
smoother (:func:`filter_and_smooth`); the backward sweep reads its inputs block-wise forwards
first (prefetching).  Measured: docs/benchmarks.md, "Kalman filter".

Agreement with filterpy on the 14-state model, and why it needs the true-error basis
(:func:`change_basis`, :func:`gravsurvey.inm.errormodel.true_error_basis`): docs/benchmarks.md,
"Kalman filter: speed and agreement".

numba's on-disk cache tracks only the file that defines a function: after editing
``simd.py`` or ``kalman14.py`` (its steps are inlined into this module's loops) or regenerating
``_unrolled.py``, delete this module's cached kernels
(``inm_*/kalman.*.nb?`` in the kernel cache folder, :func:`gravsurvey.setup_numba_cache`), or
they keep the old steps.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._unrolled import filter_step8, matmul8, matmul14, matmul16, rts_step8, tri_solve8, tri_solve14, tri_solve16
from .kalman14 import N14, filter_step14, rts_gain14, rts_update14


# --------------------------------------------------------------------------
# Matrix exponential (used for the Van Loan discretisation)
# --------------------------------------------------------------------------


@njit(cache=True)
def expm(a):
    """Matrix exponential by scaling and squaring with a degree-16 Taylor series.

    The matrix is scaled so that its 1-norm is <= 0.25; the truncation error
    is then below 0.25**17/17! ~ 1e-25 relative, i.e. round-off limited.

    Parameters
    ----------
    a : ndarray, shape (n, n)

    Returns
    -------
    ndarray, shape (n, n)
    """
    n = a.shape[0]
    norm = 0.0
    for j in range(n):
        s = 0.0
        for i in range(n):
            s += abs(a[i, j])
        if s > norm:
            norm = s
    sq = 0
    if norm > 0.25:
        sq = int(math.ceil(math.log2(norm / 0.25)))
    scale = 1.0 / (2.0**sq)
    x = a * scale
    result = np.eye(n)
    term = np.eye(n)
    for k in range(1, 17):
        term = term @ x / k
        result += term
    for _ in range(sq):
        result = result @ result
    return result


@njit(cache=True)
def matmul_into(a, b, out):
    """``out = a @ b`` for square matrices, no allocation (public: the error model uses it).

    Parameters
    ----------
    a, b : ndarray (n, n)
        C-contiguous float64.
    out : ndarray (n, n)
        Written in place; must not alias ``a`` or ``b``.

    Generated vector code for n = 8, 14 and 16, :func:`_matmul` otherwise; the same rounding
    either way.
    """
    n = a.shape[0]
    if n == 8:
        matmul8(a, b, out)
    elif n == 14:
        matmul14(a, b, out)
    elif n == 16:
        matmul16(a, b, out)
    else:
        _matmul(a, b, out, False)


#: Van Loan's Taylor series stops at the first term whose bound is below this (relative).
TAYLOR_TOL = 2.4e-18


@njit(cache=True)
def van_loan(a, qc, dt):
    """Exact discretisation of ``dx/dt = A x + w``, ``E[w w^T] = Qc delta``, over ``dt``.

    Van Loan (1978): ``expm(M)`` of ``M = [[-A dt, Qc dt], [0, A^T dt]]`` holds
    ``[[expm(-A dt), E12], [0, expm(A dt)^T]]`` and ``Qd = expm(A dt) E12``.  The exponential
    is taken by scaling and squaring with a Taylor series, on the blocks: with ``X = -A dt s``
    (``s = 2^-j`` scales the 1-norm of ``M`` to <= 0.25), ``M^k = [[X^k, Y_k], [0, (-X^T)^k]]``
    and ``Y_k = X^(k-1) Q + Y_(k-1) (-X^T)``, so one power sequence of ``X`` gives both
    diagonal blocks (``expm(A dt) = sum (-1)^k X^k / k!``) and each term costs three n x n
    products instead of one (2n x 2n) product (8 n^3); the products are :func:`matmul_into` (BLAS
    calls cost more than the arithmetic at this size).
    Taylor terms up to ``K``, the fewest for which the first omitted term is below
    ``2.4e-18`` relative (``||M s||^(K+1) / (K+1)! <= 2.4e-18``): thirteen at the scaled norm's
    bound 0.25, eight at 0.025 (the balanced 14-state model of a 1 s epoch,
    :func:`gravsurvey.inm.errormodel.balance_scales`), so a balanced model needs no squaring
    and ~40 % fewer products.

    Returns
    -------
    phi : ndarray (n, n)
        ``expm(A dt)``.
    qd : ndarray (n, n)
        ``int_0^dt expm(A s) Qc expm(A s)^T ds`` (symmetrised).
    """
    n = a.shape[0]
    # 1-norm of M: columns of [X; 0] and of [Q; -X^T]
    norm = 0.0
    for j in range(n):
        c1 = 0.0
        c2 = 0.0
        for i in range(n):
            c1 += abs(a[i, j])
            c2 += abs(qc[i, j]) + abs(a[j, i])
        norm = max(norm, c1 * dt, c2 * dt)
    sq = 0
    if norm > 0.25:
        sq = int(math.ceil(math.log2(norm / 0.25)))
    s = dt / (2.0**sq)
    ns = norm / (2.0**sq)
    kmax = 1
    bound = 0.5 * ns * ns  # ||M s||^(K+1) / (K+1)!, the first omitted term, K = kmax
    while bound > TAYLOR_TOL and kmax < 13:
        kmax += 1
        bound *= ns / (kmax + 1)
    x = -a * s
    xt = np.ascontiguousarray(x.T)
    qs = qc * s
    e11 = np.eye(n)  # sum X^k / k!
    f = np.eye(n)  # sum (-X)^k / k! = expm(A dt s)
    e12 = qs.copy()  # sum Y_k / k!
    t = x.copy()  # X^k / k!
    u = qs.copy()  # Y_k / k!
    t_new = np.empty((n, n))
    u_new = np.empty((n, n))
    tmp = np.empty((n, n))
    ft = np.empty((n, n))
    e11 += t
    f -= t
    for k in range(2, kmax + 1):
        # U_k = (T_(k-1) Q - U_(k-1) X^T) / k;  T_k = T_(k-1) X / k
        matmul_into(t, qs, u_new)
        matmul_into(u, xt, tmp)
        matmul_into(t, x, t_new)
        sign = 1.0 if k % 2 == 0 else -1.0
        rk = 1.0 / k  # a multiply per element, not a division (those dominated this loop)
        for i in range(n):  # one fused pass (numba's array expressions would be seven)
            for j in range(n):
                uv = (u_new[i, j] - tmp[i, j]) * rk
                tv = t_new[i, j] * rk
                u_new[i, j] = uv
                t_new[i, j] = tv
                e11[i, j] += tv
                e12[i, j] += uv
                f[i, j] += sign * tv
        t, t_new = t_new, t
        u, u_new = u_new, u
    # squaring: [[E11, E12], [0, F^T]]^2 = [[E11^2, E11 E12 + E12 F^T], [0, (F^2)^T]]
    for _ in range(sq):
        matmul_into(e11, e12, tmp)
        transpose_into(f, ft)
        matmul_into(e12, ft, u_new)
        for i in range(n):
            for j in range(n):
                e12[i, j] = tmp[i, j] + u_new[i, j]
        matmul_into(e11, e11, t_new)
        e11, t_new = t_new, e11
        matmul_into(f, f, t_new)
        f, t_new = t_new, f
    phi = f
    qd = np.empty((n, n))
    matmul_into(phi, e12, qd)
    qd = 0.5 * (qd + qd.T)
    return phi, qd


# --------------------------------------------------------------------------
# Compiled filter and smoother
# --------------------------------------------------------------------------


@njit(cache=True)
def _update(x, p, z, h, r, nis_out, kg, ph):
    """Joseph-form update in place with a full ``R`` (finite components of ``z`` only); writes
    the whitened innovations into ``nis_out`` (NaN where ``z`` is NaN).

    The measurement is decorrelated by the Cholesky factor of its ``R``: ``L^-1 z = L^-1 H x +
    w`` with ``w`` white, then updated one scalar at a time (:func:`_scalar_update`).  That is
    the batch update exactly (up to rounding), and the scalar updates' normalised innovations
    are ``L_S^-1 nu`` with ``L_S`` the Cholesky factor of the innovation covariance
    ``S = H P H^T + R``: the same whitening as before.  No ``np.linalg``: its kernels (LAPACK
    wrappers with their error paths) took ~7 s of CPU to compile on a cold cache, for an update
    a default run never makes (its ``R`` is diagonal).  ``R`` must be positive definite on the
    finite components.
    """
    m = z.shape[0]
    n = x.shape[0]
    idx = np.empty(m, dtype=np.int64)
    cnt = 0
    for i in range(m):
        nis_out[i] = np.nan
        if not math.isnan(z[i]):
            idx[cnt] = i
            cnt += 1
    if cnt == 0:
        return
    lr = np.empty((cnt, cnt))
    for a in range(cnt):
        for b in range(a + 1):
            acc = r[idx[a], idx[b]]
            for c in range(b):
                acc -= lr[a, c] * lr[b, c]
            if a == b:
                lr[a, a] = math.sqrt(acc)
            else:
                lr[a, b] = acc / lr[b, b]
    # forward substitution, row by row: the whitened measurement and its row of H
    zw = np.empty(cnt)
    hw = np.empty((cnt, n))
    for a in range(cnt):
        acc = z[idx[a]]
        for c in range(a):
            acc -= lr[a, c] * zw[c]
        zw[a] = acc / lr[a, a]
        for j in range(n):
            acc = h[idx[a], j]
            for c in range(a):
                acc -= lr[a, c] * hw[c, j]
            hw[a, j] = acc / lr[a, a]
    for a in range(cnt):
        nis_out[idx[a]] = _scalar_update(x, p, zw[a], hw[a], 1.0, kg, ph)


@njit(cache=True)
def _matmul(a, b, out, upper):
    """``out = a @ b`` for small square matrices, no allocation.

    With ``upper`` only the upper triangle ``j >= i`` is guaranteed (row ``i`` starts at the
    column block ``4 * (i // 4)``, so a few elements below the diagonal are computed too).

    Each output element is the sum over ``l = 0, 1, ...`` of ``a[i, l] b[l, j]`` in that order
    (the same rounding as a plain triple loop).  Columns are processed in blocks of 8 and 4
    held in scalar accumulators: without this, aliasing between ``out`` and ``b`` forces a
    load/store of ``out`` per multiply-add, which dominates for n = 8..14.
    """
    n = a.shape[0]
    for i in range(n):
        j = 4 * (i // 4) if upper else 0
        while j + 8 <= n:
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            s3 = 0.0
            s4 = 0.0
            s5 = 0.0
            s6 = 0.0
            s7 = 0.0
            for l in range(n):
                c = a[i, l]
                s0 += c * b[l, j]
                s1 += c * b[l, j + 1]
                s2 += c * b[l, j + 2]
                s3 += c * b[l, j + 3]
                s4 += c * b[l, j + 4]
                s5 += c * b[l, j + 5]
                s6 += c * b[l, j + 6]
                s7 += c * b[l, j + 7]
            out[i, j] = s0
            out[i, j + 1] = s1
            out[i, j + 2] = s2
            out[i, j + 3] = s3
            out[i, j + 4] = s4
            out[i, j + 5] = s5
            out[i, j + 6] = s6
            out[i, j + 7] = s7
            j += 8
        while j + 4 <= n:
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            s3 = 0.0
            for l in range(n):
                c = a[i, l]
                s0 += c * b[l, j]
                s1 += c * b[l, j + 1]
                s2 += c * b[l, j + 2]
                s3 += c * b[l, j + 3]
            out[i, j] = s0
            out[i, j + 1] = s1
            out[i, j + 2] = s2
            out[i, j + 3] = s3
            j += 4
        while j < n:
            s0 = 0.0
            for l in range(n):
                s0 += a[i, l] * b[l, j]
            out[i, j] = s0
            j += 1


@njit(cache=True)
def _tri_solve(lch, idg, b, forward):
    """:func:`_tri_solve_rows` by generated vector loops for n = 8, 14 and 16 (same rounding)."""
    n = b.shape[0]
    if n == 8:
        tri_solve8(lch, idg, b, forward)
    elif n == 14:
        tri_solve14(lch, idg, b, forward)
    elif n == 16:
        tri_solve16(lch, idg, b, forward)
    else:
        _tri_solve_rows(lch, idg, b, forward)


@njit(cache=True)
def _tri_solve_rows(lch, idg, b, forward):
    """In place ``b <- L^-1 b`` (``forward``) or ``b <- L^-T b``; ``idg = 1 / diag(L)``.

    Row ``i`` is ``(b[i] - sum_l L[i, l] b[l]) * idg[i]`` with ``l`` ascending (forward) or
    ``(b[i] - sum_l L[l, i] b[l]) * idg[i]`` with ``l`` from ``i + 1`` up (backward); the
    columns are held in scalar accumulators in blocks of 8 and 4 (see :func:`_matmul`).
    """
    n = b.shape[0]
    for ii in range(n):
        i = ii if forward else n - 1 - ii
        lo = 0 if forward else i + 1
        hi = i if forward else n
        g = idg[i]
        j = 0
        while j + 8 <= n:
            s0 = b[i, j]
            s1 = b[i, j + 1]
            s2 = b[i, j + 2]
            s3 = b[i, j + 3]
            s4 = b[i, j + 4]
            s5 = b[i, j + 5]
            s6 = b[i, j + 6]
            s7 = b[i, j + 7]
            for l in range(lo, hi):
                c = lch[i, l] if forward else lch[l, i]
                s0 -= c * b[l, j]
                s1 -= c * b[l, j + 1]
                s2 -= c * b[l, j + 2]
                s3 -= c * b[l, j + 3]
                s4 -= c * b[l, j + 4]
                s5 -= c * b[l, j + 5]
                s6 -= c * b[l, j + 6]
                s7 -= c * b[l, j + 7]
            b[i, j] = s0 * g
            b[i, j + 1] = s1 * g
            b[i, j + 2] = s2 * g
            b[i, j + 3] = s3 * g
            b[i, j + 4] = s4 * g
            b[i, j + 5] = s5 * g
            b[i, j + 6] = s6 * g
            b[i, j + 7] = s7 * g
            j += 8
        while j + 4 <= n:
            s0 = b[i, j]
            s1 = b[i, j + 1]
            s2 = b[i, j + 2]
            s3 = b[i, j + 3]
            for l in range(lo, hi):
                c = lch[i, l] if forward else lch[l, i]
                s0 -= c * b[l, j]
                s1 -= c * b[l, j + 1]
                s2 -= c * b[l, j + 2]
                s3 -= c * b[l, j + 3]
            b[i, j] = s0 * g
            b[i, j + 1] = s1 * g
            b[i, j + 2] = s2 * g
            b[i, j + 3] = s3 * g
            j += 4
        while j < n:
            s0 = b[i, j]
            for l in range(lo, hi):
                c = lch[i, l] if forward else lch[l, i]
                s0 -= c * b[l, j]
            b[i, j] = s0 * g
            j += 1


@njit(cache=True)
def transpose_into(a, out):
    """``out = a.T`` for a square matrix, no allocation (public: the error model uses it).

    Parameters
    ----------
    a : ndarray (n, n)
    out : ndarray (n, n)
        Written in place; must not alias ``a``.
    """
    n = a.shape[0]
    for i in range(n):
        for j in range(n):
            out[j, i] = a[i, j]


@njit(cache=True)
def _predict_into(phi, q, x, p, tmp, phit, xout, pout, xout2, pout2):
    """xout, xout2 <- phi x; pout, pout2 <- phi p phi^T + sym(q) (upper triangle mirrored).

    ``tmp`` <- phi p.  No allocation.
    """
    n = x.shape[0]
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += phi[i, j] * x[j]
        xout[i] = acc
        xout2[i] = acc
    matmul_into(phi, p, tmp)
    transpose_into(phi, phit)
    matmul_into(tmp, phit, pout)
    for i in range(n):
        for j in range(i, n):
            v = pout[i, j] + 0.5 * (q[i, j] + q[j, i])
            pout[i, j] = v
            pout[j, i] = v
            pout2[i, j] = v
            pout2[j, i] = v


@njit(cache=True)
def _scalar_update(x, p, z, h, r, k, ph):
    """Joseph-form update with one scalar measurement in O(n^2); returns the whitened innovation.

    With ``k = P h / s`` and ``s = h^T P h + r``:
    ``(I - k h^T) P (I - k h^T)^T + r k k^T = P - k (P h)^T - (P h) k^T + s k k^T``.
    """
    n = x.shape[0]
    # P h as a sum of rows (P is exactly symmetric)
    for j in range(n):
        ph[j] = 0.0
    for i in range(n):
        c = h[i]
        if c != 0.0:
            for j in range(n):
                ph[j] += c * p[i, j]
    s = r
    nu = z
    for i in range(n):
        s += h[i] * ph[i]
        nu -= h[i] * x[i]
    for i in range(n):
        k[i] = ph[i] / s
    for i in range(n):
        x[i] += k[i] * nu
    for i in range(n):
        ki = k[i]
        phi_ = ph[i]
        ski = s * ki
        for j in range(i, n):
            v = p[i, j] - ki * ph[j] - phi_ * k[j] + ski * k[j]
            p[i, j] = v
            p[j, i] = v
    return nu / math.sqrt(s)


@njit(cache=True)
def _diagonal_at(r, k):
    """Whether ``r[k]`` is diagonal (without creating the row view)."""
    m = r.shape[1]
    for i in range(m):
        for j in range(m):
            if i != j and r[k, i, j] != 0.0:
                return False
    return True


def kalman_filter(x0, p0, phi, q, z, h, r, unrolled=True):
    """Forward Kalman filter over ``N`` epochs (numba kernel :func:`_kalman_filter_into`).

    The outputs are allocated here, as one huge-page-aligned block (:func:`_outputs`), rather
    than inside the kernel: with numba's allocator every call page-faulted ~2000 4-KiB pages per
    (N, 8, 8) array, a third of the run time.

    Parameters
    ----------
    x0 : ndarray (n,)
        Prior state at epoch 0.
    p0 : ndarray (n, n)
        Prior covariance at epoch 0.
    phi, q : ndarray (N, n, n)
        Transition from epoch k-1 to k and its process noise (index 0 unused).
    z : ndarray (N, m)
        Measurements, NaN = missing.
    h : ndarray (N, m, n)
    r : ndarray (N, m, m)
    unrolled : bool
        Use the fixed-size vector steps where they apply (n = 8: generated,
        :mod:`gravsurvey.inm.codegen`; n = 14: :mod:`gravsurvey.inm.kalman14`); ``False`` forces
        the generic loops (same numbers).

    Returns
    -------
    x_f, p_f : ndarray (N, n), (N, n, n)
        Filtered (a posteriori) state and covariance.
    x_p, p_p : ndarray (N, n), (N, n, n)
        Predicted (a priori) state and covariance (epoch 0: the prior).
    innov : ndarray (N, m)
        Innovations whitened by the Cholesky factor of their covariance (NaN if missing).
    """
    # C-contiguous float64 throughout: the vector kernels address rows by flat offsets
    x0, p0, phi, q, z, h, r = (np.ascontiguousarray(a, dtype=float) for a in (x0, p0, phi, q, z, h, r))
    nep = phi.shape[0]
    n = x0.shape[0]
    m = z.shape[1]
    x_f, p_f, x_p, p_p, innov = _outputs(((nep, n), (nep, n, n), (nep, n), (nep, n, n), (nep, m)))
    _kalman_filter_into(x0, p0, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, np.empty((1, n, n)), unrolled)
    return x_f, p_f, x_p, p_p, innov


def _kalman_filter_into(x0, p0, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf, unrolled):
    """Kernel of :func:`kalman_filter`; writes into the preallocated outputs.

    If ``phi_pf`` has ``N`` rows, ``phi_pf[k - 1] = phi[k] @ p_f[k - 1]`` (a by-product of the
    prediction, stored one row down so that the smoother's ``p_s`` can hold it) is kept for the
    smoother; give it one row to discard it.  ``unrolled``: use the fixed-size vector steps
    where they apply (n = 8: :mod:`gravsurvey.inm._unrolled`; n = 14:
    :mod:`gravsurvey.inm.kalman14`; diagonal R), same numbers.

    Separate compiled loops, chosen here: with the fixed-size steps in the same kernel, numba
    would compile them for every state size (~4 s of CPU on a cold cache for the 8-state step).
    """
    if unrolled and x0.shape[0] == 8:
        _filter_loop8(x0, p0, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf)
    elif unrolled and x0.shape[0] == N14:
        _filter_loop14(x0, p0, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf)
    else:
        _filter_loop(x0, p0, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf)


@njit(cache=True)
def _filter_loop(x0, p0, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf):
    """Every epoch by the generic loops (:func:`_filter_epoch`)."""
    n = x0.shape[0]
    phit = np.empty((n, n))
    kg = np.empty(n)
    ph = np.empty(n)
    for k in range(phi.shape[0]):
        _filter_epoch(k, x0, p0, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf, phit, kg, ph)


@njit(cache=True)
def _filter_loop8(x0, p0, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf):
    """n = 8: the generated step wherever R is diagonal, the generic loops elsewhere."""
    n = x0.shape[0]
    keep = phi_pf.shape[0] == phi.shape[0]
    phit = np.empty((n, n))
    kg = np.empty(n)
    ph = np.empty(n)
    for k in range(phi.shape[0]):
        # the fixed-size step takes whole arrays and k: no row views (each costs atomic
        # reference-count updates, comparable to the arithmetic of a step)
        if k > 0 and _diagonal_at(r, k):
            filter_step8(k, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf, k - 1 if keep else 0)
        else:
            _filter_epoch(k, x0, p0, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf, phit, kg, ph)


@njit(cache=True)
def _filter_loop14(x0, p0, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf):
    """n = 14: the vector step (:mod:`gravsurvey.inm.kalman14`) wherever R is diagonal, the
    generic loops elsewhere."""
    n = x0.shape[0]
    keep = phi_pf.shape[0] == phi.shape[0]
    phit = np.empty((n, n))
    kg = np.empty(n)
    ph = np.empty(n)
    wk = np.empty(32)
    for k in range(phi.shape[0]):
        if k > 0 and _diagonal_at(r, k):
            filter_step14(k, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf, k - 1 if keep else 0, phit, wk)
        else:
            _filter_epoch(k, x0, p0, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf, phit, kg, ph)


@njit(cache=True)
def _filter_epoch(k, x0, p0, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf, phit, kg, ph):
    """Epoch ``k`` of the filter by the generic loops (any n, any R); ``phit, kg, ph`` scratch."""
    n = x0.shape[0]
    m = z.shape[1]
    x = x_f[k]
    p = p_f[k]
    if k > 0:
        tmp = phi_pf[k - 1] if phi_pf.shape[0] == phi.shape[0] else phi_pf[0]
        _predict_into(phi[k], q[k], x_f[k - 1], p_f[k - 1], tmp, phit, x_p[k], p_p[k], x, p)
    else:
        for i in range(n):
            x_p[0, i] = x0[i]
            x[i] = x0[i]
            for j in range(n):
                v = 0.5 * (p0[i, j] + p0[j, i])
                p_p[0, i, j] = v
                p[i, j] = v
    if _diagonal_at(r, k):
        # sequential scalar updates: identical to the batch update for a diagonal R, and the
        # normalised innovations are the Cholesky-whitened ones
        for i in range(m):
            if math.isnan(z[k, i]):
                innov[k, i] = np.nan
            else:
                innov[k, i] = _scalar_update(x, p, z[k, i], h[k, i], r[k, i, i], kg, ph)
    else:
        _update(x, p, z[k], h[k], r[k], innov[k], kg, ph)


def rts_smoother(x_f, p_f, x_p, p_p, phi, unrolled=True):
    """Rauch-Tung-Striebel smoother over the filter output (numba kernel :func:`_rts_into`).

    ``G_k = P_f[k] phi[k+1]^T P_p[k+1]^-1``; the inverse is applied through a
    Cholesky solve on the diagonally scaled (correlation) matrix, because the state
    mixes metres with 1e-6 m/s^2.

    Returns
    -------
    x_s, p_s : ndarray (N, n), (N, n, n)
    """
    x_f, p_f, x_p, p_p, phi = (np.ascontiguousarray(a, dtype=float) for a in (x_f, p_f, x_p, p_p, phi))
    x_s = np.empty(x_f.shape)
    p_s = np.empty(p_f.shape)
    _rts_into(x_f, p_f, x_p, p_p, phi, phi, False, x_s, p_s, unrolled)
    return x_s, p_s


def _rts_into(x_f, p_f, x_p, p_p, phi, phi_pf, have_phi_pf, x_s, p_s, unrolled):
    """Kernel of :func:`rts_smoother`; writes into the preallocated ``x_s, p_s``.

    With ``have_phi_pf``, ``phi_pf[k]`` must hold ``phi[k + 1] @ p_f[k]`` exactly as the
    filter computed it (see :func:`_kalman_filter_into`) and is used instead of recomputing it.
    ``phi_pf`` may be ``p_s`` itself: row ``k`` is read before ``p_s[k]`` is written.
    ``unrolled``: the fixed-size vector steps (same numbers) when n = 8 or 14, each size in its
    own compiled loop (as the filter's).
    """
    if unrolled and x_f.shape[1] == 8:
        _rts_loop8(x_f, p_f, x_p, p_p, phi, phi_pf, have_phi_pf, x_s, p_s)
    elif unrolled and x_f.shape[1] == N14:
        _rts_loop14(x_f, p_f, x_p, p_p, phi, phi_pf, have_phi_pf, x_s, p_s)
    else:
        _rts_loop(x_f, p_f, x_p, p_p, phi, phi_pf, have_phi_pf, x_s, p_s)


# The recursion runs backwards in time, and backward streams through the (N, n, n) arrays are
# badly prefetched (measured: 8x8 products 2.4x slower than in a forward loop).  So the epochs
# are processed in blocks: each block's inputs are first read in a forward sweep (pulling them
# into cache, :func:`_prefetch_block`), then the block is smoothed backwards from cache.


@njit(cache=True)
def _copy_last(x_f, p_f, x_s, p_s):
    """``x_s[-1] = x_f[-1]``, ``p_s[-1] = p_f[-1]`` element by element: an array assignment
    compiles numba's broadcast-error formatting (string kernels, ~2 s on a cold start)."""
    nep, n = x_f.shape
    for i in range(n):
        x_s[nep - 1, i] = x_f[nep - 1, i]
        for j in range(n):
            p_s[nep - 1, i, j] = p_f[nep - 1, i, j]


@njit(cache=True)
def _rts_loop(x_f, p_f, x_p, p_p, phi, phi_pf, have_phi_pf, x_s, p_s):
    """Every epoch by the generic loops (:func:`_rts_step`)."""
    nep, n = x_f.shape
    if nep == 0:
        return 0.0
    _copy_last(x_f, p_f, x_s, p_s)
    d = np.empty(n)
    idg = np.empty(n)
    lch = np.empty((n, n))
    b = np.empty((n, n))
    bt = np.empty((n, n))
    dx = np.empty(n)
    dp = np.empty((n, n))
    tmp = np.empty((n, n))
    sink = 0.0
    for k1 in range(nep - 2, -1, -_BLOCK):
        k0 = max(k1 - _BLOCK + 1, 0)
        sink += _prefetch_block(p_p, p_f, p_s, phi, phi_pf, have_phi_pf, k0, k1)
        for kk in range(k1 - k0 + 1):
            _rts_step(k1 - kk, x_f, p_f, x_p, p_p, phi, phi_pf, have_phi_pf, x_s, p_s, d, idg, lch, b, bt, dx, dp, tmp)
    return sink


@njit(cache=True)
def _rts_loop8(x_f, p_f, x_p, p_p, phi, phi_pf, have_phi_pf, x_s, p_s):
    """n = 8: every epoch by the generated step."""
    nep, n = x_f.shape
    if nep == 0:
        return 0.0
    _copy_last(x_f, p_f, x_s, p_s)
    phi_pf1 = np.empty((1, n, n))
    sink = 0.0
    for k1 in range(nep - 2, -1, -_BLOCK):
        k0 = max(k1 - _BLOCK + 1, 0)
        sink += _prefetch_block(p_p, p_f, p_s, phi, phi_pf, have_phi_pf, k0, k1)
        for kk in range(k1 - k0 + 1):
            k = k1 - kk
            if have_phi_pf:
                rts_step8(k, x_f, p_f, x_p, p_p, phi_pf, k, x_s, p_s)
            else:
                _matmul(phi[k + 1], p_f[k], phi_pf1[0], False)
                rts_step8(k, x_f, p_f, x_p, p_p, phi_pf1, 0, x_s, p_s)
    return sink


@njit(cache=True)
def _rts_loop14(x_f, p_f, x_p, p_p, phi, phi_pf, have_phi_pf, x_s, p_s):
    """n = 14: the vector steps of :mod:`gravsurvey.inm.kalman14`, block by block: first the gains
    of the block's epochs in a forward sweep (they do not depend on the smoothed epochs, so their
    long latency chains overlap; the inputs are read forwards), then the backward recursion."""
    nep, n = x_f.shape
    if nep == 0:
        return 0.0
    _copy_last(x_f, p_f, x_s, p_s)
    phi_pf1 = np.empty((1, n, n))
    gain = np.empty((_BLOCK, n, n))
    lt = np.empty((n, n))
    b = np.empty((n, n))
    t = np.empty((n, n))
    wk = np.empty(32)
    sink = 0.0
    for k1 in range(nep - 2, -1, -_BLOCK):
        k0 = max(k1 - _BLOCK + 1, 0)
        sink += _touch(p_f, k0, k1 + 1)
        for k in range(k0, k1 + 1):
            if have_phi_pf:
                rts_gain14(k, p_p, phi_pf, k, gain, k - k0, lt, b, wk)
            else:
                _matmul(phi[k + 1], p_f[k], phi_pf1[0], False)
                rts_gain14(k, p_p, phi_pf1, 0, gain, k - k0, lt, b, wk)
        for kk in range(k1 - k0 + 1):
            k = k1 - kk
            rts_update14(k, x_f, p_f, x_p, p_p, gain, k - k0, x_s, p_s, b, t)
    return sink


@njit(cache=True)
def _prefetch_block(p_p, p_f, p_s, phi, phi_pf, have_phi_pf, k0, k1):
    """Read the smoother's inputs of epochs ``k0..k1`` forwards (see above)."""
    sink = _touch(p_p, k0 + 1, k1 + 2) + _touch(p_f, k0, k1 + 1) + _touch(p_s, k0, k1 + 1)
    if have_phi_pf:
        sink += _touch(phi_pf, k0, k1 + 1)
    else:
        sink += _touch(phi, k0 + 1, k1 + 2)
    return sink


#: Epochs per block of the smoother's cache-friendly sweep (4 (n, n) arrays x 64 epochs: 128 KB
#: for n = 8, 400 KB for n = 14 with its gain buffer, inside L2; 32 and 128 measured no faster).
_BLOCK = 64


@njit(cache=True)
def _touch(a, lo, hi):
    """Read one element per cache line of ``a[lo:hi]`` (n x n, C order) in ascending order."""
    n = a.shape[2]
    s = 0.0
    for k in range(lo, hi):
        for i in range(n):
            s += a[k, i, 0] + a[k, i, n - 1]
    return s


@njit(cache=True)
def _rts_step(k, x_f, p_f, x_p, p_p, phi, phi_pf, have_phi_pf, x_s, p_s, d, idg, lch, b, bt, dx, dp, tmp):
    """One backward RTS step: ``x_s[k], p_s[k]`` from epoch ``k + 1``."""
    n = x_f.shape[1]
    pp = p_p[k + 1]
    ph = phi[k + 1]
    pf = p_f[k]
    for i in range(n):
        d[i] = 1.0 / math.sqrt(pp[i, i]) if pp[i, i] > 0 else 1.0  # D^-1
    # Cholesky of the correlation matrix D^-1 P_p D^-1 (inverse diagonal kept in idg)
    for i in range(n):
        for j in range(i + 1):
            acc = pp[i, j] * d[i] * d[j]
            for l in range(j):
                acc -= lch[i, l] * lch[j, l]
            if i == j:
                lch[i, i] = math.sqrt(acc) if acc > 0 else 1e-300
                idg[i] = 1.0 / lch[i, i]
            else:
                lch[i, j] = acc * idg[j]
    # B = D^-1 phi P_f
    if have_phi_pf:
        for i in range(n):
            c = d[i]
            for j in range(n):
                b[i, j] = phi_pf[k, i, j] * c
    else:
        matmul_into(ph, pf, b)
        for i in range(n):
            c = d[i]
            for j in range(n):
                b[i, j] *= c
    # solve L L^T Y = B for all columns at once (row operations); G^T = D^-1 Y -> b
    _tri_solve(lch, idg, b, True)
    _tri_solve(lch, idg, b, False)
    for i in range(n):
        c = d[i]
        for j in range(n):
            b[i, j] *= c
    # now b = G^T.  x_s = x_f + G (x_s[k+1] - x_p[k+1])
    for i in range(n):
        dx[i] = x_s[k + 1, i] - x_p[k + 1, i]
    for i in range(n):
        acc = x_f[k, i]
        for l in range(n):
            acc += b[l, i] * dx[l]
        x_s[k, i] = acc
    # P_s = P_f + G (P_s[k+1] - P_p) G^T:  tmp = G dp = b^T dp, then tmp b
    for i in range(n):
        for j in range(n):
            dp[i, j] = p_s[k + 1, i, j] - pp[i, j]
    transpose_into(b, bt)
    matmul_into(bt, dp, tmp)
    matmul_into(tmp, b, dp)  # symmetric: the upper triangle is used
    for i in range(n):
        for j in range(i, n):
            v = pf[i, j] + dp[i, j]
            p_s[k, i, j] = v
            p_s[k, j, i] = v


# --------------------------------------------------------------------------
# Pure-numpy reference path (slow; for tests)
# --------------------------------------------------------------------------


def kalman_filter_ref(x0, p0, phi, q, z, h, r):
    """Pure-numpy reference of :func:`kalman_filter` (same arguments and returns)."""
    nep, n = phi.shape[0], x0.shape[0]
    m = z.shape[1]
    x_f = np.empty((nep, n))
    p_f = np.empty((nep, n, n))
    x_p = np.empty((nep, n))
    p_p = np.empty((nep, n, n))
    innov = np.full((nep, m), np.nan)
    x = np.array(x0, dtype=float)
    p = np.array(p0, dtype=float)
    for k in range(nep):
        if k > 0:
            x = phi[k] @ x
            p = phi[k] @ p @ phi[k].T + q[k]
            p = 0.5 * (p + p.T)
        x_p[k], p_p[k] = x, p
        ok = ~np.isnan(z[k])
        if ok.any():
            hk = h[k][ok]
            rk = r[k][np.ix_(ok, ok)]
            nu = z[k][ok] - hk @ x
            s = hk @ p @ hk.T + rk
            kg = p @ hk.T @ np.linalg.inv(s)
            x = x + kg @ nu
            ikh = np.eye(n) - kg @ hk
            p = ikh @ p @ ikh.T + kg @ rk @ kg.T
            p = 0.5 * (p + p.T)
            innov[k, ok] = np.linalg.solve(np.linalg.cholesky(s), nu)
        x_f[k], p_f[k] = x, p
    return x_f, p_f, x_p, p_p, innov


def rts_smoother_ref(x_f, p_f, x_p, p_p, phi):
    """Pure-numpy reference of :func:`rts_smoother`."""
    nep = x_f.shape[0]
    x_s = x_f.copy()
    p_s = p_f.copy()
    for k in range(nep - 2, -1, -1):
        g = p_f[k] @ phi[k + 1].T @ np.linalg.inv(p_p[k + 1])
        x_s[k] = x_f[k] + g @ (x_s[k + 1] - x_p[k + 1])
        p = p_f[k] + g @ (p_s[k + 1] - p_p[k + 1]) @ g.T
        p_s[k] = 0.5 * (p + p.T)
    return x_s, p_s


def filter_and_smooth(x0, p0, phi, q, z, h, r, reference: bool = False, unrolled: bool = True):
    """Run the filter then the smoother; returns a dict of arrays.

    Keys: ``x_f, p_f, x_p, p_p, innov, x_s, p_s`` (see :func:`kalman_filter`).
    ``reference=True`` uses the pure-numpy path; ``unrolled=False`` the compiled generic loops
    instead of the 8- and 14-state vector steps (for tests: the numbers are the same).
    """
    args = [np.ascontiguousarray(a, dtype=float) for a in (x0, p0, phi, q, z, h, r)]
    if reference:
        x_f, p_f, x_p, p_p, innov = kalman_filter_ref(*args)
        x_s, p_s = rts_smoother_ref(x_f, p_f, x_p, p_p, args[2])
    else:
        x0, p0, phi, q, z, h, r = args
        nep, n, m = phi.shape[0], x0.shape[0], z.shape[1]
        x_f, x_p, x_s, p_f, p_p, p_s, innov = _outputs(((nep, n),) * 3 + ((nep, n, n),) * 3 + ((nep, m),))
        # phi[k + 1] @ p_f[k] is computed by the prediction and reused by the smoother; it is
        # parked in p_s[k] (written by the smoother only after it has been read)
        _kalman_filter_into(x0, p0, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, p_s, unrolled)
        _rts_into(x_f, p_f, x_p, p_p, phi, p_s, True, x_s, p_s, unrolled)
    return dict(x_f=x_f, p_f=p_f, x_p=x_p, p_p=p_p, innov=innov, x_s=x_s, p_s=p_s)


def log_likelihood(p_p, innov, z, h, r) -> np.ndarray:
    """Log-likelihood of the measurements under the filter's model, epoch by epoch, from its
    own innovations (the prediction-error decomposition): ``-1/2 (log det S_k + |L_k^-1 nu_k|^2)``
    with ``S_k = H_k P_k^- H_k^T + R_k`` on the finite components of ``z_k``, the ``2 pi``
    terms left out.  Their sum is the log of the joint Gaussian density of all the
    measurements, so two models of the same measurements compare by it (maximum likelihood;
    :func:`likelihood_gain_z` for how clearly).

    Parameters
    ----------
    p_p : ndarray (N, n, n)
        Predicted covariances (:func:`kalman_filter`).
    innov : ndarray (N, m)
        Whitened innovations (NaN where ``z`` is missing).
    z, h, r : ndarray (N, m), (N, m, n), (N, m, m)
        The measurements the filter ran on.

    Returns
    -------
    ndarray (N,)
        Each epoch's term (0 at an epoch without a finite measurement).
    """
    ok = np.isfinite(np.asarray(z, float))
    pair = ok[:, :, None] & ok[:, None, :]
    hk = np.where(ok[:, :, None], h, 0.0)
    s = np.matmul(np.matmul(hk, p_p), hk.transpose(0, 2, 1))
    # missing components: a unit diagonal, nothing to the determinant
    s = np.where(pair, s + r, np.eye(ok.shape[1])[None])
    _, logdet = np.linalg.slogdet(s)
    v = np.where(ok, innov, 0.0)
    return -0.5 * (logdet + np.sum(v * v, axis=1))


def likelihood_gain_z(terms_a, terms_b) -> float:
    """How many standard errors model ``a`` is more likely than model ``b`` on the same
    measurements (Vuong's test for models that need not nest): the sum of the per-epoch
    log-likelihood differences over ``sqrt(n)`` times their standard deviation, over the ``n``
    epochs with measurements.  Under misspecified models a difference of tens in the total can
    be chance; this says when it is not.

    Parameters
    ----------
    terms_a, terms_b : ndarray (N,)
        :func:`log_likelihood` of the two models.

    Returns
    -------
    float
        NaN when the two do not cover the same epochs or fewer than two epochs differ.
    """
    a, b = np.asarray(terms_a, float), np.asarray(terms_b, float)
    if a.shape != b.shape:
        return float("nan")
    d = (a - b)[(a != 0.0) | (b != 0.0)]
    if d.size < 2 or not np.all(np.isfinite(d)):
        return float("nan")
    sd = float(np.std(d))
    if sd == 0.0:
        return float("nan")
    return float(np.sum(d) / (math.sqrt(d.size) * sd))


#: Huge-page size of x86-64 and arm64 Linux (transparent huge pages), bytes.
_HUGE_PAGE = 2 << 20


def _outputs(shapes):
    """Uninitialised float64 arrays of the given shapes, carved from one allocation that starts
    on a 2-MiB boundary.

    Fresh memory is paid for on first touch, one page fault per page the kernel zeroes.  numpy
    asks for transparent huge pages on large allocations (``madvise``), but an array gets them
    only for the 2-MiB-aligned stretches inside it: separate (N, 14, 14) arrays for a 1-hour
    flight (5.6 MB each) were mostly 4-KiB pages, ~1 us of page fault each on this VM, 0.6-1.2 us
    per epoch in all (docs/benchmarks.md, "Kalman filter").  One aligned block is all huge pages.
    The arrays are views of it (they keep it alive together).
    """
    sizes = [int(np.prod(s)) * 8 for s in shapes]
    offsets = np.cumsum([0] + [(b + 63) // 64 * 64 for b in sizes])  # cache-line aligned
    raw = np.empty(int(offsets[-1]) + _HUGE_PAGE, dtype=np.uint8)
    base = (-raw.ctypes.data) % _HUGE_PAGE
    return [raw[base + o : base + o + b].view(np.float64).reshape(s) for s, o, b in zip(shapes, offsets[:-1], sizes)]


def change_basis(t, t_inv, x0, p0, phi, q, h):
    """The same linear-Gaussian model in the state ``x'_k = T_k x_k`` (an exact similarity).

    ``phi'[k] = T_k phi[k] T_(k-1)^-1``, ``q'[k] = T_k q[k] T_k^T``, ``h'[k] = h[k] T_k^-1``,
    ``x0' = T_0 x0``, ``P0' = T_0 P0 T_0^T``; ``z`` and ``r`` are unchanged.  Filtering either
    model gives the same estimate (``x = T^-1 x'``, ``P = T^-1 P' T^-T``) up to rounding;
    the rounding is what differs: a basis in which the covariance is well conditioned lets
    any two correct implementations agree to ~1e-12 (docs/benchmarks.md, "Kalman filter").

    Parameters
    ----------
    t, t_inv : ndarray (N, n, n)
        ``T_k`` and its inverse per epoch.
    x0 : ndarray (n,)
    p0 : ndarray (n, n)
    phi, q : ndarray (N, n, n)
    h : ndarray (N, m, n)

    Returns
    -------
    tuple
        ``(x0', P0', phi', q', h')`` (covariances symmetrised).
    """
    phi2 = np.array(phi, dtype=float)
    phi2[1:] = np.einsum("kij,kjl,klm->kim", t[1:], phi[1:], t_inv[:-1])
    q2 = np.einsum("kij,kjl,kml->kim", t, q, t)
    q2 = 0.5 * (q2 + q2.transpose(0, 2, 1))
    h2 = np.einsum("kij,kjl->kil", h, t_inv)
    p02 = t[0] @ p0 @ t[0].T
    return t[0] @ x0, 0.5 * (p02 + p02.T), phi2, q2, h2


def restore_basis(t_inv, x, p):
    """States ``(N, n)`` and covariances ``(N, n, n)`` of a :func:`change_basis` model, back in
    the original basis: ``x = T^-1 x'``, ``P = T^-1 P' T^-T``."""
    p2 = np.einsum("kij,kjl,kml->kim", t_inv, p, t_inv)
    return np.einsum("kij,kj->ki", t_inv, x), 0.5 * (p2 + p2.transpose(0, 2, 1))


def filter_and_smooth_exact(x0, p0, phi, q, z, h, r):
    """Textbook filter (Joseph form) + RTS smoother in ``np.longdouble`` with a pivoted
    Gauss-Jordan inverse: the accuracy yardstick for the double-precision paths on badly
    conditioned models (slow: pure Python loops; keep ``N`` to a few hundred epochs).

    Same arguments as :func:`filter_and_smooth`; returns ``x_f, p_f, x_s, p_s`` as float64
    ``(N, n)``, ``(N, n, n)`` arrays.  Where ``np.longdouble`` is plain double (some
    platforms), this is only another double-precision implementation.
    """
    ld = np.longdouble
    x0, p0, phi, q, z, h, r = (np.asarray(a, dtype=ld) for a in (x0, p0, phi, q, z, h, r))

    def inv(a):
        m = a.shape[0]
        g = np.concatenate([a.copy(), np.eye(m, dtype=ld)], axis=1)
        for c in range(m):
            piv = c + int(np.argmax(np.abs(g[c:, c])))
            g[[c, piv]] = g[[piv, c]]
            g[c] /= g[c, c]
            for i in range(m):
                if i != c:
                    g[i] -= g[i, c] * g[c]
        return g[:, m:]

    nep, n = phi.shape[0], x0.size
    xf, pf = np.empty((nep, n), ld), np.empty((nep, n, n), ld)
    xp, pp = np.empty_like(xf), np.empty_like(pf)
    x, p = x0.copy(), p0.copy()
    for k in range(nep):
        if k:
            x = phi[k] @ x
            p = phi[k] @ p @ phi[k].T + q[k]
            p = (p + p.T) / 2
        xp[k], pp[k] = x, p
        ok = ~np.isnan(z[k].astype(float))
        if ok.any():
            hk, rk = h[k][ok], r[k][np.ix_(ok, ok)]
            kg = p @ hk.T @ inv(hk @ p @ hk.T + rk)
            x = x + kg @ (z[k][ok] - hk @ x)
            ikh = np.eye(n, dtype=ld) - kg @ hk
            p = ikh @ p @ ikh.T + kg @ rk @ kg.T
            p = (p + p.T) / 2
        xf[k], pf[k] = x, p
    xs, ps = xf.copy(), pf.copy()
    for k in range(nep - 2, -1, -1):
        g = pf[k] @ phi[k + 1].T @ inv(pp[k + 1])
        xs[k] = xf[k] + g @ (xs[k + 1] - xp[k + 1])
        pn = pf[k] + g @ (ps[k + 1] - pp[k + 1]) @ g.T
        ps[k] = (pn + pn.T) / 2
    return xf.astype(float), pf.astype(float), xs.astype(float), ps.astype(float)
