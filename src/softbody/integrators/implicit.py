"""Implicit (backward) Euler, Baraff & Witkin (1998) style, solved matrix-free by CG.

One Newton step of backward Euler on M v' = f(x, v):

    (M - dt C - dt^2 K) dv = dt (f0 + dt K v0),   v1 = v0 + dv,   x1 = x0 + dt v1,

with K = df/dx and C = df/dv at the start of the step. Nothing is assembled: the products
K p and C p are computed term by term:

* springs: K_s = k [u u^T + max(0, 1 - L0/L) (I - u u^T)] between the two ends (the
  compressive part of the geometric stiffness is dropped so that -K stays positive
  semi-definite, as Choi & Ko do), C_s = c u u^T;
* attachments: the same blocks to a fixed point;
* pressure of each body: K_p = P'(V) g g^T + (P - P_a) d2V/dx2 with g = dV/dx: a rank-one
  term (one dot product per body) plus, for each face (a, b, c) and its rotations,
  (d2V/dx2 p)_a += ((p_b x x_c) + (x_b x p_c)) / 6, never a dense matrix.

The system matrix is symmetric; CG with a Jacobi preconditioner solves it to a relative
residual ``tolerance``. The pressure Hessian is indefinite, so at very large steps the
matrix may lose definiteness: CG then stops at its last good iterate. Pinned particles
keep their velocity (their rows are filtered out). Backward Euler is unconditionally
stable for linear problems and first-order accurate, and it damps: energy is lost at a
rate that grows with dt (benchmarks/implicit_energy.py plots it).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _prepare_springs(
    q, spring_indices, spring_rest_length, spring_stiffness, spring_u, spring_a, spring_b
):
    """Per spring: unit direction u (S, 3), axial stiffness a = k and transverse
    stiffness b = k max(0, 1 - L0 / L) (S,)."""
    for s in range(spring_indices.shape[0]):
        i, j = spring_indices[s, 0], spring_indices[s, 1]
        dx, dy, dz = q[j, 0] - q[i, 0], q[j, 1] - q[i, 1], q[j, 2] - q[i, 2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        k = spring_stiffness[s]
        if length == 0.0:
            spring_u[s, 0] = spring_u[s, 1] = spring_u[s, 2] = 0.0
            spring_a[s] = 0.0
            spring_b[s] = k
            continue
        spring_u[s, 0], spring_u[s, 1], spring_u[s, 2] = dx / length, dy / length, dz / length
        spring_a[s] = k
        spring_b[s] = k * max(0.0, 1.0 - spring_rest_length[s] / length)


@njit(cache=True)
def apply_jacobians(
    m,
    c,
    q,
    p,
    alpha_m,
    alpha_c,
    alpha_k,
    spring_u,
    spring_a,
    spring_b,
    volume_gradient,
    body_dpdv,
    body_pnet,
    out,
):
    """out = alpha_m M p + alpha_c C p + alpha_k K p for p (N, 3), C = df/dv, K = df/dx.

    spring_u/a/b from ``_prepare_springs``; volume_gradient (N, 3) = dV/dx; body_dpdv (B,)
    = dP/dV [Pa/m^3]; body_pnet (B,) = P - P_ambient [Pa].
    """
    for i in range(q.shape[0]):
        w = alpha_m * m.particle_mass[i]
        out[i, 0] = w * p[i, 0]
        out[i, 1] = w * p[i, 1]
        out[i, 2] = w * p[i, 2]
    # springs: (K p)_i += K_s (p_j - p_i), (C p)_i += C_s (p_j - p_i); opposite on j
    for s in range(m.spring_indices.shape[0]):
        i, j = m.spring_indices[s, 0], m.spring_indices[s, 1]
        dx, dy, dz = p[j, 0] - p[i, 0], p[j, 1] - p[i, 1], p[j, 2] - p[i, 2]
        ux, uy, uz = spring_u[s, 0], spring_u[s, 1], spring_u[s, 2]
        ud = ux * dx + uy * dy + uz * dz
        iso = alpha_k * spring_b[s]
        axial = alpha_k * (spring_a[s] - spring_b[s]) * ud + alpha_c * m.spring_damping[s] * ud
        wx, wy, wz = iso * dx + axial * ux, iso * dy + axial * uy, iso * dz + axial * uz
        out[i, 0] += wx
        out[i, 1] += wy
        out[i, 2] += wz
        out[j, 0] -= wx
        out[j, 1] -= wy
        out[j, 2] -= wz
    # attachments to fixed anchors: (K p)_i -= K_a p_i, (C p)_i -= c u u^T p_i
    for a in range(m.attachment_particle.shape[0]):
        i = m.attachment_particle[a]
        dx = c.attachment_anchor[a, 0] - q[i, 0]
        dy = c.attachment_anchor[a, 1] - q[i, 1]
        dz = c.attachment_anchor[a, 2] - q[i, 2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        k = m.attachment_stiffness[a]
        if length == 0.0:
            iso, ux, uy, uz, ud = k, 0.0, 0.0, 0.0, 0.0
        else:
            ux, uy, uz = dx / length, dy / length, dz / length
            iso = k * max(0.0, 1.0 - m.attachment_rest_length[a] / length)
            ud = ux * p[i, 0] + uy * p[i, 1] + uz * p[i, 2]
        axial = alpha_k * (k - iso) * ud + alpha_c * m.attachment_damping[a] * ud
        out[i, 0] -= alpha_k * iso * p[i, 0] + axial * ux
        out[i, 1] -= alpha_k * iso * p[i, 1] + axial * uy
        out[i, 2] -= alpha_k * iso * p[i, 2] + axial * uz
    # grab spring (Control): (K p)_i -= k p_i, (C p)_i -= c p_i
    g = c.grab_particle
    if g >= 0:
        for k in range(3):
            out[g, k] -= (alpha_k * c.grab_stiffness + alpha_c * c.grab_damping) * p[g, k]
    # pressure: (K p) += P'(V) g (g . p) + (P - Pa) H p, per body
    if alpha_k == 0.0:
        return
    for body in range(m.body_particle_range.shape[0]):
        p0, p1 = m.body_particle_range[body, 0], m.body_particle_range[body, 1]
        gp = 0.0
        for i in range(p0, p1):
            gp += (
                volume_gradient[i, 0] * p[i, 0]
                + volume_gradient[i, 1] * p[i, 1]
                + volume_gradient[i, 2] * p[i, 2]
            )
        c1 = alpha_k * body_dpdv[body] * gp
        if c1 != 0.0:
            for i in range(p0, p1):
                out[i, 0] += c1 * volume_gradient[i, 0]
                out[i, 1] += c1 * volume_gradient[i, 1]
                out[i, 2] += c1 * volume_gradient[i, 2]
        coef = alpha_k * body_pnet[body] / 6.0
        if coef == 0.0:
            continue
        # d/dx of (x_b - x_a) x (x_c - x_a) / 6, the face's share of g at each corner
        for t in range(m.body_tri_range[body, 0], m.body_tri_range[body, 1]):
            for rot in range(3):
                ia = m.tri_indices[t, rot]
                ib = m.tri_indices[t, (rot + 1) % 3]
                ic = m.tri_indices[t, (rot + 2) % 3]
                bx, by, bz = q[ib, 0] - q[ia, 0], q[ib, 1] - q[ia, 1], q[ib, 2] - q[ia, 2]
                cx, cy, cz = q[ic, 0] - q[ia, 0], q[ic, 1] - q[ia, 1], q[ic, 2] - q[ia, 2]
                pbx, pby, pbz = p[ib, 0] - p[ia, 0], p[ib, 1] - p[ia, 1], p[ib, 2] - p[ia, 2]
                pcx, pcy, pcz = p[ic, 0] - p[ia, 0], p[ic, 1] - p[ia, 1], p[ic, 2] - p[ia, 2]
                hx = (pby * cz - pbz * cy) + (by * pcz - bz * pcy)
                hy = (pbz * cx - pbx * cz) + (bz * pcx - bx * pcz)
                hz = (pbx * cy - pby * cx) + (bx * pcy - by * pcx)
                out[ia, 0] += coef * hx
                out[ia, 1] += coef * hy
                out[ia, 2] += coef * hz


@njit(cache=True)
def _body_pressure_slopes(m, body_volume, body_pressure, body_dpdv, body_pnet):
    """dP/dV (B,) of each body's gas law at its volume, and P - P_ambient (B,)."""
    for b in range(body_volume.shape[0]):
        law = m.body_gas_law[b]
        v = body_volume[b]
        p = body_pressure[b]
        body_pnet[b] = p - m.body_ambient_pressure[b]
        if law == 1 or m.body_closed[b] == 0 or not v > 0.0:
            body_dpdv[b] = 0.0  # fixed pressure (or an open surface)
        elif law == 0:
            body_dpdv[b] = -p / v  # isothermal: P = nRT / V
        else:
            body_dpdv[b] = -m.body_gas_gamma[b] * p / v  # adiabatic: P V^gamma const


