"""Particles against rigid colliders (paper, section 3.5, with continuous detection).

After each step, a particle found in a collider is put back on its surface (for a thin
solid collider, at the point where its path of this step entered it, so fast particles
cannot pass through), and its velocity relative to the collider's surface is split into
normal and tangential parts: the normal part, if approaching, is reflected and scaled by
the restitution; the tangential part is scaled by (1 - friction). The impulse this takes
is added, with opposite sign, to the impulse the collider receives.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _local(rot, center, c, x, i):
    """Coordinates of world point x[i] in collider c's frame: rot^T (x - center)."""
    dx, dy, dz = x[i, 0] - center[c, 0], x[i, 1] - center[c, 1], x[i, 2] - center[c, 2]
    return (
        rot[c, 0, 0] * dx + rot[c, 1, 0] * dy + rot[c, 2, 0] * dz,
        rot[c, 0, 1] * dx + rot[c, 1, 1] * dy + rot[c, 2, 1] * dz,
        rot[c, 0, 2] * dx + rot[c, 1, 2] * dy + rot[c, 2, 2] * dz,
    )


@njit(cache=True)
def _world(rot, center, c, lx, ly, lz):
    return (
        center[c, 0] + rot[c, 0, 0] * lx + rot[c, 0, 1] * ly + rot[c, 0, 2] * lz,
        center[c, 1] + rot[c, 1, 0] * lx + rot[c, 1, 1] * ly + rot[c, 1, 2] * lz,
        center[c, 2] + rot[c, 2, 0] * lx + rot[c, 2, 1] * ly + rot[c, 2, 2] * lz,
    )


@njit(cache=True)
def _slab(l0, l1, h, s_in, s_out, axis, side, k):
    """Clip the segment parameter range [s_in, s_out] by the slab |l| <= h of axis k,
    keeping the axis and side (-1 or +1) of the latest entry. An empty range has
    s_in > s_out."""
    d = l1 - l0
    if d == 0.0:
        if abs(l0) > h:
            return np.inf, -np.inf, axis, side
        return s_in, s_out, axis, side
    a = (-h - l0) / d
    b = (h - l0) / d
    enter_side = -1.0
    if a > b:
        a, b = b, a
        enter_side = 1.0
    if a > s_in:
        s_in, axis, side = a, k, enter_side
    return s_in, min(s_out, b), axis, side


@njit(cache=True)
def _clamp(value, h):
    """Clamp a local coordinate into [-h, h]; the second value is the inward normal part."""
    if value > h:
        return h, -1.0
    if value < -h:
        return -h, 1.0
    return value, 0.0


