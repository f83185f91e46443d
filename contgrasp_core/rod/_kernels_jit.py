"""The numba-compiled kernels behind :mod:`contgrasp_core.rod._kernels` (imported on first use,
so a process that never steps a rod does not import numba). Documentation: that module."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["frames_nodes", "kinetic_energy", "newton_system", "chain_solve", "circle_projection",
           "circle_shadow_geometry", "circle_sense", "joint_couple_jacobian", "self_contact_pairs"]


@njit(cache=True)
def frames_nodes(theta: np.ndarray, h: float, base: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tangents ``a`` (N, 2), normals ``b`` (N, 2) and nodes ``x`` (N+1, 2) (as :mod:`.chain`)."""
    n = theta.shape[0]
    a = np.empty((n, 2))
    b = np.empty((n, 2))
    x = np.empty((n + 1, 2))
    x[0, 0] = base[0]
    x[0, 1] = base[1]
    s0 = 0.0
    s1 = 0.0
    for j in range(n):
        c = math.cos(theta[j])
        s = math.sin(theta[j])
        a[j, 0] = c
        a[j, 1] = s
        b[j, 0] = -s
        b[j, 1] = c
        s0 += h * c
        s1 += h * s
        x[j + 1, 0] = s0 + base[0]
        x[j + 1, 1] = s1 + base[1]
    return a, b, x


@njit(cache=True)
def kinetic_energy(theta: np.ndarray, omega: np.ndarray, h: float, mass_e: np.ndarray,
                   rot_inertia: np.ndarray) -> float:
    """``1/2 omega^T M omega`` (:func:`contgrasp_core.rod.chain.mass_matrix`) in O(N), as its
    definition ``1/2 sum m_i |v_i|^2 + 1/2 sum J_i omega_i^2`` with the centre velocities
    ``v_i = h sum_j w_ij b_j omega_j`` (:func:`contgrasp_core.rod.chain.centre_velocities`)."""
    p0 = 0.0  # h sum_{j<i} b_j omega_j
    p1 = 0.0
    total = 0.0
    for i in range(theta.shape[0]):
        bw0 = -h * math.sin(theta[i]) * omega[i]
        bw1 = h * math.cos(theta[i]) * omega[i]
        v0 = p0 + 0.5 * bw0
        v1 = p1 + 0.5 * bw1
        total += mass_e[i] * (v0 * v0 + v1 * v1) + rot_inertia[i] * omega[i] ** 2
        p0 += bw0
        p1 += bw1
    return 0.5 * total


@njit(cache=True)
def _tails(d: np.ndarray) -> np.ndarray:
    """Exclusive suffix sums ``sum_{i>m} D_i`` of per-centre tensors (4, N)."""
    n = d.shape[1]
    t = np.zeros((4, n))
    for m in range(n - 2, -1, -1):
        for p in range(4):
            t[p, m] = t[p, m + 1] + d[p, m + 1]
    return t


