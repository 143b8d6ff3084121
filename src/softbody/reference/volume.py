"""Body volumes by each method (``core/terms/volume.hpp``).

Exact (method 0), by the divergence theorem over the body's outward-wound faces t with
corners a_t, b_t, c_t and n_t = (b_t - a_t) x (c_t - a_t) (twice the area times the unit
normal):

    V = 1/6 sum_t n_t . (a_t - r)                                         [m^3]
    dV/dx_i = 1/6 sum_{t at i} n_t                                         [m^2]

r, the body's first particle, only keeps round-off of the body's size far from the origin
(the sum does not depend on r for a closed surface). The paper's bounding objects from the
axis-aligned bounds lo, hi of the body's particles, with half sizes h = (hi - lo) / 2 and
centre c = lo + h:

    box (1)        V = 8 h_x h_y h_z
    sphere (2)     V = 4/3 pi R^3,   R = max_i |x_i - c|
    ellipsoid (3)  V = 4/3 pi s^3 h_x h_y h_z,  s = max_i |(x_i - c) / h|  (per component)

(the ellipsoid's flat directions get the floor h >= 1e-12 max(h)). Monte Carlo (4): S
vertical lines through points lo + w (s_x, ?, s_z) of the xz rectangle (w = hi - lo, the
model's seeded samples s in [0, 1)^2); each line's inside length is the sum over the
faces it crosses of +y where it leaves (n_y > 0) and -y where it enters, so

    V = w_x w_z / S sum_lines sum_crossed sign(n_y) (y - y0),  y0 = (lo_y + hi_y) / 2.

Whatever a body's method, the pressure force acts through the exact dV/dx.
"""

from __future__ import annotations

import numpy as np

from softbody.sim.model import Model

EXACT, BOUNDING_BOX, BOUNDING_SPHERE, BOUNDING_ELLIPSOID, MONTE_CARLO = range(5)


