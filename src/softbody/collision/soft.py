"""Soft body against soft body.

Two modes, chosen per model:

* ``bounding`` (the paper, section 3.5): bodies whose bounding boxes overlap are tested
  vertex by vertex against the other body's implicit bounding object (ellipsoid, sphere or
  box, fitted each step as in ``softbody.volume``). A vertex inside is moved out to the
  object's surface; its velocity relative to the other body's mean velocity is reflected
  and scaled (restitution, friction), and the opposite impulse goes to the other body,
  spread over its particles by mass, so momentum is conserved. A body's mean velocity and
  mass count its pinned particles too: their share of the impulse goes to whatever holds
  them, so a body pinned all over is an immovable obstacle, and one free particle on a
  pinned body does not take a whole body's impulse. All bodies are tested against the
  objects as they were at the start of the pass (order independent).
* ``surface`` (beyond the paper): vertices are tested against the other body's actual
  triangles, found through a spatial hash of triangle bounding boxes. A vertex behind the
  nearest triangle (within ``contact_margin``) is separated from it by a mass-weighted
  correction shared with the triangle's corners by barycentric weight, and the same
  weighting applies the normal (restitution) and tangential (friction) impulses: momentum
  is conserved and the bodies touch where their surfaces touch.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def eval_body_motion(
    particle_mass,
    body_particle_range,
    q,
    qd,
    body_lo,
    body_hi,
    body_velocity,
    body_mass,
):
    """Bounds (B, 3), mass-weighted velocity (B, 3) and mass (B,) of each body, over all
    its particles (pinned ones with their set velocities)."""
    for b in range(body_particle_range.shape[0]):
        # sums and bounds in registers, written once per body
        lx = ly = lz = np.inf
        hx = hy = hz = -np.inf
        px = py = pz = mass = 0.0
        for i in range(body_particle_range[b, 0], body_particle_range[b, 1]):
            x, y, z = q[i, 0], q[i, 1], q[i, 2]
            lx, ly, lz = min(lx, x), min(ly, y), min(lz, z)
            hx, hy, hz = max(hx, x), max(hy, y), max(hz, z)
            m = particle_mass[i]
            mass += m
            px += m * qd[i, 0]
            py += m * qd[i, 1]
            pz += m * qd[i, 2]
        body_lo[b, 0], body_lo[b, 1], body_lo[b, 2] = lx, ly, lz
        body_hi[b, 0], body_hi[b, 1], body_hi[b, 2] = hx, hy, hz
        body_mass[b] = mass
        if mass > 0.0:
            px, py, pz = px / mass, py / mass, pz / mass
        body_velocity[b, 0], body_velocity[b, 1], body_velocity[b, 2] = px, py, pz


@njit(cache=True)
def _fit_bounding_object(q, begin, end, shape, b, lo, hi, center, axes):
    """Centre and semi-axes (rows b of center, axes (B, 3)) of body b's bounding box (1),
    sphere (2) or ellipsoid (3), from its bounds lo, hi (B, 3)."""
    for k in range(3):
        center[b, k] = 0.5 * (lo[b, k] + hi[b, k])
        axes[b, k] = max(0.5 * (hi[b, k] - lo[b, k]), 1e-12)
    if shape == 1:
        return
    cx, cy, cz = center[b, 0], center[b, 1], center[b, 2]
    # scaled distance: by the box's half extents for the ellipsoid, plain for the sphere
    wx, wy, wz = 1.0, 1.0, 1.0
    if shape == 3:
        wx, wy, wz = 1.0 / axes[b, 0], 1.0 / axes[b, 1], 1.0 / axes[b, 2]
    s2 = 0.0
    for i in range(begin, end):
        dx, dy, dz = (q[i, 0] - cx) * wx, (q[i, 1] - cy) * wy, (q[i, 2] - cz) * wz
        s2 = max(s2, dx * dx + dy * dy + dz * dz)
    s = np.sqrt(s2)
    for k in range(3):
        axes[b, k] = s if shape == 2 else s * axes[b, k]


@njit(cache=True, inline="always")
def _respond(v, u, n, e, keep):
    """New velocity (3-tuple) for velocity v against normal n, relative to velocity u
    (all 3-tuples of numbers: passing array views here cost far more than the test)."""
    vx, vy, vz = v[0] - u[0], v[1] - u[1], v[2] - u[2]
    vn = vx * n[0] + vy * n[1] + vz * n[2]
    if vn >= 0.0:
        return v[0], v[1], v[2]
    tx, ty, tz = vx - vn * n[0], vy - vn * n[1], vz - vn * n[2]
    return (
        u[0] - e * vn * n[0] + keep * tx,
        u[1] - e * vn * n[1] + keep * ty,
        u[2] - e * vn * n[2] + keep * tz,
    )


@njit(cache=True)
def eval_soft_contacts_bounding(
    particle_mass,
    particle_inv_mass,
    body_particle_range,
    body_contact_shape,
    restitution,
    friction,
    q,
    qd,
    body_lo,
    body_hi,
    body_velocity,
    body_mass,
    body_center,
    body_axes,
    body_dv,
):
    """The paper's soft-soft collisions against bounding objects (module docstring).

    body_* arrays are scratch (B, 3) / (B,).
    """
    bodies = body_particle_range.shape[0]
    eval_body_motion(
        particle_mass,
        body_particle_range,
        q,
        qd,
        body_lo,
        body_hi,
        body_velocity,
        body_mass,
    )
    for b in range(bodies):
        _fit_bounding_object(
            q,
            body_particle_range[b, 0],
            body_particle_range[b, 1],
            body_contact_shape[b],
            b,
            body_lo,
            body_hi,
            body_center,
            body_axes,
        )
        for k in range(3):
            body_dv[b, k] = 0.0
    keep = 1.0 - friction
    for a in range(bodies):
        for b in range(bodies):
            if a == b or body_mass[b] == 0.0:
                continue  # a body of massless particles: nothing to test against
            overlap = True
            for k in range(3):
                if body_hi[a, k] < body_lo[b, k] or body_hi[b, k] < body_lo[a, k]:
                    overlap = False
            if not overlap:
                continue
            # the other body's object and velocity as numbers (read once per pair)
            cx, cy, cz = body_center[b, 0], body_center[b, 1], body_center[b, 2]
            ax, ay, az = body_axes[b, 0], body_axes[b, 1], body_axes[b, 2]
            iax, iay, iaz = 1.0 / (ax * ax), 1.0 / (ay * ay), 1.0 / (az * az)
            u = (body_velocity[b, 0], body_velocity[b, 1], body_velocity[b, 2])
            share = 1.0 / body_mass[b]
            shape = body_contact_shape[b]
            for i in range(body_particle_range[a, 0], body_particle_range[a, 1]):
                if particle_inv_mass[i] == 0.0:
                    continue
                dx, dy, dz = q[i, 0] - cx, q[i, 1] - cy, q[i, 2] - cz
                if shape == 1:
                    px, py, pz = ax - abs(dx), ay - abs(dy), az - abs(dz)
                    if px <= 0.0 or py <= 0.0 or pz <= 0.0:
                        continue
                    nx = ny = nz = 0.0
                    if px <= py and px <= pz:
                        nx = 1.0 if dx >= 0.0 else -1.0
                        q[i, 0] = cx + nx * ax
                    elif py <= pz:
                        ny = 1.0 if dy >= 0.0 else -1.0
                        q[i, 1] = cy + ny * ay
                    else:
                        nz = 1.0 if dz >= 0.0 else -1.0
                        q[i, 2] = cz + nz * az
                else:
                    f = dx * dx * iax + dy * dy * iay + dz * dz * iaz
                    if f >= 1.0:
                        continue
                    if f == 0.0:
                        dx, dy, dz, f = 0.0, ay, 0.0, 1.0
                    s = 1.0 / np.sqrt(f)  # move along the ray from the centre to F = 1
                    q[i, 0], q[i, 1], q[i, 2] = cx + s * dx, cy + s * dy, cz + s * dz
                    gx, gy, gz = s * dx * iax, s * dy * iay, s * dz * iaz
                    g = np.sqrt(gx * gx + gy * gy + gz * gz)
                    nx, ny, nz = gx / g, gy / g, gz / g
                v = (qd[i, 0], qd[i, 1], qd[i, 2])
                nvx, nvy, nvz = _respond(v, u, (nx, ny, nz), restitution, keep)
                m = particle_mass[i] * share
                body_dv[b, 0] -= m * (nvx - v[0])
                body_dv[b, 1] -= m * (nvy - v[1])
                body_dv[b, 2] -= m * (nvz - v[2])
                qd[i, 0], qd[i, 1], qd[i, 2] = nvx, nvy, nvz
    for b in range(bodies):
        dvx, dvy, dvz = body_dv[b, 0], body_dv[b, 1], body_dv[b, 2]
        if dvx == 0.0 and dvy == 0.0 and dvz == 0.0:
            continue  # nothing hit this body
        for i in range(body_particle_range[b, 0], body_particle_range[b, 1]):
            if particle_inv_mass[i] > 0.0:
                qd[i, 0] += dvx
                qd[i, 1] += dvy
                qd[i, 2] += dvz


@njit(cache=True)
def closest_point_on_triangle(px, py, pz, a, b, c):
    """Closest point to p on triangle (a, b, c) and its barycentric weights (Ericson,
    Real-Time Collision Detection, 5.1.5). Returns (x, y, z, wa, wb, wc)."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = px - a[0], py - a[1], pz - a[2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return a[0], a[1], a[2], 1.0, 0.0, 0.0
    bpx, bpy, bpz = px - b[0], py - b[1], pz - b[2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return b[0], b[1], b[2], 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a[0] + v * abx, a[1] + v * aby, a[2] + v * abz, 1.0 - v, v, 0.0
    cpx, cpy, cpz = px - c[0], py - c[1], pz - c[2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return c[0], c[1], c[2], 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a[0] + w * acx, a[1] + w * acy, a[2] + w * acz, 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return (
            b[0] + w * (c[0] - b[0]),
            b[1] + w * (c[1] - b[1]),
            b[2] + w * (c[2] - b[2]),
            0.0,
            1.0 - w,
            w,
        )
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return (
        a[0] + abx * v + acx * w,
        a[1] + aby * v + acy * w,
        a[2] + abz * v + acz * w,
        1.0 - v - w,
        v,
        w,
    )


@njit(cache=True)
def _cell_hash(ix, iy, iz, table_size):
    h = (ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791)
    return h % table_size  # Python-style modulo: non-negative


@njit(cache=True)
def _cell_range(a, b, c, margin, inv):
    """First and last grid cell covered by [min(a, b, c) - margin, max(a, b, c) + margin]."""
    lo = np.int64(np.floor((min(a, b, c) - margin) * inv))
    hi = np.int64(np.floor((max(a, b, c) + margin) * inv))
    return lo, hi


@njit(cache=True)
def build_triangle_hash(q, tri_indices, cell_size, margin, hash_start, hash_count, hash_entries):
    """Spatial hash of triangle boxes (grown by ``margin`` [m]) on a grid of ``cell_size``.

    hash_start (H + 1,), hash_count (H,) and hash_entries (E,) are scratch; returns the
    number of entries needed (if larger than len(hash_entries), nothing was stored and
    the caller must grow the array and call again).
    """
    table = hash_count.shape[0]
    hash_count[:] = 0
    inv = 1.0 / cell_size
    total = 0
    for pass_ in range(2):
        if pass_ == 1:
            if total > hash_entries.shape[0]:
                return total
            hash_start[0] = 0
            for h in range(table):
                hash_start[h + 1] = hash_start[h] + hash_count[h]
                hash_count[h] = 0
        for t in range(tri_indices.shape[0]):
            i, j, k = tri_indices[t, 0], tri_indices[t, 1], tri_indices[t, 2]
            x0, x1 = _cell_range(q[i, 0], q[j, 0], q[k, 0], margin, inv)
            y0, y1 = _cell_range(q[i, 1], q[j, 1], q[k, 1], margin, inv)
            z0, z1 = _cell_range(q[i, 2], q[j, 2], q[k, 2], margin, inv)
            for ix in range(x0, x1 + 1):
                for iy in range(y0, y1 + 1):
                    for iz in range(z0, z1 + 1):
                        h = _cell_hash(ix, iy, iz, table)
                        if pass_ == 0:
                            hash_count[h] += 1
                            total += 1
                        else:
                            hash_entries[hash_start[h] + hash_count[h]] = t
                            hash_count[h] += 1
    return total


@njit(cache=True)
def eval_soft_contacts_surface(
    particle_mass,
    particle_inv_mass,
    particle_body,
    body_particle_range,
    tri_indices,
    tri_body,
    restitution,
    friction,
    cell_size,
    margin,
    q,
    qd,
    body_lo,
    body_hi,
    body_velocity,
    body_mass,
    hash_start,
    hash_count,
    hash_entries,
):
    """Vertex-triangle contacts between different bodies (module docstring).

    Returns 0, or the hash capacity needed when ``hash_entries`` was too small (nothing
    was resolved then).
    """
    bodies = body_particle_range.shape[0]
    eval_body_motion(
        particle_mass,
        body_particle_range,
        q,
        qd,
        body_lo,
        body_hi,
        body_velocity,
        body_mass,
    )
    any_overlap = False
    for a in range(bodies):
        for b in range(a + 1, bodies):
            ok = True
            for k in range(3):
                if body_hi[a, k] + margin < body_lo[b, k] or body_hi[b, k] + margin < body_lo[a, k]:
                    ok = False
            any_overlap = any_overlap or ok
    if not any_overlap:
        return 0
    needed = build_triangle_hash(
        q, tri_indices, cell_size, margin, hash_start, hash_count, hash_entries
    )
    if needed > hash_entries.shape[0]:
        return needed
    table = hash_count.shape[0]
    inv = 1.0 / cell_size
    keep = 1.0 - friction
    for a in range(bodies):
        for i in range(body_particle_range[a, 0], body_particle_range[a, 1]):
            px, py, pz = q[i, 0], q[i, 1], q[i, 2]
            h = _cell_hash(
                np.int64(np.floor(px * inv)),
                np.int64(np.floor(py * inv)),
                np.int64(np.floor(pz * inv)),
                table,
            )
            best, best_t = margin * margin, -1
            bx = by = bz = wa = wb = wc = 0.0
            for e in range(hash_start[h], hash_start[h + 1]):
                t = hash_entries[e]
                b = tri_body[t]
                if b == a:
                    continue
                inside_box = (
                    body_lo[b, 0] - margin <= px <= body_hi[b, 0] + margin
                    and body_lo[b, 1] - margin <= py <= body_hi[b, 1] + margin
                    and body_lo[b, 2] - margin <= pz <= body_hi[b, 2] + margin
                )
                if not inside_box:
                    continue
                cx, cy, cz, u0, u1, u2 = closest_point_on_triangle(
                    px, py, pz, q[tri_indices[t, 0]], q[tri_indices[t, 1]], q[tri_indices[t, 2]]
                )
                d2 = (px - cx) ** 2 + (py - cy) ** 2 + (pz - cz) ** 2
                if d2 < best:
                    best, best_t = d2, t
                    bx, by, bz, wa, wb, wc = cx, cy, cz, u0, u1, u2
            if best_t < 0:
                continue
            i0, i1, i2 = tri_indices[best_t, 0], tri_indices[best_t, 1], tri_indices[best_t, 2]
            ux, uy, uz = q[i1, 0] - q[i0, 0], q[i1, 1] - q[i0, 1], q[i1, 2] - q[i0, 2]
            vx, vy, vz = q[i2, 0] - q[i0, 0], q[i2, 1] - q[i0, 1], q[i2, 2] - q[i0, 2]
            nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
            nn = np.sqrt(nx * nx + ny * ny + nz * nz)
            if nn == 0.0:
                continue
            nx, ny, nz = nx / nn, ny / nn, nz / nn
            depth = (px - bx) * nx + (py - by) * ny + (pz - bz) * nz
            if depth >= 0.0:
                continue  # outside the other body
            w0, w1, w2 = (particle_inv_mass[i0], particle_inv_mass[i1], particle_inv_mass[i2])
            wp = particle_inv_mass[i]
            weight = wp + wa * wa * w0 + wb * wb * w1 + wc * wc * w2
            if weight == 0.0:
                continue
            # positions: separate along the triangle normal, shared by inverse mass
            lam = -depth / weight
            q[i, 0] += lam * wp * nx
            q[i, 1] += lam * wp * ny
            q[i, 2] += lam * wp * nz
            for idx, wk, bk in ((i0, w0, wa), (i1, w1, wb), (i2, w2, wc)):
                q[idx, 0] -= lam * wk * bk * nx
                q[idx, 1] -= lam * wk * bk * ny
                q[idx, 2] -= lam * wk * bk * nz
            # velocities: normal impulse (restitution) and tangential (friction)
            rvx = qd[i, 0] - (wa * qd[i0, 0] + wb * qd[i1, 0] + wc * qd[i2, 0])
            rvy = qd[i, 1] - (wa * qd[i0, 1] + wb * qd[i1, 1] + wc * qd[i2, 1])
            rvz = qd[i, 2] - (wa * qd[i0, 2] + wb * qd[i1, 2] + wc * qd[i2, 2])
            vn = rvx * nx + rvy * ny + rvz * nz
            if vn >= 0.0:
                continue
            tx, ty, tz = rvx - vn * nx, rvy - vn * ny, rvz - vn * nz
            jn = -(1.0 + restitution) * vn / weight
            jt = -(1.0 - keep) / weight
            jx, jy, jz = jn * nx + jt * tx, jn * ny + jt * ty, jn * nz + jt * tz
            qd[i, 0] += wp * jx
            qd[i, 1] += wp * jy
            qd[i, 2] += wp * jz
            for idx, wk, bk in ((i0, w0, wa), (i1, w1, wb), (i2, w2, wc)):
                qd[idx, 0] -= wk * bk * jx
                qd[idx, 1] -= wk * bk * jy
                qd[idx, 2] -= wk * bk * jz
    return 0