@njit(cache=True, fastmath={"reassoc", "contract"})
def newton_system(theta: np.ndarray, omega: np.ndarray, delta: np.ndarray, dt: float, cw: float, cq: float,
                  h: float, base: np.ndarray, rot_inertia: np.ndarray, mass_e: np.ndarray, zeta: float,
                  drag_n: float, drag_t: float, r_c: np.ndarray, stiffness: np.ndarray, joint_ei: np.ndarray,
                  joint_len: np.ndarray, base_angle: float, couple: np.ndarray, node_forces: np.ndarray,
                  rows: np.ndarray, foot: np.ndarray, normal: np.ndarray, tangent: np.ndarray, k_c: float,
                  d_c: float, mu: float, v_eps: float, u_fb: np.ndarray, du: np.ndarray, a: np.ndarray,
                  b: np.ndarray,
                  x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Residual ``mass @ delta - dt q`` and Newton matrix ``mass + dt cw jac_w + cq (dt jac_q + jac_m)``
    at angles ``theta`` and rates ``omega`` (``delta`` the step's rate increment ``w1 - w0``), as
    :meth:`~contgrasp_core.rod.integrator.RodSystem.newton_system`, the matrix in the form of
    :class:`~contgrasp_core.rod.newton_matrix.ChainMatrix`. Empty ``couple`` / ``node_forces`` /
    ``rows`` / ``u_fb`` mean absent; ``a``, ``b``, ``x`` from :func:`frames_nodes`.
    Returns (residual, lower triangle and diagonal, upper generators (N, 2), band (N,), penetration)."""
    n = theta.shape[0]
    hh = h * h
    # ---- per-element kinematics: centres, velocities, centripetal forces
    v = np.empty((n, 2))
    f = np.empty((n, 2))
    c = np.empty((n, 2))
    p0 = 0.0
    p1 = 0.0
    q0 = 0.0
    q1 = 0.0
    for i in range(n):
        bw0 = h * b[i, 0] * omega[i]
        bw1 = h * b[i, 1] * omega[i]
        w2 = omega[i] ** 2
        aw0 = -h * a[i, 0] * w2
        aw1 = -h * a[i, 1] * w2
        v[i, 0] = 0.5 * bw0 + p0
        v[i, 1] = 0.5 * bw1 + p1
        f[i, 0] = -mass_e[i] * (0.5 * aw0 + q0)
        f[i, 1] = -mass_e[i] * (0.5 * aw1 + q1)
        p0 += bw0
        p1 += bw1
        q0 += aw0
        q1 += aw1
        c[i, 0] = 0.5 * (x[i, 0] + x[i + 1, 0])
        c[i, 1] = 0.5 * (x[i, 1] + x[i + 1, 1])
    damp = np.zeros((4, n))  # per-centre -df/dv (xx, xy, yx, yy)
    stiff = np.zeros((4, n))  # per-centre -df/dc of contact
    e = np.zeros((n, 2))
    has_drag = drag_n > 0 or drag_t > 0
    if has_drag:
        for i in range(n):
            vn = v[i, 0] * b[i, 0] + v[i, 1] * b[i, 1]
            vt = v[i, 0] * a[i, 0] + v[i, 1] * a[i, 1]
            dl = 2.0 * r_c[i] * h
            fn = -drag_n * dl * abs(vn) * vn
            ft = -drag_t * dl * abs(vt) * vt
            fd0 = fn * b[i, 0] + ft * a[i, 0]
            fd1 = fn * b[i, 1] + ft * a[i, 1]
            f[i, 0] += fd0
            f[i, 1] += fd1
            gn = 2.0 * drag_n * dl * abs(vn)
            gt = 2.0 * drag_t * dl * abs(vt)
            damp[0, i] += gn * b[i, 0] * b[i, 0] + gt * a[i, 0] * a[i, 0]
            damp[1, i] += gn * b[i, 0] * b[i, 1] + gt * a[i, 0] * a[i, 1]
            damp[2, i] += gn * b[i, 1] * b[i, 0] + gt * a[i, 1] * a[i, 0]
            damp[3, i] += gn * b[i, 1] * b[i, 1] + gt * a[i, 1] * a[i, 1]
            fnb = fd0 * b[i, 0] + fd1 * b[i, 1]
            fta = fd0 * a[i, 0] + fd1 * a[i, 1]
            cb = gn * vt + fta
            ca = gt * vn + fnb
            e[i, 0] = cb * b[i, 0] - ca * a[i, 0]
            e[i, 1] = cb * b[i, 1] - ca * a[i, 1]
    pen_max = 0.0
    nr = rows.shape[0]
    for r in range(nr):
        i = rows[r]
        n0 = normal[r, 0]
        n1 = normal[r, 1]
        t0 = tangent[r, 0]
        t1 = tangent[r, 1]
        pen = r_c[i] - ((c[i, 0] - foot[r, 0]) * n0 + (c[i, 1] - foot[r, 1]) * n1)
        pen_max = max(pen_max, pen)
        pen_rate = -(v[i, 0] * n0 + v[i, 1] * n1)
        fn = h * (k_c * pen + d_c * pen_rate)
        active = pen > 0 and fn > 0
        if not active:
            fn = 0.0
        ratio = 0.0
        frd = 0.0
        f[i, 0] += fn * n0
        f[i, 1] += fn * n1
        if mu > 0:
            vt = v[i, 0] * t0 + v[i, 1] * t1
            xx = vt / v_eps
            ratio = mu * math.tanh(xx)
            f[i, 0] -= ratio * fn * t0
            f[i, 1] -= ratio * fn * t1
            frd = mu * fn / v_eps / math.cosh(xx) ** 2
        if not active:
            ratio = 0.0
        kk = h * k_c if active else 0.0
        dd = h * d_c if active else 0.0
        u0 = n0 - ratio * t0
        u1 = n1 - ratio * t1
        stiff[0, i] = hh * (kk * u0 * n0)
        stiff[1, i] = hh * (kk * u0 * n1)
        stiff[2, i] = hh * (kk * u1 * n0)
        stiff[3, i] = hh * (kk * u1 * n1)
        damp[0, i] += dd * u0 * n0 + frd * t0 * t0
        damp[1, i] += dd * u0 * n1 + frd * t0 * t1
        damp[2, i] += dd * u1 * n0 + frd * t1 * t0
        damp[3, i] += dd * u1 * n1 + frd * t1 * t1
    pen_max = max(pen_max, 0.0)
    for p in range(4):
        for i in range(n):
            damp[p, i] *= hh
    # ---- Gram forms through their tail sums (chain.gram_form): per row/column 2-vectors
    ts = _tails(stiff)
    td = _tails(damp)
    us = np.empty((n, 2))  # (S_j + D_j/2)^T b_j, stiffness, lower triangle rows
    zs = np.empty((n, 2))  # (S_k + D_k/2) b_k, upper triangle columns
    ud = np.empty((n, 2))  # damping, (b, .) lower rows
    zdb = np.empty((n, 2))  # damping upper columns with right = b
    zda = np.empty((n, 2))  # damping upper columns with right = a
    gs = np.empty(n)  # diagonals: b^T (S + D/4) b (stiffness), b^T (S + D/4) b and b^T (S + D/4) a (damping)
    gdb = np.empty(n)
    gda = np.empty(n)
    for j in range(n):
        sxx = ts[0, j] + 0.5 * stiff[0, j]
        sxy = ts[1, j] + 0.5 * stiff[1, j]
        syx = ts[2, j] + 0.5 * stiff[2, j]
        syy = ts[3, j] + 0.5 * stiff[3, j]
        us[j, 0] = sxx * b[j, 0] + syx * b[j, 1]
        us[j, 1] = sxy * b[j, 0] + syy * b[j, 1]
        zs[j, 0] = sxx * b[j, 0] + sxy * b[j, 1]
        zs[j, 1] = syx * b[j, 0] + syy * b[j, 1]
        dxx = td[0, j] + 0.5 * damp[0, j]
        dxy = td[1, j] + 0.5 * damp[1, j]
        dyx = td[2, j] + 0.5 * damp[2, j]
        dyy = td[3, j] + 0.5 * damp[3, j]
        ud[j, 0] = dxx * b[j, 0] + dyx * b[j, 1]
        ud[j, 1] = dxy * b[j, 0] + dyy * b[j, 1]
        zdb[j, 0] = dxx * b[j, 0] + dxy * b[j, 1]
        zdb[j, 1] = dyx * b[j, 0] + dyy * b[j, 1]
        zda[j, 0] = dxx * a[j, 0] + dxy * a[j, 1]
        zda[j, 1] = dyx * a[j, 0] + dyy * a[j, 1]
        sxx = ts[0, j] + 0.25 * stiff[0, j]
        sxy = ts[1, j] + 0.25 * stiff[1, j]
        syx = ts[2, j] + 0.25 * stiff[2, j]
        syy = ts[3, j] + 0.25 * stiff[3, j]
        gs[j] = b[j, 0] * (sxx * b[j, 0] + sxy * b[j, 1]) + b[j, 1] * (syx * b[j, 0] + syy * b[j, 1])
        dxx = td[0, j] + 0.25 * damp[0, j]
        dxy = td[1, j] + 0.25 * damp[1, j]
        dyx = td[2, j] + 0.25 * damp[2, j]
        dyy = td[3, j] + 0.25 * damp[3, j]
        gdb[j] = b[j, 0] * (dxx * b[j, 0] + dxy * b[j, 1]) + b[j, 1] * (dyx * b[j, 0] + dyy * b[j, 1])
        gda[j] = b[j, 0] * (dxx * a[j, 0] + dxy * a[j, 1]) + b[j, 1] * (dyx * a[j, 0] + dyy * a[j, 1])
    # ---- generalised force q
    tail0 = 0.0
    tail1 = 0.0
    nf0 = 0.0
    nf1 = 0.0
    has_nf = node_forces.shape[0] > 0
    q = np.empty(n)
    tdiag = np.empty(n)  # h a_j . tail_j (the diagonal of jac_q from the force directions' rotation)
    for j in range(n - 1, -1, -1):
        t0 = tail0 + 0.5 * f[j, 0]
        t1 = tail1 + 0.5 * f[j, 1]
        if has_nf:
            nf0 += node_forces[j + 1, 0]
            nf1 += node_forces[j + 1, 1]
            t0 += nf0
            t1 += nf1
        q[j] = h * (b[j, 0] * t0 + b[j, 1] * t1)
        tdiag[j] = h * (a[j, 0] * t0 + a[j, 1] * t1)
        tail0 += f[j, 0]
        tail1 += f[j, 1]
    mom = np.empty(n)
    prev = base_angle
    for k in range(n):
        mom[k] = joint_ei[k] * ((theta[k] - prev) / joint_len[k])
        prev = theta[k]
    if couple.shape[0] > 0:
        for k in range(n):
            mom[k] += couple[k]
    has_fb = u_fb.shape[0] > 0
    if has_fb:
        for k in range(n):
            mom[k] += u_fb[k]
    for k in range(n):
        q[k] -= mom[k]
    for k in range(n - 1):
        q[k] += mom[k + 1]
    # ---- the matrix in the structure of its terms (contgrasp_core.rod.newton_matrix): with the
    # weights W_jk = g_max(j,k) off the diagonal (g_k = T_k + m_k/2, W_kk = T_k + m_k/4, T_k the
    # mass beyond element k; chain.weight_matrix), the inertia terms are h^2 W_jk a_j . gam_k with
    # gam_k = alpha_k a_k + beta_k b_k; the upper triangle is a_j . up_k (k > j) plus the band
    # entry band_j at (j, j+1), the lower triangle lo_j . col_k plus the bending band and the
    # feedback's du: only the lower triangle and the diagonal are stored in jac
    g = np.empty(n)
    w_diag = np.empty(n)
    beyond = 0.0
    for k in range(n - 1, -1, -1):
        g[k] = beyond + 0.5 * mass_e[k]
        w_diag[k] = beyond + 0.25 * mass_e[k]
        beyond += mass_e[k]
    cwdt = dt * cw
    cqdt = cq * dt
    col = np.empty((n, 6))  # lower triangle column generators: gam_k, b_k, omega_k a_k
    up = np.empty((n, 2))
    band = np.zeros(n)
    alpha = np.empty(n)
    for k in range(n):
        alpha[k] = 1.0 + cwdt * zeta - cqdt * omega[k] ** 2
        beta = 2.0 * cwdt * omega[k] + cqdt * zeta * omega[k] + cq * delta[k]
        gam0 = alpha[k] * a[k, 0] + beta * b[k, 0]
        gam1 = alpha[k] * a[k, 1] + beta * b[k, 1]
        col[k, 0] = gam0
        col[k, 1] = gam1
        col[k, 2] = b[k, 0]
        col[k, 3] = b[k, 1]
        col[k, 4] = omega[k] * a[k, 0]
        col[k, 5] = omega[k] * a[k, 1]
        # b_j . z = a_j . (z_1, -z_0): the damping and stiffness Gram forms and drag as a_j . up_k
        z0 = cwdt * zdb[k, 0] + cqdt * (zs[k, 0] - zda[k, 0] * omega[k])
        z1 = cwdt * zdb[k, 1] + cqdt * (zs[k, 1] - zda[k, 1] * omega[k])
        if has_drag:
            z0 -= cqdt * h * e[k, 0]
            z1 -= cqdt * h * e[k, 1]
        up[k, 0] = hh * g[k] * gam0 + z1
        up[k, 1] = hh * g[k] * gam1 - z0
        if k < n - 1:
            band[k] = cqdt * stiffness[k, k + 1]
            if has_fb:
                band[k] -= cqdt * du[k + 1, k + 1]
    # row sums of the mass matrix and of ws_jk = h^2 W_jk a_j . b_k (against omega and delta)
    # through prefix sums (k < j, weight g_j) and suffix sums (k > j, weight g_k)
    suf = np.zeros((n, 4))  # sum_{k>j} g_k a_k omega_k, sum_{k>j} g_k a_k delta_k
    for k in range(n - 1, 0, -1):
        suf[k - 1, 0] = suf[k, 0] + g[k] * a[k, 0] * omega[k]
        suf[k - 1, 1] = suf[k, 1] + g[k] * a[k, 1] * omega[k]
        suf[k - 1, 2] = suf[k, 2] + g[k] * a[k, 0] * delta[k]
        suf[k - 1, 3] = suf[k, 3] + g[k] * a[k, 1] * delta[k]
    pre_w0 = 0.0  # sum_{k<j} a_k omega_k, sum_{k<j} a_k delta_k
    pre_w1 = 0.0
    pre_d0 = 0.0
    pre_d1 = 0.0
    jac = np.empty((n, n))
    res = np.empty(n)
    for j in range(n):
        cj = a[j, 0]
        sj = a[j, 1]
        gj = hh * g[j]
        mjj = hh * w_diag[j] + rot_inertia[j]
        mo = gj * (cj * pre_w0 + sj * pre_w1) + hh * (cj * suf[j, 0] + sj * suf[j, 1]) + mjj * omega[j]
        md = gj * (cj * pre_d0 + sj * pre_d1) + hh * (cj * suf[j, 2] + sj * suf[j, 3]) + mjj * delta[j]
        wso = gj * (sj * pre_w0 - cj * pre_w1) + hh * (sj * suf[j, 0] - cj * suf[j, 1])
        wsd = gj * (sj * pre_d0 - cj * pre_d1) + hh * (sj * suf[j, 2] - cj * suf[j, 3])
        qj = q[j]
        if zeta > 0:
            qj -= zeta * mo
        res[j] = md - dt * qj
        pre_w0 += cj * omega[j]
        pre_w1 += sj * omega[j]
        pre_d0 += cj * delta[j]
        pre_d1 += sj * delta[j]
        # lower triangle: inertia h^2 g_j a_j . gam_k, the Gram forms (rows ud, us), bending, du
        l0 = gj * cj
        l1 = gj * sj
        l2 = cwdt * ud[j, 0] + cqdt * us[j, 0]
        l3 = cwdt * ud[j, 1] + cqdt * us[j, 1]
        l4 = -cqdt * ud[j, 0]
        l5 = -cqdt * ud[j, 1]
        row = jac[j]
        for k in range(j):
            row[k] = (l0 * col[k, 0] + l1 * col[k, 1] + l2 * col[k, 2] + l3 * col[k, 3] + l4 * col[k, 4]
                      + l5 * col[k, 5])
        if j > 0:
            row[j - 1] += cqdt * stiffness[j, j - 1]
        # diagonal: inertia, rotary inertia, row sums, drag, Gram diagonals, force-direction rotation
        jq = -zeta * wso + gs[j] - gda[j] * omega[j] + tdiag[j]
        if has_drag:
            jq -= h * 0.5 * (b[j, 0] * e[j, 0] + b[j, 1] * e[j, 1])
        row[j] = (hh * w_diag[j] * alpha[j] + rot_inertia[j] * (1.0 + cwdt * zeta) + cwdt * gdb[j]
                  + cq * (dt * jq - wsd) + cqdt * stiffness[j, j])
        if has_fb:  # du (lower triangle and diagonal) minus the next joint's row
            for k in range(j + 1):
                row[k] += cqdt * du[j, k]
            if j < n - 1:
                for k in range(j + 1):
                    row[k] -= cqdt * du[j + 1, k]
    return res, jac, up, band, pen_max


@njit(cache=True, error_model="numpy")  # (a zero pivot gives inf/NaN, not an exception)
def chain_solve(lower: np.ndarray, left: np.ndarray, up: np.ndarray, band: np.ndarray,
                rhs: np.ndarray) -> np.ndarray:
    """``A^-1 rhs`` for ``A`` with the given lower triangle and diagonal (``lower``, its upper
    triangle unused) and the upper triangle ``A_jk = left_j . up_k + [k = j+1] band_j``, by
    Gaussian elimination without pivoting in O(N^2) (:class:`contgrasp_core.rod.newton_matrix.ChainMatrix`)."""
    n = rhs.shape[0]
    acc = np.zeros((n, 2))  # W_i: the Schur complement's upper triangle is (left_i - W_i) . up_k
    carry = np.zeros(n)  # the band entry's share in the next pivot column
    y = rhs.copy()
    piv = np.empty(n)
    z = np.empty((n, 2))
    for j in range(n):
        u0 = up[j, 0]
        u1 = up[j, 1]
        d = lower[j, j] - acc[j, 0] * u0 - acc[j, 1] * u1 - carry[j]
        z0 = left[j, 0] - acc[j, 0]
        z1 = left[j, 1] - acc[j, 1]
        piv[j] = d
        z[j, 0] = z0
        z[j, 1] = z1
        inv = 1.0 / d
        yj = y[j]
        ej = band[j]
        for i in range(j + 1, n):
            f = (lower[i, j] - acc[i, 0] * u0 - acc[i, 1] * u1 - carry[i]) * inv
            acc[i, 0] += f * z0
            acc[i, 1] += f * z1
            carry[i] = f * ej
            y[i] -= f * yj
    x = np.empty(n)
    t0 = 0.0  # sum_{k>j} up_k x_k
    t1 = 0.0
    nxt = 0.0
    for j in range(n - 1, -1, -1):
        xj = (y[j] - z[j, 0] * t0 - z[j, 1] * t1 - band[j] * nxt) / piv[j]
        x[j] = xj
        t0 += up[j, 0] * xj
        t1 += up[j, 1] * xj
        nxt = xj
    return x


@njit(cache=True)
def _circle_polar(qx: float, qy: float, cx: float, cy: float) -> tuple[float, float, float, float]:
    """Distance of ``(qx, qy)`` from the circle's centre, its polar angle, and the outward unit
    normal ``(n0, n1)`` there ((1, 0) at the centre): the per-point part of the circle kernels."""
    d0 = qx - cx
    d1 = qy - cy
    dist = math.hypot(d0, d1)
    if dist > 0:
        return dist, math.atan2(d1, d0), d0 / dist, d1 / dist
    return dist, math.atan2(d1, d0), 1.0, 0.0


@njit(cache=True)
def circle_projection(q: np.ndarray, radius: float, cx: float,
                      cy: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closest points on the circle ``|p - c| = radius`` (as ``Obstacle.project``): foot (n, 2),
    arclength ``s_o = mod(t, 2 pi) radius`` (n,), tangent angle ``t + pi/2`` (n,), curvature
    (n,), signed distance (n,), outward normal (n, 2), ``t`` the query's polar angle; a query at
    the centre gets the normal (1, 0)."""
    n = q.shape[0]
    foot = np.empty((n, 2))
    s_o = np.empty(n)
    phi = np.empty(n)
    kappa = np.full(n, 1.0 / radius)
    sd = np.empty(n)
    nrm = np.empty((n, 2))
    for i in range(n):
        dist, ang, n0, n1 = _circle_polar(q[i, 0], q[i, 1], cx, cy)
        s_o[i] = (ang % (2 * np.pi)) * radius  # (Python's float mod: numpy's np.mod)
        phi[i] = ang + 0.5 * np.pi
        nrm[i, 0] = n0
        nrm[i, 1] = n1
        foot[i, 0] = cx + radius * n0
        foot[i, 1] = cy + radius * n1
        sd[i] = dist - radius
    return foot, s_o, phi, kappa, sd, nrm


@njit(cache=True, error_model="numpy")  # (1 + rho kappa_o = 0 gives inf, as numpy's division)
def circle_shadow_geometry(q: np.ndarray, angles: np.ndarray, radius: float, cx: float,
                           cy: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`contgrasp_core.contact.shadow_geometry` against a circle: ``rho``, ``alpha``,
    ``kappa_o``, ``foot_turn``, ``normal_out`` of the points ``q`` (n, 2) with tangent angles (n,),
    by the operations of :func:`circle_projection` and of ``shadow_geometry`` on its result, in
    the same order (the same bits)."""
    n = q.shape[0]
    rho = np.empty(n)
    alpha = np.empty(n)
    kappa = np.full(n, 1.0 / radius)
    turn = np.empty(n)
    nrm = np.empty((n, 2))
    for i in range(n):
        dist, ang, nrm[i, 0], nrm[i, 1] = _circle_polar(q[i, 0], q[i, 1], cx, cy)
        phi = ang + 0.5 * np.pi
        rho[i] = dist - radius
        alpha[i] = (phi + 0.5 * np.pi - angles[i] + np.pi) % (2.0 * np.pi) - np.pi
        turn[i] = kappa[i] / (1.0 + rho[i] * kappa[i])
    return rho, alpha, kappa, turn, nrm


@njit(cache=True, error_model="numpy")  # (1 + rho kappa_o = 0 gives inf or NaN, as numpy's division)
def circle_sense(r: np.ndarray, theta: np.ndarray, rad: np.ndarray, radius: float, cx: float, cy: float,
                 length: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                         np.ndarray, np.ndarray, np.ndarray]:
    """:func:`contgrasp_core.contact.sense` of the points ``r`` (n, 2) with tangent angles
    ``theta`` and arm radii ``rad`` (n,) against the circle of ``radius`` about ``(cx, cy)``
    (a :class:`~contgrasp_core.boundary.Boundary` of kind circle, perimeter ``length``), in one
    pass: the closest point as ``Boundary._project_circle`` computes it (foot from the query's
    polar angle ``t``), then eqs. (4), (5) and (7) as ``sense`` does, and ``s_o`` unwrapped along
    the arm as ``contact._unwrap`` (numpy's ``unwrap`` with period ``length``). Returns ``s_o``,
    ``rho``, ``alpha``, ``delta``, ``foot`` (n, 2), ``kappa_o``, ``nu_o``, ``foot_turn`` and
    ``normal_out`` (n, 2); the same operations as the numpy path (agreement to
    rounding: numpy's and libm's transcendental functions may differ in the last bit)."""
    n = r.shape[0]
    two_pi = 2.0 * np.pi
    s_o = np.empty(n)
    rho = np.empty(n)
    alpha = np.empty(n)
    delta = np.empty(n)
    foot = np.empty((n, 2))
    kappa = np.full(n, 1.0 / radius)
    nu = np.empty(n)
    turn = np.empty(n)
    nrm = np.empty((n, 2))
    for i in range(n):
        t = math.atan2(r[i, 1] - cy, r[i, 0] - cx) % two_pi
        if t >= two_pi:
            t = 0.0  # (mod of a tiny negative rounds to 2 pi: the seam is t = 0)
        cs, sn = math.cos(t), math.sin(t)
        foot[i, 0] = radius * cs + cx
        foot[i, 1] = radius * sn + cy
        rel0, rel1 = r[i, 0] - foot[i, 0], r[i, 1] - foot[i, 1]
        d = math.hypot(rel0, rel1)
        cross = -radius * sn * rel1 - radius * cs * rel0  # c'(t) x (q - foot) > 0: inside
        side = -np.sign(cross)
        so = (radius * t) % length
        s_o[i] = 0.0 if so >= length else so
        rho[i] = side * d
        phi = t + 0.5 * np.pi
        alpha[i] = (phi + 0.5 * np.pi - theta[i] + np.pi) % two_pi - np.pi
        one_plus = 1.0 + rho[i] * kappa[i]
        nu[i] = math.sin(alpha[i]) / one_plus
        turn[i] = kappa[i] / one_plus
        delta[i] = rad[i] - rho[i]
        nrm[i, 0] = math.sin(phi)
        nrm[i, 1] = -math.cos(phi)
    # unwrap s_o along the arm (numpy's unwrap, period = length, discont = length / 2)
    half = length / 2
    correction = 0.0
    previous = s_o[0] if n else 0.0
    for i in range(1, n):
        dd = s_o[i] - previous
        previous = s_o[i]
        if abs(dd) >= half:
            ddmod = (dd + half) % length - half
            if ddmod == -half and dd > 0:
                ddmod = half  # (a step of exactly +period/2 stays)
            correction += ddmod - dd
        s_o[i] += correction
    return s_o, rho, alpha, delta, foot, kappa, nu, turn, nrm


@njit(cache=True)
def joint_couple_jacobian(h: float, g_rho: np.ndarray, g_alpha: np.ndarray, rho: np.ndarray, kappa_o: np.ndarray,
                          foot_turn: np.ndarray, normal_out: np.ndarray, b: np.ndarray,
                          safe_one_plus: float) -> np.ndarray:
    """``du/dtheta`` (N, N) of :func:`contgrasp_core.control.rod_feedback.joint_couple_jacobian`:
    ``h (g_rho n_k + g_alpha turn_k t_k) . b_l`` for ``l < k`` and ``-g_alpha_k / 2`` at
    ``(k, k)`` and ``(k, k-1)``, ``k >= 1``; ``turn_k = foot_turn_k`` where ``1 + rho_k kappa_o_k >
    safe_one_plus``, else 0 (the shadow geometry at the N+1 nodes; the joints are the first N)."""
    n = g_rho.shape[0]
    du = np.zeros((n, b.shape[0]))
    for k in range(n):
        n0 = normal_out[k, 0]
        n1 = normal_out[k, 1]
        ga = g_alpha[k] * (foot_turn[k] if 1.0 + rho[k] * kappa_o[k] > safe_one_plus else 0.0)
        d0 = g_rho[k] * n0 + ga * (-n1)
        d1 = g_rho[k] * n1 + ga * n0
        for j in range(k):
            du[k, j] = h * (d0 * b[j, 0] + d1 * b[j, 1])
        if k >= 1:
            coef = -0.5 * g_alpha[k]
            du[k, k] += coef
            du[k, k - 1] += coef
    return du


@njit(cache=True)
def _segment_point(c: np.ndarray, i: int, seg: int) -> tuple[float, float]:
    """Parameter ``t`` of the point of segment ``(seg, seg + 1)`` of the polyline ``c`` closest to
    ``c[i]``, and the distance to it (as :func:`contgrasp_core.rod.self_contact._segment_geometry`)."""
    e0 = c[seg + 1, 0] - c[seg, 0]
    e1 = c[seg + 1, 1] - c[seg, 1]
    t = ((c[i, 0] - c[seg, 0]) * e0 + (c[i, 1] - c[seg, 1]) * e1) / (e0 * e0 + e1 * e1)
    t = min(max(t, 0.0), 1.0)
    return t, math.hypot(c[i, 0] - (c[seg, 0] + t * e0), c[i, 1] - (c[seg, 1] + t * e1))


@njit(cache=True)
def self_contact_pairs(c: np.ndarray, s: np.ndarray, r: np.ndarray, h: float,
                       margin: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pairs of :func:`contgrasp_core.rod.self_contact._pairs` in one loop over centres and
    segments (the same tests on the same values): centre, segment, ``t``, distance, foot radius."""
    n = c.shape[0]
    cap = 8 * n
    out_i = np.empty(cap, dtype=np.int64)
    out_seg = np.empty(cap, dtype=np.int64)
    out_t = np.empty(cap)
    out_d = np.empty(cap)
    out_r = np.empty(cap)
    k = 0
    r_max = 0.0
    for j in range(n):
        r_max = max(r_max, r[j])
    for i in range(n):
        reach = r[i] + r_max + margin + h  # (a foot on the segment is within h of its first centre)
        for seg in range(n - 1):
            if abs(s[i] - s[seg]) + h < 0.5 * np.pi * (r[i] + min(r[seg], r[seg + 1])):
                continue  # (every foot on this segment is a neighbour along the arm)
            dx = c[i, 0] - c[seg, 0]
            dy = c[i, 1] - c[seg, 1]
            if dx * dx + dy * dy > reach * reach:
                continue
            t, dist = _segment_point(c, i, seg)
            r_foot = (1.0 - t) * r[seg] + t * r[seg + 1]
            if abs(s[i] - (s[seg] + t * h)) <= 0.5 * np.pi * (r[i] + r_foot):
                continue
            if not dist - r[i] - r_foot < margin:
                continue
            if seg > 0 and not dist <= _segment_point(c, i, seg - 1)[1]:
                continue
            if seg < n - 2 and not dist < _segment_point(c, i, seg + 1)[1]:
                continue
            if k == cap:
                cap *= 2
                out_i, out_seg = np.resize(out_i, cap), np.resize(out_seg, cap)
                out_t, out_d, out_r = np.resize(out_t, cap), np.resize(out_d, cap), np.resize(out_r, cap)
            out_i[k], out_seg[k], out_t[k], out_d[k], out_r[k] = i, seg, t, dist, r_foot
            k += 1
    return out_i[:k], out_seg[:k], out_t[:k], out_d[:k], out_r[:k]
