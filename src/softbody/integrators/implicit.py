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
  term (one dot product per body) plus, for each face (a, b, c), the change of its area
  vector (e1 x e2) / 6 (e1 = x_b - x_a, e2 = x_c - x_a), (d1 x e2 + e1 x d2) / 6 with
  d1, d2 the same differences of p, added to all three corners; never a dense matrix.

The system matrix is symmetric; preconditioned CG solves it to a relative residual
``tolerance``, starting from the previous step's dv. The preconditioner is one V-cycle
whose finest level smooths with block Gauss-Seidel on the true spring blocks and whose
coarse levels are an algebraic multigrid hierarchy of the spring Laplacian
(``integrators.multigrid``), or Jacobi. The pressure Hessian is indefinite, so at large
steps (a ball whose springs are still slack, say) the matrix may be too: CG's
recurrences hold for any symmetric matrix, so it carries on through negative curvature
and stops only on an exact breakdown (p^T A p = 0), keeping its last iterate. Pinned particles
keep their velocity (their rows are filtered out). Backward Euler is unconditionally
stable for linear problems and first-order accurate, and it damps: energy is lost at a
rate that grows with dt (benchmarks/implicit_energy.py plots it).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from softbody.integrators.multigrid import _coarse_solve, cycle_from, prolong, restrict


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
        # each corner's share of g is the face's area vector / 3 = (e1 x e2) / 6 with
        # e1 = x_b - x_a, e2 = x_c - x_a (the same from any corner), so its change under
        # p, d1 x e2 + e1 x d2 with d1 = p_b - p_a, d2 = p_c - p_a, goes to all three
        for t in range(m.body_tri_range[body, 0], m.body_tri_range[body, 1]):
            ia, ib, ic = m.tri_indices[t, 0], m.tri_indices[t, 1], m.tri_indices[t, 2]
            ax, ay, az = q[ia, 0], q[ia, 1], q[ia, 2]
            e1x, e1y, e1z = q[ib, 0] - ax, q[ib, 1] - ay, q[ib, 2] - az
            e2x, e2y, e2z = q[ic, 0] - ax, q[ic, 1] - ay, q[ic, 2] - az
            pax, pay, paz = p[ia, 0], p[ia, 1], p[ia, 2]
            d1x, d1y, d1z = p[ib, 0] - pax, p[ib, 1] - pay, p[ib, 2] - paz
            d2x, d2y, d2z = p[ic, 0] - pax, p[ic, 1] - pay, p[ic, 2] - paz
            hx = coef * ((d1y * e2z - d1z * e2y) + (e1y * d2z - e1z * d2y))
            hy = coef * ((d1z * e2x - d1x * e2z) + (e1z * d2x - e1x * d2z))
            hz = coef * ((d1x * e2y - d1y * e2x) + (e1x * d2y - e1y * d2x))
            out[ia, 0] += hx
            out[ia, 1] += hy
            out[ia, 2] += hz
            out[ib, 0] += hx
            out[ib, 1] += hy
            out[ib, 2] += hz
            out[ic, 0] += hx
            out[ic, 1] += hy
            out[ic, 2] += hz


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
def _prepare_blocks(m, c, dt, q, w, mg):
    """The true spring part of the system matrix for the finest-level smoother: per spring
    the block alpha u u^T + beta I (alpha = dt c + dt^2 (a - b), beta = dt^2 b), per
    particle the diagonal block m I + sum of its springs' blocks (+ attachments, grab),
    and its inverse."""
    n = q.shape[0]
    # per particle, its springs' coefficients packed in entry order (the smoother and the
    # residual then stream through them instead of gathering per spring)
    for i in range(n):
        b00 = b11 = b22 = m.particle_mass[i]
        b01 = b02 = b12 = 0.0
        for e in range(mg.vertex_spring_ptr[i], mg.vertex_spring_ptr[i + 1]):
            s = mg.vertex_spring[e]
            ux, uy, uz = w.spring_u[s, 0], w.spring_u[s, 1], w.spring_u[s, 2]
            alpha = dt * m.spring_damping[s] + dt * dt * (w.spring_a[s] - w.spring_b[s])
            beta = dt * dt * w.spring_b[s]
            mg.entry_coef[e, 0], mg.entry_coef[e, 1], mg.entry_coef[e, 2] = ux, uy, uz
            mg.entry_coef[e, 3], mg.entry_coef[e, 4] = alpha, beta
            b00 += alpha * ux * ux + beta
            b11 += alpha * uy * uy + beta
            b22 += alpha * uz * uz + beta
            b01 += alpha * ux * uy
            b02 += alpha * ux * uz
            b12 += alpha * uy * uz
        mg.block[i, 0, 0], mg.block[i, 1, 1], mg.block[i, 2, 2] = b00, b11, b22
        mg.block[i, 0, 1] = mg.block[i, 1, 0] = b01
        mg.block[i, 0, 2] = mg.block[i, 2, 0] = b02
        mg.block[i, 1, 2] = mg.block[i, 2, 1] = b12
    for a in range(m.attachment_particle.shape[0]):
        i = m.attachment_particle[a]
        d = w.scratch[0]
        for k in range(3):
            d[k] = c.attachment_anchor[a, k] - q[i, k]
        length = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        k_a = m.attachment_stiffness[a]
        iso = k_a if length == 0.0 else k_a * max(0.0, 1.0 - m.attachment_rest_length[a] / length)
        alpha = dt * m.attachment_damping[a] + dt * dt * (k_a - iso)
        for r in range(3):
            for k in range(3):
                if length > 0.0:
                    mg.block[i, r, k] += alpha * d[r] * d[k] / (length * length)
            mg.block[i, r, r] += dt * dt * iso
    g = c.grab_particle
    if g >= 0:
        for r in range(3):
            mg.block[g, r, r] += dt * dt * c.grab_stiffness + dt * c.grab_damping
    for i in range(n):
        _invert_3x3(mg.block[i], mg.block_inv[i])


