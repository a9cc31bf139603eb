"""Vector Kalman filter and RTS smoother steps for the 14-state GNSS-aided model.

Each step does, operation for operation, what the generic loops of :mod:`gravsurvey.inm.kalman`
do for one epoch (``_predict_into`` + ``_scalar_update``, ``_rts_step``), so the numbers are the
same to the last bit (tested), but with every 14-element row of a covariance held in two
:mod:`gravsurvey.inm.simd` vectors (8 and 6 lanes) and written as loops, not unrolled text: the
generated 14-state steps this replaces (:mod:`gravsurvey.inm.codegen`) took ~27 s to compile;
these take ~5-6 s of CPU (measured on a loaded machine; most of it numba's typing and lowering
of the intrinsic calls: a variant still took 3.4 s with ``NUMBA_OPT=0``), in place of the generic 14-state loops a
default run then no longer compiles, so its cold first call is unchanged (docs/benchmarks.md,
"Kalman filter").

Structure used, without changing a single rounding:

- zero coefficients of ``phi`` and ``h`` are skipped.  Every sum here starts from +0.0 and a
  sum that starts from +0.0 is never -0.0 in round-to-nearest, so adding a product ``0 * x``
  (+-0 for finite ``x``) never changes it: skipping is exact.  The INS error model's ``phi``
  has 107 of 196 entries nonzero (rows of gravity, ``f3`` and gyro bias are diagonal, the
  attitude rows see only attitude and gyro bias), ``h`` 6 of 14 per row;
- in ``phi P phi^T`` the 6-lane half of a column of ``phi`` is skipped where it is all zero (the
  columns of the position, velocity, gravity and ``f3`` states);
- only the upper triangle of each symmetric product is computed; the lower lanes of a row are
  gathered from the rows above it (the generic loops mirror the upper triangle too);
- the Joseph update ``P - k (P h)^T - (P h) k^T + s k k^T`` computes, in one pass over each
  row, the lanes above the diagonal with the generic loops' formula for ``(i, j)`` and the lanes
  below with its formula for ``(j, i)``, and joins them (:func:`gravsurvey.inm.simd.vjoin`),
  instead of mirroring element by element after each scalar measurement.

All arrays are C-contiguous float64 with 14 states (the callers check); epochs are addressed by
index into whole arrays (row views cost atomic reference counting, comparable to the arithmetic).
"""

from __future__ import annotations

import math

from numba import njit

from .simd import vadd, vcol, vdiv, vget, vjoin, vload, vmul, vset, vsplat, vstore, vsub

#: The state size these steps are written for.
N14 = 14
_NN = N14 * N14