def face_normals(q: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """n_t = (b - a) x (c - a) of faces tri (T, 3) at q (N, 3) [m^2], shape (T, 3)."""
    a = q[tri[:, 0]]
    return np.cross(q[tri[:, 1]] - a, q[tri[:, 2]] - a)


def exact(q: np.ndarray, tri: np.ndarray, reference: np.ndarray) -> float:
    """Exact volume [m^3] 1/6 sum_t n_t . (a_t - r) of the faces tri (T, 3) at q (N, 3),
    seen from the point ``reference`` r (3,)."""
    n = face_normals(q, tri)
    return float(np.einsum("tk,tk->", q[tri[:, 0]] - reference, n) / 6.0)


def exact_gradient(q: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """dV/dx [m^2], shape (N, 3): each face's n_t / 6 added to its three corners (zero
    rows for particles on no face)."""
    g = np.zeros_like(q, dtype=np.float64)
    share = face_normals(q, tri) / 6.0
    for corner in range(3):
        np.add.at(g, tri[:, corner], share)
    return g


def bounds(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds (lo, hi) (3,) each [m] of the points x (n, 3)."""
    return x.min(axis=0), x.max(axis=0)


def bounding(x: np.ndarray, method: int) -> float:
    """Volume [m^3] of the bounding box (1), sphere (2) or ellipsoid (3) of the points
    x (n, 3) of one body, as the module docstring defines them."""
    lo, hi = bounds(x)
    h = 0.5 * (hi - lo)
    if method == BOUNDING_BOX:
        return float(8.0 * h[0] * h[1] * h[2])
    c = lo + h
    if method == BOUNDING_SPHERE:
        r2 = max(0.0, float(np.max(np.einsum("ik,ik->i", x - c, x - c))))
        return 4.0 / 3.0 * np.pi * r2**1.5
    if method != BOUNDING_ELLIPSOID:
        raise ValueError(f"not a bounding method: {method}")
    tiny = 1e-12 * max(h[0], h[1], h[2], 1e-300)
    inv = 1.0 / np.maximum(h, tiny)
    s = (x - c) * inv
    s2 = max(0.0, float(np.max(np.einsum("ik,ik->i", s, s))))
    return 4.0 / 3.0 * np.pi * s2**1.5 / (inv[0] * inv[1] * inv[2])


def monte_carlo(
    q: np.ndarray,
    tri: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    samples: np.ndarray,
    *,
    absolute: bool = False,
) -> float:
    """Monte Carlo volume [m^3] of the faces tri (T, 3) at q (N, 3) along vertical lines
    through ``samples`` (S, 2) of the xz rectangle of lo, hi (module docstring); NaN
    without samples. Each line meets a face where its barycentric coordinates
    (1 - l1 - l2, l1, l2) in the xz projection are all >= 0. With ``absolute`` the sum
    of |y - y0| instead (the same units): the scale of the sum's round-off."""
    if len(samples) == 0:
        return float("nan")
    wx, wz = hi[0] - lo[0], hi[2] - lo[2]
    y0 = 0.5 * (lo[1] + hi[1])
    a, b, c = q[tri[:, 0]], q[tri[:, 1]], q[tri[:, 2]]
    det = (b[:, 0] - a[:, 0]) * (c[:, 2] - a[:, 2]) - (c[:, 0] - a[:, 0]) * (b[:, 2] - a[:, 2])
    keep = det != 0.0  # a vertical face (n_y = -det = 0) is crossed by no line
    a, b, c, det = a[keep], b[keep], c[keep], det[keep]
    px = (lo[0] + samples[:, 0] * wx)[None, :]  # (1, S)
    pz = (lo[2] + samples[:, 1] * wz)[None, :]
    ax, az, bx, bz, cx, cz = (v[:, None] for v in (a[:, 0], a[:, 2], b[:, 0], b[:, 2],
                                                    c[:, 0], c[:, 2]))  # fmt: skip
    inv = (1.0 / det)[:, None]
    l1 = ((px - ax) * (cz - az) - (cx - ax) * (pz - az)) * inv  # (T, S)
    l2 = ((bx - ax) * (pz - az) - (px - ax) * (bz - az)) * inv
    xmin, xmax = np.minimum(ax, np.minimum(bx, cx)), np.maximum(ax, np.maximum(bx, cx))
    zmin, zmax = np.minimum(az, np.minimum(bz, cz)), np.maximum(az, np.maximum(bz, cz))
    hit = (px >= xmin) & (px <= xmax) & (pz >= zmin) & (pz <= zmax)
    hit &= (l1 >= 0.0) & (l2 >= 0.0) & (l1 + l2 <= 1.0)
    ay, by, cy = (v[:, 1][:, None] - y0 for v in (a, b, c))
    y = ay + l1 * (by - ay) + l2 * (cy - ay)  # height of the crossing, from y0 [m]
    sign = np.where(det < 0.0, 1.0, -1.0)[:, None]  # leaving (n_y > 0) adds, entering subtracts
    if absolute:
        sign, y = 1.0, np.abs(y)
    total = np.sum(np.where(hit, sign * y, 0.0))
    return float(wx * wz * total / len(samples))


def body_volumes(
    q: np.ndarray,
    tri_indices: np.ndarray,
    body_particle_range: np.ndarray,
    body_tri_range: np.ndarray,
    body_volume_method: np.ndarray,
    body_mc_range: np.ndarray,
    mc_samples: np.ndarray,
) -> np.ndarray:
    """Volume of every body by its own method [m^3], shape (B,), from plain arrays (the
    arguments of ``softbody._core.body_volumes``): particles [p0, p1) and faces [t0, t1)
    of body b by ``body_*_range`` (B, 2), its method (B,) and its rows of ``mc_samples``."""
    out = np.zeros(len(body_particle_range))
    for b, ((p0, p1), (t0, t1)) in enumerate(zip(body_particle_range, body_tri_range, strict=True)):
        method = int(body_volume_method[b])
        tri = tri_indices[t0:t1]
        if method == EXACT:
            out[b] = exact(q, tri, q[p0])
        elif method == MONTE_CARLO:
            s0, s1 = body_mc_range[b]
            lo, hi = bounds(q[p0:p1])
            out[b] = monte_carlo(q, tri, lo, hi, mc_samples[s0:s1])
        else:
            out[b] = bounding(q[p0:p1], method)
    return out


def volumes(model: Model, q: np.ndarray) -> np.ndarray:
    """Volume of every body of ``model`` by its own method at q (N, 3) [m^3], shape (B,)."""
    return body_volumes(
        q,
        model.tri_indices,
        model.body_particle_range,
        model.body_tri_range,
        model.body_volume_method,
        model.body_mc_range,
        model.mc_samples,
    )


def exact_volumes(model: Model, q: np.ndarray) -> np.ndarray:
    """Exact volume of every body whatever its method [m^3], shape (B,)."""
    return np.array(
        [
            exact(q, model.tri_indices[t0:t1], q[p0])
            for (p0, _), (t0, t1) in zip(
                model.body_particle_range, model.body_tri_range, strict=True
            )
        ]
    )


def gradient(model: Model, q: np.ndarray) -> np.ndarray:
    """dV_b/dx_i of every body's exact volume [m^2], shape (N, 3): row i belongs to the
    body of particle i (bodies share no particles), zero for free particles."""
    return exact_gradient(q, model.tri_indices)