@njit(cache=True)
def _invert_3x3(a, out):
    """out = a^-1 for a (3, 3) by the adjugate (no allocation)."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    inv_det = 1.0 / (a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02)
    out[0, 0] = c00 * inv_det
    out[1, 0] = c01 * inv_det
    out[2, 0] = c02 * inv_det
    out[0, 1] = (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]) * inv_det
    out[1, 1] = (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]) * inv_det
    out[2, 1] = (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]) * inv_det
    out[0, 2] = (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]) * inv_det
    out[1, 2] = (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]) * inv_det
    out[2, 2] = (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) * inv_det


@njit(cache=True, inline="always")
def _entries_sum(mg, x, first, last):
    """Sum over a particle's entries first..last-1 of their spring block
    (alpha u u^T + beta I) times x_j: minus the off-diagonal blocks times x."""
    s0 = s1 = s2 = 0.0
    for e in range(first, last):
        j = mg.vertex_neighbor[e]
        ux, uy, uz = mg.entry_coef[e, 0], mg.entry_coef[e, 1], mg.entry_coef[e, 2]
        beta = mg.entry_coef[e, 4]
        xj0, xj1, xj2 = x[j, 0], x[j, 1], x[j, 2]
        ax = mg.entry_coef[e, 3] * (ux * xj0 + uy * xj1 + uz * xj2)
        s0 += ax * ux + beta * xj0
        s1 += ax * uy + beta * xj1
        s2 += ax * uz + beta * xj2
    return s0, s1, s2


@njit(cache=True, inline="always")
def _offdiagonal_sum(mg, i, x):
    """-sum over particle i's springs of their off-diagonal block times x_j (the blocks
    are -(alpha u u^T + beta I))."""
    return _entries_sum(mg, x, mg.vertex_spring_ptr[i], mg.vertex_spring_ptr[i + 1])


@njit(cache=True, inline="always")
def _first_later_entry(mg, i):
    """Particle i's first entry to a particle j > i (entries are sorted by j: those to
    earlier particles come first)."""
    e, end = mg.vertex_spring_ptr[i], mg.vertex_spring_ptr[i + 1]
    while e < end and mg.vertex_neighbor[e] < i:
        e += 1
    return e


@njit(cache=True, inline="always")
def _solve_row(mg, i, s0, s1, s2):
    """x_i = D_i^-1 s, D_i particle i's diagonal block."""
    d = mg.block_inv[i]
    mg.x[i, 0] = d[0, 0] * s0 + d[0, 1] * s1 + d[0, 2] * s2
    mg.x[i, 1] = d[1, 0] * s0 + d[1, 1] * s1 + d[1, 2] * s2
    mg.x[i, 2] = d[2, 0] * s0 + d[2, 1] * s1 + d[2, 2] * s2