@njit(cache=True, inline="always")
def collider_contact(kind, center, rot, size, c, x, x0, i, out_x, out_n):
    """Whether particle i at x[i] violates collider c; if so its corrected position and
    the surface normal pointing to the allowed side are written to out_x, out_n (3,).

    center (C, 3), rot (C, 3, 3), size (C, 3): the colliders; x, x0 (N, 3): positions now
    and at the start of the step (continuous detection for solid spheres and boxes).
    Whole arrays and indices, not row views: a view per particle and collider costs
    reference counting that took longer than the test itself. Allocates nothing.
    """
    if kind == 0:  # plane: local +y is the normal
        nx, ny, nz = rot[c, 0, 1], rot[c, 1, 1], rot[c, 2, 1]
        d = (
            (x[i, 0] - center[c, 0]) * nx
            + (x[i, 1] - center[c, 1]) * ny
            + (x[i, 2] - center[c, 2]) * nz
        )
        if d >= 0.0:
            return False
        out_x[0], out_x[1], out_x[2] = x[i, 0] - d * nx, x[i, 1] - d * ny, x[i, 2] - d * nz
        out_n[0], out_n[1], out_n[2] = nx, ny, nz
        return True
    if kind == 1:  # container: clamp into the box
        lx, ly, lz = _local(rot, center, c, x, i)
        lx, mx = _clamp(lx, size[c, 0])
        ly, my = _clamp(ly, size[c, 1])
        lz, mz = _clamp(lz, size[c, 2])
        if mx == 0.0 and my == 0.0 and mz == 0.0:
            return False
        out_x[0], out_x[1], out_x[2] = _world(rot, center, c, lx, ly, lz)
        norm = np.sqrt(mx * mx + my * my + mz * mz)
        for k in range(3):
            out_n[k] = (rot[c, k, 0] * mx + rot[c, k, 1] * my + rot[c, k, 2] * mz) / norm
        return True
    if kind == 2:  # solid sphere
        r = size[c, 0]
        dx, dy, dz = x[i, 0] - center[c, 0], x[i, 1] - center[c, 1], x[i, 2] - center[c, 2]
        d2 = dx * dx + dy * dy + dz * dz
        # did the step's path enter the sphere? solve |x0 + s (x - x0) - c| = r, s in [0, 1]
        ex, ey, ez = x0[i, 0] - center[c, 0], x0[i, 1] - center[c, 1], x0[i, 2] - center[c, 2]
        ux, uy, uz = x[i, 0] - x0[i, 0], x[i, 1] - x0[i, 1], x[i, 2] - x0[i, 2]
        a = ux * ux + uy * uy + uz * uz
        b = ex * ux + ey * uy + ez * uz
        cc = ex * ex + ey * ey + ez * ez - r * r
        if a > 0.0 and cc >= 0.0 and b < 0.0 and b * b - a * cc >= 0.0:
            s = (-b - np.sqrt(b * b - a * cc)) / a
            if s <= 1.0:  # entry point: cut the displacement there
                for k in range(3):
                    out_x[k] = x0[i, k] + s * (x[i, k] - x0[i, k])
                    out_n[k] = (out_x[k] - center[c, k]) / r
                return True
        if d2 >= r * r:
            return False
        # started inside (the sphere moved onto it): out along the radius
        d = np.sqrt(d2)
        if d == 0.0:
            dx, dy, dz, d = 0.0, 1.0, 0.0, 1.0
        out_n[0], out_n[1], out_n[2] = dx / d, dy / d, dz / d
        for k in range(3):
            out_x[k] = center[c, k] + r * out_n[k]
        return True
    # solid box: path entry first (a fast particle may end beyond the middle, or beyond
    # the box), else the nearest face for a particle that started inside
    lx, ly, lz = _local(rot, center, c, x, i)
    hx, hy, hz = size[c, 0], size[c, 1], size[c, 2]
    ax, ay, az = _local(rot, center, c, x0, i)
    s_in, s_out, axis, side = -np.inf, np.inf, -1, 0.0
    s_in, s_out, axis, side = _slab(ax, lx, hx, s_in, s_out, axis, side, 0)
    s_in, s_out, axis, side = _slab(ay, ly, hy, s_in, s_out, axis, side, 1)
    s_in, s_out, axis, side = _slab(az, lz, hz, s_in, s_out, axis, side, 2)
    if axis >= 0 and 0.0 <= s_in <= s_out and s_in <= 1.0:
        lx, ly, lz = ax + s_in * (lx - ax), ay + s_in * (ly - ay), az + s_in * (lz - az)
        if axis == 0:
            lx = side * hx
        elif axis == 1:
            ly = side * hy
        else:
            lz = side * hz
    elif abs(lx) < hx and abs(ly) < hy and abs(lz) < hz:
        dx, dy, dz = hx - abs(lx), hy - abs(ly), hz - abs(lz)
        if dx <= dy and dx <= dz:
            axis, side = 0, (1.0 if lx >= 0.0 else -1.0)
            lx = side * hx
        elif dy <= dz:
            axis, side = 1, (1.0 if ly >= 0.0 else -1.0)
            ly = side * hy
        else:
            axis, side = 2, (1.0 if lz >= 0.0 else -1.0)
            lz = side * hz
    else:
        return False
    out_x[0], out_x[1], out_x[2] = _world(rot, center, c, lx, ly, lz)
    for k in range(3):
        out_n[k] = rot[c, k, axis] * side
    return True


@njit(cache=True)
def eval_collider_contacts(
    particle_mass,
    particle_inv_mass,
    collider_kind,
    collider_size,
    collider_restitution,
    collider_friction,
    collider_q,
    collider_rot,
    collider_v,
    collider_w,
    q_start,
    q,
    qd,
    collider_impulse,
    xp,
    n,
):
    """Resolve every particle against every collider (see module docstring).

    q_start (N, 3) positions at the start of the step; q, qd (N, 3) updated in place;
    collider_impulse (C, 3) [N s] accumulates the impulse each collider receives;
    xp, n (3,) are scratch.
    """
    for i in range(q.shape[0]):
        if particle_inv_mass[i] == 0.0:
            continue
        for c in range(collider_kind.shape[0]):
            if not collider_contact(
                collider_kind[c],
                collider_q,
                collider_rot,
                collider_size,
                c,
                q,
                q_start,
                i,
                xp,
                n,
            ):
                continue
            # velocity of the collider's surface at the contact point
            rx = xp[0] - collider_q[c, 0]
            ry = xp[1] - collider_q[c, 1]
            rz = xp[2] - collider_q[c, 2]
            wx, wy, wz = collider_w[c, 0], collider_w[c, 1], collider_w[c, 2]
            ux = collider_v[c, 0] + wy * rz - wz * ry
            uy = collider_v[c, 1] + wz * rx - wx * rz
            uz = collider_v[c, 2] + wx * ry - wy * rx
            vx, vy, vz = qd[i, 0] - ux, qd[i, 1] - uy, qd[i, 2] - uz
            vn = vx * n[0] + vy * n[1] + vz * n[2]
            q[i, 0], q[i, 1], q[i, 2] = xp[0], xp[1], xp[2]
            if vn >= 0.0:
                continue  # already separating: only the position is corrected
            tx, ty, tz = vx - vn * n[0], vy - vn * n[1], vz - vn * n[2]
            e = collider_restitution[c]
            keep = 1.0 - collider_friction[c]
            nvx = ux - e * vn * n[0] + keep * tx
            nvy = uy - e * vn * n[1] + keep * ty
            nvz = uz - e * vn * n[2] + keep * tz
            m = particle_mass[i]
            collider_impulse[c, 0] -= m * (nvx - qd[i, 0])
            collider_impulse[c, 1] -= m * (nvy - qd[i, 1])
            collider_impulse[c, 2] -= m * (nvz - qd[i, 2])
            qd[i, 0], qd[i, 1], qd[i, 2] = nvx, nvy, nvz