@njit(cache=True, inline="always")
def filter_step14(k, phi, q, z, h, r, x_f, p_f, x_p, p_p, innov, phi_pf, kpf, phit, wk):
    """Epoch ``k >= 1``: predict from ``x_f[k - 1], p_f[k - 1]`` with ``phi[k], q[k]``, then
    update with every finite ``z[k, i]`` (``r[k]`` diagonal: the caller checks).

    Writes ``phi_pf[kpf] = phi[k] @ p_f[k - 1]`` (kept for the smoother), the prediction into
    ``x_p[k], p_p[k]``, the update into ``x_f[k], p_f[k]`` and the whitened innovations into
    ``innov[k]`` (NaN where ``z`` is NaN).  ``phit`` (14, 14) and ``wk`` (>= 32,) are scratch.
    """
    kb = k * _NN
    kb1 = kb - _NN
    tb = kpf * _NN
    zero8 = vsplat(0.0, 8)
    zero6 = vsplat(0.0, 6)
    half8 = vsplat(0.5, 8)
    half6 = vsplat(0.5, 6)
    # phi^T, and which of its rows have a nonzero 6-lane half (bit l of hi)
    hi = 0
    for l in range(N14):
        for i in range(N14):
            c = phi[k, i, l]
            phit[l, i] = c
            if i >= 8 and c != 0.0:
                hi |= 1 << l
    # x = phi x_f[k - 1]: lane i sums phi[i, j] x[j] over j ascending, as the generic loop
    x0 = zero8
    x1 = zero6
    for j in range(N14):
        c = x_f[k - 1, j]
        x0 = vadd(x0, vmul(vload(phit, N14 * j, 8), vsplat(c, 8)))
        x1 = vadd(x1, vmul(vload(phit, N14 * j + 8, 6), vsplat(c, 6)))
    vstore(x_p, k * N14, x0)
    vstore(x_p, k * N14 + 8, x1)
    vstore(x_f, k * N14, x0)
    vstore(x_f, k * N14 + 8, x1)
    # T = phi P: row i = sum over the nonzero phi[i, l] of phi[i, l] P[l, :]
    for i in range(N14):
        o0 = zero8
        o1 = zero6
        for l in range(N14):
            c = phi[k, i, l]
            if c != 0.0:
                o0 = vadd(o0, vmul(vsplat(c, 8), vload(p_f, kb1 + N14 * l, 8)))
                o1 = vadd(o1, vmul(vsplat(c, 6), vload(p_f, kb1 + N14 * l + 8, 6)))
        vstore(phi_pf, tb + N14 * i, o0)
        vstore(phi_pf, tb + N14 * i + 8, o1)
    # P_p = T phi^T + sym(Q), upper triangle by rows; the lower lanes from the rows above
    for i in range(N14):
        qo = kb + N14 * i
        o1 = zero6
        if i < 8:
            o0 = zero8
            for l in range(N14):
                c = phi_pf[kpf, i, l]
                o0 = vadd(o0, vmul(vsplat(c, 8), vload(phit, N14 * l, 8)))
                if (hi >> l) & 1:
                    o1 = vadd(o1, vmul(vsplat(c, 6), vload(phit, N14 * l + 8, 6)))
            o0 = vadd(o0, vmul(half8, vadd(vload(q, qo, 8), vcol(q, kb + i, N14, 8))))
            o0 = vjoin(vcol(p_p, kb + i, N14, 8), o0, i)
        else:
            for l in range(N14):
                if (hi >> l) & 1:
                    o1 = vadd(o1, vmul(vsplat(phi_pf[kpf, i, l], 6), vload(phit, N14 * l + 8, 6)))
            o0 = vcol(p_p, kb + i, N14, 8)
        o1 = vadd(o1, vmul(half6, vadd(vload(q, qo + 8, 6), vcol(q, kb + 8 * N14 + i, N14, 6))))
        o1 = vjoin(vcol(p_p, kb + 8 * N14 + i, N14, 6), o1, i - 8)
        vstore(p_p, qo, o0)
        vstore(p_p, qo + 8, o1)
        vstore(p_f, qo, o0)
        vstore(p_f, qo + 8, o1)
    # sequential scalar updates (Joseph form in O(n^2), as kalman._scalar_update)
    for a in range(z.shape[1]):
        za = z[k, a]
        if math.isnan(za):
            innov[k, a] = math.nan
            continue
        g0 = zero8
        g1 = zero6
        for i in range(N14):
            c = h[k, a, i]
            if c != 0.0:
                g0 = vadd(g0, vmul(vsplat(c, 8), vload(p_f, kb + N14 * i, 8)))
                g1 = vadd(g1, vmul(vsplat(c, 6), vload(p_f, kb + N14 * i + 8, 6)))
        vstore(wk, 0, g0)
        vstore(wk, 8, g1)
        s = r[k, a, a]
        nu = za
        for i in range(N14):
            s += h[k, a, i] * wk[i]
            nu -= h[k, a, i] * x_f[k, i]
        k0 = vdiv(g0, vsplat(s, 8))
        k1 = vdiv(g1, vsplat(s, 6))
        vstore(wk, 16, k0)
        vstore(wk, 24, k1)
        vstore(x_f, k * N14, vadd(vload(x_f, k * N14, 8), vmul(k0, vsplat(nu, 8))))
        vstore(x_f, k * N14 + 8, vadd(vload(x_f, k * N14 + 8, 6), vmul(k1, vsplat(nu, 6))))
        sk0 = vmul(vsplat(s, 8), k0)
        sk1 = vmul(vsplat(s, 6), k1)
        for i in range(N14):
            kr = wk[16 + i]
            phr = wk[i]
            skr = s * kr
            po = kb + N14 * i
            # lane j >= i: p - k_i ph_j - ph_i k_j + (s k_i) k_j (element (i, j));
            # lane j < i: p - k_j ph_i - ph_j k_i + (s k_j) k_i (element (j, i), mirrored)
            p0 = vload(p_f, po, 8)
            a0 = vmul(vsplat(kr, 8), g0)
            b0 = vmul(vsplat(phr, 8), k0)
            up0 = vadd(vsub(vsub(p0, a0), b0), vmul(vsplat(skr, 8), k0))
            if i < 8:
                lo0 = vadd(vsub(vsub(p0, b0), a0), vmul(sk0, vsplat(kr, 8)))
                up0 = vjoin(lo0, up0, i)
            else:
                up0 = vadd(vsub(vsub(p0, b0), a0), vmul(sk0, vsplat(kr, 8)))
            p1 = vload(p_f, po + 8, 6)
            a1 = vmul(vsplat(kr, 6), g1)
            b1 = vmul(vsplat(phr, 6), k1)
            up1 = vadd(vsub(vsub(p1, a1), b1), vmul(vsplat(skr, 6), k1))
            if i >= 8:
                lo1 = vadd(vsub(vsub(p1, b1), a1), vmul(sk1, vsplat(kr, 6)))
                up1 = vjoin(lo1, up1, i - 8)
            vstore(p_f, po, up0)
            vstore(p_f, po + 8, up1)
        innov[k, a] = nu / math.sqrt(s)