@njit(cache=True)
def _dot_free(a, b, inv_mass):
    s = 0.0
    for i in range(a.shape[0]):
        if inv_mass[i] > 0.0:
            s += a[i, 0] * b[i, 0] + a[i, 1] * b[i, 1] + a[i, 2] * b[i, 2]
    return s


@njit(cache=True)
def step_implicit_euler(m, c, t, dt, q, qd, w, tolerance, max_iterations):
    """One backward Euler step (module docstring). w.f holds f(x0, v0) on entry; returns
    the number of CG iterations used."""
    n = q.shape[0]
    inv_mass = m.particle_inv_mass
    _prepare_springs(
        w.q0,
        m.spring_indices,
        m.spring_rest_length,
        m.spring_stiffness,
        w.spring_u,
        w.spring_a,
        w.spring_b,
    )
    _body_pressure_slopes(m, w.body_volume, w.body_pressure, w.body_dpdv, w.body_pnet)
    # right-hand side b = dt (f0 + dt K v0), kept in w.acc_v
    apply_jacobians(
        m,
        c,
        w.q0,
        w.v0,
        0.0,
        0.0,
        1.0,
        w.spring_u,
        w.spring_a,
        w.spring_b,
        w.volume_gradient,
        w.body_dpdv,
        w.body_pnet,
        w.acc_v,
    )
    # Jacobi preconditioner: mass + dt (damping) + dt^2 (stiffness) on the diagonal
    for i in range(n):
        w.cg_diag[i] = m.particle_mass[i]
    for s in range(m.spring_indices.shape[0]):
        d = dt * m.spring_damping[s] + dt * dt * w.spring_a[s]
        w.cg_diag[m.spring_indices[s, 0]] += d
        w.cg_diag[m.spring_indices[s, 1]] += d
    rhs_norm = 0.0
    for i in range(n):
        for k in range(3):
            b = dt * (w.f[i, k] + dt * w.acc_v[i, k]) if inv_mass[i] > 0.0 else 0.0
            w.cg_r[i, k] = b  # residual of dv = 0
            w.cg_x[i, k] = 0.0
            rhs_norm += b * b
    rhs_norm = np.sqrt(rhs_norm)
    iterations = 0
    if rhs_norm > 0.0:
        for i in range(n):
            for k in range(3):
                w.cg_z[i, k] = w.cg_r[i, k] / w.cg_diag[i]
                w.cg_p[i, k] = w.cg_z[i, k]
        rz = _dot_free(w.cg_r, w.cg_z, inv_mass)
        while iterations < max_iterations:
            apply_jacobians(
                m,
                c,
                w.q0,
                w.cg_p,
                1.0,
                -dt,
                -dt * dt,
                w.spring_u,
                w.spring_a,
                w.spring_b,
                w.volume_gradient,
                w.body_dpdv,
                w.body_pnet,
                w.cg_ap,
            )
            pap = _dot_free(w.cg_p, w.cg_ap, inv_mass)
            if not pap > 0.0:
                break  # lost definiteness (pressure Hessian at a huge step): keep x
            alpha = rz / pap
            res = 0.0
            for i in range(n):
                if inv_mass[i] == 0.0:
                    continue
                for k in range(3):
                    w.cg_x[i, k] += alpha * w.cg_p[i, k]
                    w.cg_r[i, k] -= alpha * w.cg_ap[i, k]
                    res += w.cg_r[i, k] * w.cg_r[i, k]
            iterations += 1
            if np.sqrt(res) <= tolerance * rhs_norm:
                break
            for i in range(n):
                for k in range(3):
                    w.cg_z[i, k] = w.cg_r[i, k] / w.cg_diag[i]
            rz_new = _dot_free(w.cg_r, w.cg_z, inv_mass)
            beta = rz_new / rz
            rz = rz_new
            for i in range(n):
                for k in range(3):
                    w.cg_p[i, k] = w.cg_z[i, k] + beta * w.cg_p[i, k]
    for i in range(n):
        for k in range(3):
            v = w.v0[i, k] + w.cg_x[i, k]
            qd[i, k] = v
            q[i, k] = w.q0[i, k] + dt * v
    return iterations