@njit(cache=True)
def _forward_sweep_from_zero(mg, inv_mass, b):
    """x = mg.x[:N] after one forward block Gauss-Seidel sweep from x = 0 for b (N, 3),
    with the true spring blocks; pinned rows 0. Row i reads only its springs to earlier
    particles, as the later x_j are still 0: nothing is cleared first, and half the
    entries are read."""
    for i in range(inv_mass.shape[0]):
        if inv_mass[i] == 0.0:
            mg.x[i, 0] = mg.x[i, 1] = mg.x[i, 2] = 0.0
            continue
        s0, s1, s2 = _entries_sum(mg, mg.x, mg.vertex_spring_ptr[i], _first_later_entry(mg, i))
        _solve_row(mg, i, s0 + b[i, 0], s1 + b[i, 1], s2 + b[i, 2])


@njit(cache=True)
def _backward_sweep(mg, inv_mass, b):
    """One backward block Gauss-Seidel sweep on x = mg.x[:N] in place for b (N, 3), with
    the true spring blocks; pinned rows are left as they are."""
    for i in range(inv_mass.shape[0] - 1, -1, -1):
        if inv_mass[i] == 0.0:
            continue
        s0, s1, s2 = _offdiagonal_sum(mg, i, mg.x)
        _solve_row(mg, i, s0 + b[i, 0], s1 + b[i, 1], s2 + b[i, 2])


@njit(cache=True)
def _precondition(m, mg, w, diag, inv_mass, r, z):
    """z = P^-1 r for r, z (N, 3); pinned rows are 0.

    With ``mg`` built for this model: one V-cycle whose finest level smooths with block
    Gauss-Seidel on the true (anisotropic) spring matrix, forward down and backward up,
    and whose coarse correction is the isotropic Laplacian hierarchy; both halves are
    symmetric, so the cycle is a symmetric operator. Otherwise Jacobi with ``diag`` (N,).
    """
    n = r.shape[0]
    if mg.level_size[0] != n:
        for i in range(n):
            for k in range(3):
                z[i, k] = r[i, k] / diag[i]
        return
    _forward_sweep_from_zero(mg, inv_mass, r)
    # residual of the true spring matrix after the sweep (0 on pinned rows). The sweep
    # started from x = 0, and row i's equation held when x_i was set, with x_j = 0 for
    # every j > i: what is left of r_i - (A x)_i is those springs' blocks times their new
    # x_j. The other half of the entries, and no diagonal block product.
    for i in range(n):
        if inv_mass[i] == 0.0:
            mg.r[i, 0] = mg.r[i, 1] = mg.r[i, 2] = 0.0
            continue
        last = mg.vertex_spring_ptr[i + 1]
        mg.r[i, 0], mg.r[i, 1], mg.r[i, 2] = _entries_sum(mg, mg.x, _first_later_entry(mg, i), last)
    # coarse correction with the Laplacian hierarchy (the dense solve when it is 1 level)
    if mg.level_count > 0:
        restrict(mg, 0, mg.r[:n])
        cycle_from(mg, 1)
        prolong(mg, 0)
    else:
        for i in range(n):
            for k in range(3):
                # the residual is the dense solve's right-hand side; keep the smoothed x
                mg.b[i, k] = mg.r[i, k]
                mg.r[i, k] = mg.x[i, k]
        _coarse_solve(mg)
        for i in range(n):
            for k in range(3):
                mg.x[i, k] += mg.r[i, k]
    for i in range(n):
        if inv_mass[i] == 0.0:
            mg.x[i, 0] = mg.x[i, 1] = mg.x[i, 2] = 0.0
    _backward_sweep(mg, inv_mass, r)
    for i in range(n):
        for k in range(3):
            z[i, k] = mg.x[i, k]


@njit(cache=True)
def _apply_at_start(m, c, w, alpha_m, alpha_c, alpha_k, p, out):
    """``apply_jacobians`` at the step's start w.q0 with the prepared spring and
    pressure data in ``w``: out = alpha_m M p + alpha_c C p + alpha_k K p."""
    apply_jacobians(
        m,
        c,
        w.q0,
        p,
        alpha_m,
        alpha_c,
        alpha_k,
        w.spring_u,
        w.spring_a,
        w.spring_b,
        w.volume_gradient,
        w.body_dpdv,
        w.body_pnet,
        out,
    )