@njit(cache=True, inline="always")
def rts_gain14(k, p_p, phi_pf, kpf, gain, kg, lt, b, wk):
    """The smoother gain of epoch ``k``: ``gain[kg] = G_k^T = P_p[k+1]^-1 phi[k+1] P_f[k]``.

    ``phi_pf[kpf]`` holds ``phi[k + 1] @ p_f[k]``; ``gain`` may be ``phi_pf`` with ``kg = kpf``
    (each row is read before it is written).  ``lt, b`` (14, 14) and ``wk`` (>= 32,) are scratch.
    The gain does not depend on the smoothed epochs, so the caller computes the gains of a block
    of epochs in a forward sweep: its latency chains (square roots and divisions of the Cholesky
    factorisation, the triangular solves) then overlap between epochs.
    """
    pb = (k + 1) * _NN
    tb = kpf * _NN
    gb = kg * _NN
    # D^-1 in wk[0:14]
    for i in range(N14):
        v = p_p[k + 1, i, i]
        wk[i] = 1.0 / math.sqrt(v) if v > 0 else 1.0
    d0 = vload(wk, 0, 8)
    d1 = vload(wk, 8, 6)
    # Cholesky of D^-1 P_p D^-1 by columns: row j of lt is column j of L (lanes > j), 1 / L_jj in
    # wk[16 + j]; element (i, j) is (P_ij d_i d_j - sum_l L_il L_jl) / L_jj with l ascending
    for j in range(N14):
        dj = wk[j]
        a1 = vmul(vmul(vload(p_p, pb + N14 * j + 8, 6), d1), vsplat(dj, 6))
        if j < 8:
            a0 = vmul(vmul(vload(p_p, pb + N14 * j, 8), d0), vsplat(dj, 8))
            for l in range(j):
                c = lt[l, j]
                a0 = vsub(a0, vmul(vload(lt, N14 * l, 8), vsplat(c, 8)))
                a1 = vsub(a1, vmul(vload(lt, N14 * l + 8, 6), vsplat(c, 6)))
            ajj = vget(a0, j)
        else:
            for l in range(j):
                a1 = vsub(a1, vmul(vload(lt, N14 * l + 8, 6), vsplat(lt[l, j], 6)))
            ajj = vget(a1, j - 8)
        ljj = math.sqrt(ajj) if ajj > 0 else 1e-300
        g = 1.0 / ljj
        wk[16 + j] = g
        a1 = vmul(a1, vsplat(g, 6))
        if j < 8:
            a0 = vset(vmul(a0, vsplat(g, 8)), j, ljj)
            vstore(lt, N14 * j, a0)
        else:
            a1 = vset(a1, j - 8, ljj)
        vstore(lt, N14 * j + 8, a1)
    # B = D^-1 phi P_f; forward solve L Y = B row by row (row i of L is column i of lt)
    for i in range(N14):
        di = wk[i]
        s0 = vmul(vload(phi_pf, tb + N14 * i, 8), vsplat(di, 8))
        s1 = vmul(vload(phi_pf, tb + N14 * i + 8, 6), vsplat(di, 6))
        for l in range(i):
            c = lt[l, i]
            s0 = vsub(s0, vmul(vsplat(c, 8), vload(b, N14 * l, 8)))
            s1 = vsub(s1, vmul(vsplat(c, 6), vload(b, N14 * l + 8, 6)))
        gi = wk[16 + i]
        vstore(b, N14 * i, vmul(s0, vsplat(gi, 8)))
        vstore(b, N14 * i + 8, vmul(s1, vsplat(gi, 6)))
    # backward solve L^T Z = Y; G^T = D^-1 Z
    for ii in range(N14):
        i = N14 - 1 - ii
        s0 = vload(b, N14 * i, 8)
        s1 = vload(b, N14 * i + 8, 6)
        for l in range(i + 1, N14):
            c = lt[i, l]
            s0 = vsub(s0, vmul(vsplat(c, 8), vload(b, N14 * l, 8)))
            s1 = vsub(s1, vmul(vsplat(c, 6), vload(b, N14 * l + 8, 6)))
        gi = wk[16 + i]
        s0 = vmul(s0, vsplat(gi, 8))
        s1 = vmul(s1, vsplat(gi, 6))
        vstore(b, N14 * i, s0)
        vstore(b, N14 * i + 8, s1)
        di = wk[i]
        vstore(gain, gb + N14 * i, vmul(s0, vsplat(di, 8)))
        vstore(gain, gb + N14 * i + 8, vmul(s1, vsplat(di, 6)))


