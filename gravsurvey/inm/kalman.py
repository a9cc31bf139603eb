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
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


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
def van_loan(a, qc, dt):
    """Exact discretisation of ``dx/dt = A x + w``, ``E[w w^T] = Qc delta``, over ``dt``.

    Returns
    -------
    phi : ndarray (n, n)
        ``expm(A dt)``.
    qd : ndarray (n, n)
        ``int_0^dt expm(A s) Qc expm(A s)^T ds`` (symmetrised).
    """
    n = a.shape[0]
    m = np.zeros((2 * n, 2 * n))
    m[:n, :n] = -a * dt
    m[:n, n:] = qc * dt
    m[n:, n:] = a.T * dt
    e = expm(m)
    phi = e[n:, n:].T.copy()
    qd = phi @ np.ascontiguousarray(e[:n, n:])
    qd = 0.5 * (qd + qd.T)
    return phi, qd


# --------------------------------------------------------------------------
# Compiled filter and smoother
# --------------------------------------------------------------------------


@njit(cache=True)
def _update(x, p, z, h, r, nis_out):
    """Joseph-form update in place; writes whitened innovations into ``nis_out``."""
    m = z.shape[0]
    n = x.shape[0]
    cnt = 0
    for i in range(m):
        if not math.isnan(z[i]):
            cnt += 1
    for i in range(m):
        nis_out[i] = np.nan
    if cnt == 0:
        return
    idx = np.empty(cnt, dtype=np.int64)
    c = 0
    for i in range(m):
        if not math.isnan(z[i]):
            idx[c] = i
            c += 1
    hs = np.empty((cnt, n))
    zs = np.empty(cnt)
    rs = np.empty((cnt, cnt))
    for a in range(cnt):
        hs[a] = h[idx[a]]
        zs[a] = z[idx[a]]
        for b in range(cnt):
            rs[a, b] = r[idx[a], idx[b]]
    nu = zs - hs @ x
    pht = p @ hs.T
    s = hs @ pht + rs
    s = 0.5 * (s + s.T)
    # K = P H^T S^-1  -> solve S K^T = H P
    kt = np.linalg.solve(s, pht.T)
    k = kt.T
    x += k @ nu
    ikh = np.eye(n) - k @ hs
    pn = ikh @ p @ ikh.T + k @ rs @ k.T
    p[:, :] = 0.5 * (pn + pn.T)
    lch = np.linalg.cholesky(s)
    # forward substitution: whitened innovation L^-1 nu
    w = np.empty(cnt)
    for a in range(cnt):
        acc = nu[a]
        for b in range(a):
            acc -= lch[a, b] * w[b]
        w[a] = acc / lch[a, a]
    for a in range(cnt):
        nis_out[idx[a]] = w[a]


#: Floating-point flags for the small dense loops: let LLVM reassociate and fuse (SIMD sums);
#: NaN/Inf semantics are kept (missing measurements are NaN).
_FAST = {"reassoc", "contract", "arcp"}


@njit(cache=True, fastmath=_FAST)
def _predict_into(phi, q, x, p, tmp, xout, pout):
    """x <- phi x, p <- sym(phi p phi^T + q) with explicit loops (no allocation)."""
    n = x.shape[0]
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += phi[i, j] * x[j]
        xout[i] = acc
    for i in range(n):
        for j in range(n):
            tmp[i, j] = 0.0
        for l in range(n):
            c = phi[i, l]
            for j in range(n):
                tmp[i, j] += c * p[l, j]
    for i in range(n):
        for j in range(i, n):
            acc = 0.0
            for l in range(n):
                acc += tmp[i, l] * phi[j, l]
            v = acc + 0.5 * (q[i, j] + q[j, i])
            pout[i, j] = v
            pout[j, i] = v


@njit(cache=True, fastmath=_FAST)
def _scalar_update(x, p, z, h, r, a, tmp, ph):
    """Joseph-form update with one scalar measurement; returns the whitened innovation."""
    n = x.shape[0]
    s = r
    nu = z
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += p[i, j] * h[j]
        ph[i] = acc
        s += h[i] * acc
        nu -= h[i] * x[i]
    # Joseph form P <- A P A^T + r k k^T with A = I - k h^T, evaluated as two rank-one
    # products: M = A P = P - k (P h)^T, then M A^T = M - (M h) k^T
    for i in range(n):
        a[0, i] = ph[i] / s  # k
    for i in range(n):
        x[i] += a[0, i] * nu
    for i in range(n):
        ki = a[0, i]
        for j in range(n):
            tmp[i, j] = p[i, j] - ki * ph[j]
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += tmp[i, j] * h[j]
        a[1, i] = acc  # M h
    for i in range(n):
        for j in range(i, n):
            v = tmp[i, j] - a[1, i] * a[0, j] + r * a[0, i] * a[0, j]
            w = tmp[j, i] - a[1, j] * a[0, i] + r * a[0, j] * a[0, i]
            v = 0.5 * (v + w)
            p[i, j] = v
            p[j, i] = v
    return nu / math.sqrt(s)


@njit(cache=True)
def _diagonal(r):
    m = r.shape[0]
    for i in range(m):
        for j in range(m):
            if i != j and r[i, j] != 0.0:
                return False
    return True