@njit(cache=True)
def step_implicit(m, c, t, dt, q, qd, w, mg, tolerance, max_iterations, bdf2):
    """One backward Euler step, or with ``bdf2`` one BDF2 step (module docstring), from
    w.q0, w.v0 with w.f = f(x0, v0) on entry; ``mg`` is the multigrid preconditioner or an
    empty one (Jacobi). BDF2 reads the previous step's start in w.q_prev, w.v_prev; both
    schemes leave this step's start there for the next. Returns the CG iterations used.

    BDF2 (Choi & Ko 2002): x1 = 4/3 x0 - 1/3 x_-1 + h v1, v1 = 4/3 v0 - 1/3 v_-1 + h M^-1
    f(x1, v1) with h = 2/3 dt; linearised like backward Euler it is the same system with
    h for dt and the right-hand side M (v0 - v_-1) / 3 + h (f0 + K y),
    y = (x0 - x_-1) / 3 + h v0 (backward Euler: h = dt, y = dt v0, no momentum term).
    """
    n = q.shape[0]
    inv_mass = m.particle_inv_mass
    h = dt * (2.0 / 3.0) if bdf2 else dt
    # y, the linearisation's position change before dv, in w.qs
    for i in range(n):
        for k in range(3):
            if bdf2:
                w.qs[i, k] = (w.q0[i, k] - w.q_prev[i, k]) / 3.0 + h * w.v0[i, k]
            else:
                w.qs[i, k] = h * w.v0[i, k]
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
    if mg.level_size[0] == n:
        _prepare_blocks(m, c, h, w.q0, w, mg)
    # K y for the right-hand side, kept in w.acc_v
    _apply_at_start(m, c, w, 0.0, 0.0, 1.0, w.qs, w.acc_v)
    if mg.level_size[0] != n:
        # Jacobi preconditioner: mass + h (damping) + h^2 (stiffness) on the diagonal
        for i in range(n):
            w.cg_diag[i] = m.particle_mass[i]
        for s in range(m.spring_indices.shape[0]):
            d = h * m.spring_damping[s] + h * h * w.spring_a[s]
            w.cg_diag[m.spring_indices[s, 0]] += d
            w.cg_diag[m.spring_indices[s, 1]] += d
    rhs_norm = 0.0
    for i in range(n):
        for k in range(3):
            b = 0.0
            if inv_mass[i] > 0.0:
                b = h * (w.f[i, k] + w.acc_v[i, k])
                if bdf2:
                    b += m.particle_mass[i] * (w.v0[i, k] - w.v_prev[i, k]) / 3.0
            w.cg_r[i, k] = b
            rhs_norm += b * b
            if inv_mass[i] == 0.0:
                w.cg_x[i, k] = 0.0
    rhs_norm = np.sqrt(rhs_norm)
    # warm start from the previous step's dv (still in w.cg_x): in smooth motion it is
    # close, and CG then starts from residual b - A dv_prev; kept only if that is smaller
    _apply_at_start(m, c, w, 1.0, -h, -h * h, w.cg_x, w.cg_ap)
    warm = 0.0
    for i in range(n):
        if inv_mass[i] > 0.0:
            for k in range(3):
                d = w.cg_r[i, k] - w.cg_ap[i, k]
                warm += d * d
    if np.isfinite(warm) and warm < rhs_norm * rhs_norm:
        for i in range(n):
            if inv_mass[i] > 0.0:
                for k in range(3):
                    w.cg_r[i, k] -= w.cg_ap[i, k]
    else:
        w.cg_x[:] = 0.0
        warm = rhs_norm * rhs_norm
    iterations = 0
    if np.sqrt(warm) > tolerance * rhs_norm:
        _precondition(m, mg, w, w.cg_diag, inv_mass, w.cg_r, w.cg_z)
        for i in range(n):
            for k in range(3):
                w.cg_p[i, k] = w.cg_z[i, k]
        rz = _dot_free(w.cg_r, w.cg_z, inv_mass)
        while iterations < max_iterations:
            _apply_at_start(m, c, w, 1.0, -h, -h * h, w.cg_p, w.cg_ap)
            pap = _dot_free(w.cg_p, w.cg_ap, inv_mass)
            if pap == 0.0 or not np.isfinite(pap):
                break  # breakdown: keep the last iterate
            # pap < 0 (the pressure Hessian made the matrix indefinite at a large step)
            # is no breakdown: CG's recurrences still hold for a symmetric matrix
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
            _precondition(m, mg, w, w.cg_diag, inv_mass, w.cg_r, w.cg_z)
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
            if bdf2 and inv_mass[i] > 0.0:
                q[i, k] = (4.0 * w.q0[i, k] - w.q_prev[i, k]) / 3.0 + h * v
            else:
                q[i, k] = w.q0[i, k] + dt * v  # pinned particles keep their set velocity
            w.q_prev[i, k] = w.q0[i, k]
            w.v_prev[i, k] = w.v0[i, k]
    return iterations