@njit(cache=True, inline="always")
def rts_update14(k, x_f, p_f, x_p, p_p, gain, kg, x_s, p_s, b, t):
    """One backward RTS step from epoch ``k + 1`` with the gain ``gain[kg] = G_k^T``
    (:func:`rts_gain14`): ``x_s[k] = x_f[k] + G dx``, ``P_s[k] = P_f[k] + G dP G^T``.

    ``b, t`` (14, 14) are scratch.
    """
    pb = (k + 1) * _NN
    fb = k * _NN
    gb = kg * _NN
    zero8 = vsplat(0.0, 8)
    zero6 = vsplat(0.0, 6)
    # x_s = x_f + G (x_s[k+1] - x_p[k+1]); dP = P_s[k+1] - P_p[k+1] into b
    x0 = vload(x_f, k * N14, 8)
    x1 = vload(x_f, k * N14 + 8, 6)
    for l in range(N14):
        dx = x_s[k + 1, l] - x_p[k + 1, l]
        x0 = vadd(x0, vmul(vload(gain, gb + N14 * l, 8), vsplat(dx, 8)))
        x1 = vadd(x1, vmul(vload(gain, gb + N14 * l + 8, 6), vsplat(dx, 6)))
    vstore(x_s, k * N14, x0)
    vstore(x_s, k * N14 + 8, x1)
    for i in range(N14):
        o = pb + N14 * i
        vstore(b, N14 * i, vsub(vload(p_s, o, 8), vload(p_p, o, 8)))
        vstore(b, N14 * i + 8, vsub(vload(p_s, o + 8, 6), vload(p_p, o + 8, 6)))
    # t = G dP: row i = sum_l G^T[l, i] dP[l, :]
    for i in range(N14):
        o0 = zero8
        o1 = zero6
        for l in range(N14):
            c = gain[kg, l, i]
            o0 = vadd(o0, vmul(vsplat(c, 8), vload(b, N14 * l, 8)))
            o1 = vadd(o1, vmul(vsplat(c, 6), vload(b, N14 * l + 8, 6)))
        vstore(t, N14 * i, o0)
        vstore(t, N14 * i + 8, o1)
    # P_s = P_f + t G^T, upper triangle by rows, the lower lanes from the rows above
    for i in range(N14):
        o = fb + N14 * i
        o1 = zero6
        if i < 8:
            o0 = zero8
            for l in range(N14):
                c = t[i, l]
                o0 = vadd(o0, vmul(vsplat(c, 8), vload(gain, gb + N14 * l, 8)))
                o1 = vadd(o1, vmul(vsplat(c, 6), vload(gain, gb + N14 * l + 8, 6)))
            o0 = vjoin(vcol(p_s, fb + i, N14, 8), vadd(vload(p_f, o, 8), o0), i)
        else:
            for l in range(N14):
                o1 = vadd(o1, vmul(vsplat(t[i, l], 6), vload(gain, gb + N14 * l + 8, 6)))
            o0 = vcol(p_s, fb + i, N14, 8)
        o1 = vjoin(vcol(p_s, fb + 8 * N14 + i, N14, 6), vadd(vload(p_f, o + 8, 6), o1), i - 8)
        vstore(p_s, o, o0)
        vstore(p_s, o + 8, o1)