@njit(cache=True)
def kalman_filter(x0, p0, phi, q, z, h, r):
    """Forward Kalman filter over ``N`` epochs (numba kernel).

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

    Returns
    -------
    x_f, p_f : ndarray (N, n), (N, n, n)
        Filtered (a posteriori) state and covariance.
    x_p, p_p : ndarray (N, n), (N, n, n)
        Predicted (a priori) state and covariance (epoch 0: the prior).
    innov : ndarray (N, m)
        Innovations whitened by the Cholesky factor of their covariance (NaN if missing).
    """
    nep = phi.shape[0]
    n = x0.shape[0]
    m = z.shape[1]
    x_f = np.empty((nep, n))
    p_f = np.empty((nep, n, n))
    x_p = np.empty((nep, n))
    p_p = np.empty((nep, n, n))
    innov = np.empty((nep, m))
    x = x0.copy()
    p = 0.5 * (p0 + p0.T)
    tmp = np.empty((n, n))
    a = np.empty((n, n))
    ph = np.empty(n)
    for k in range(nep):
        if k > 0:
            _predict_into(phi[k], q[k], x_f[k - 1], p_f[k - 1], tmp, x, p)
        x_p[k] = x
        p_p[k] = p
        if _diagonal(r[k]):
            # sequential scalar updates: identical to the batch update for a diagonal R, and the
            # normalised innovations are the Cholesky-whitened ones
            for i in range(m):
                if math.isnan(z[k, i]):
                    innov[k, i] = np.nan
                else:
                    innov[k, i] = _scalar_update(x, p, z[k, i], h[k, i], r[k, i, i], a, tmp, ph)
        else:
            _update(x, p, z[k], h[k], r[k], innov[k])
        x_f[k] = x
        p_f[k] = p
    return x_f, p_f, x_p, p_p, innov


@njit(cache=True, fastmath=_FAST)
def rts_smoother(x_f, p_f, x_p, p_p, phi):
    """Rauch-Tung-Striebel smoother over the filter output (numba kernel).

    ``G_k = P_f[k] phi[k+1]^T P_p[k+1]^-1``; the inverse is applied through a
    solve on the diagonally scaled (correlation) matrix, because the state
    mixes metres with 1e-6 m/s^2.

    Returns
    -------
    x_s, p_s : ndarray (N, n), (N, n, n)
    """
    nep, n = x_f.shape
    x_s = x_f.copy()
    p_s = p_f.copy()
    d = np.empty(n)
    idg = np.empty(n)
    lch = np.empty((n, n))
    b = np.empty((n, n))
    dx = np.empty(n)
    dp = np.empty((n, n))
    tmp = np.empty((n, n))
    # loops are ordered i-l-j (row axpy on contiguous rows) so that LLVM vectorises them
    for k in range(nep - 2, -1, -1):
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
        for i in range(n):
            for j in range(n):
                b[i, j] = 0.0
            for l in range(n):
                c = ph[i, l]
                for j in range(n):
                    b[i, j] += c * pf[l, j]
            c = d[i]
            for j in range(n):
                b[i, j] *= c
        # solve L L^T Y = B for all columns at once (row operations); G^T = D^-1 Y -> b
        for i in range(n):
            for l in range(i):
                c = lch[i, l]
                for j in range(n):
                    b[i, j] -= c * b[l, j]
            c = idg[i]
            for j in range(n):
                b[i, j] *= c
        for i in range(n - 1, -1, -1):
            for l in range(i + 1, n):
                c = lch[l, i]
                for j in range(n):
                    b[i, j] -= c * b[l, j]
            c = idg[i]
            for j in range(n):
                b[i, j] *= c
        for i in range(n):
            c = d[i]
            for j in range(n):
                b[i, j] *= c
        # now b = G^T.  x_s = x_f + G (x_s[k+1] - x_p[k+1])
        for i in range(n):
            dx[i] = x_s[k + 1, i] - x_p[k + 1, i]
        for i in range(n):
            x_s[k, i] = x_f[k, i]
        for l in range(n):
            c = dx[l]
            for i in range(n):
                x_s[k, i] += b[l, i] * c
        # P_s = P_f + G (P_s[k+1] - P_p) G^T:  tmp = G dp = b^T dp, then tmp b
        for i in range(n):
            for j in range(n):
                dp[i, j] = p_s[k + 1, i, j] - pp[i, j]
                tmp[i, j] = 0.0
        for l in range(n):
            for i in range(n):
                c = b[l, i]
                for j in range(n):
                    tmp[i, j] += c * dp[l, j]
        for i in range(n):
            for j in range(n):
                dp[i, j] = 0.0
            for l in range(n):
                c = tmp[i, l]
                for j in range(n):
                    dp[i, j] += c * b[l, j]
        for i in range(n):
            for j in range(i, n):
                v = pf[i, j] + 0.5 * (dp[i, j] + dp[j, i])
                p_s[k, i, j] = v
                p_s[k, j, i] = v
    return x_s, p_s


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


def filter_and_smooth(x0, p0, phi, q, z, h, r, reference: bool = False):
    """Run the filter then the smoother; returns a dict of arrays.

    Keys: ``x_f, p_f, x_p, p_p, innov, x_s, p_s`` (see :func:`kalman_filter`).
    ``reference=True`` uses the pure-numpy path.
    """
    args = [np.ascontiguousarray(a, dtype=float) for a in (x0, p0, phi, q, z, h, r)]
    if reference:
        x_f, p_f, x_p, p_p, innov = kalman_filter_ref(*args)
        x_s, p_s = rts_smoother_ref(x_f, p_f, x_p, p_p, args[2])
    else:
        x_f, p_f, x_p, p_p, innov = kalman_filter(*args)
        x_s, p_s = rts_smoother(x_f, p_f, x_p, p_p, args[2])
    return dict(x_f=x_f, p_f=p_f, x_p=x_p, p_p=p_p, innov=innov, x_s=x_s, p_s=p_s)
