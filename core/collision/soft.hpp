// Soft body against soft body, port of softbody.collision.soft. Two modes:
// - bounding (the paper, section 3.5): bodies whose bounding boxes overlap are tested vertex
//   by vertex against the other body's bounding box, sphere or ellipsoid, fitted each step.
//   A vertex inside moves out to the surface; its velocity relative to the other body's mean
//   velocity is reflected (restitution, friction), and the opposite impulse goes to the other
//   body, spread over its particles by mass, so momentum is conserved.
// - surface (beyond the paper): vertices against the other body's triangles, found through a
//   spatial hash of triangle boxes. A vertex behind the nearest triangle (within the contact
//   margin) is separated from it by a mass-weighted correction shared with the triangle's
//   corners by barycentric weight, and the same weighting applies the normal (restitution)
//   and tangential (friction) impulses: momentum is conserved.
#pragma once

#include "model.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::soft {

/// Bounds (B, 3), mass-weighted velocity (B, 3) and mass (B,) of each body over all its
/// particles (pinned ones too).
inline void body_motion(const Model& m, const double* q, const double* qd,
                        const ContactBuffers& w) {
    const double inf = std::numeric_limits<double>::infinity();
    for (index b = 0; b < m.bodies.count; ++b) {
        double lo[3] = {inf, inf, inf}, hi[3] = {-inf, -inf, -inf};
        double px = 0.0, py = 0.0, pz = 0.0, mass = 0.0;
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1]; ++i) {
            for (int k = 0; k < 3; ++k) {
                lo[k] = std::min(lo[k], q[3 * i + k]);
                hi[k] = std::max(hi[k], q[3 * i + k]);
            }
            const double mi = m.particles.mass[i];
            mass += mi;
            px += mi * qd[3 * i];
            py += mi * qd[3 * i + 1];
            pz += mi * qd[3 * i + 2];
        }
        for (int k = 0; k < 3; ++k) {
            w.body_lo[3 * b + k] = lo[k];
            w.body_hi[3 * b + k] = hi[k];
        }
        w.body_mass[b] = mass;
        if (mass > 0.0) {
            px /= mass;
            py /= mass;
            pz /= mass;
        }
        store(w.body_velocity, b, {px, py, pz});
    }
}

/// Centre and semi-axes of body b's bounding box (shape 1), sphere (2) or ellipsoid (3).
inline void fit(const double* q, index begin, index end, index shape, index b,
                const ContactBuffers& w) {
    for (int k = 0; k < 3; ++k) {
        w.body_center[3 * b + k] = 0.5 * (w.body_lo[3 * b + k] + w.body_hi[3 * b + k]);
        w.body_axes[3 * b + k] =
            std::max(0.5 * (w.body_hi[3 * b + k] - w.body_lo[3 * b + k]), 1e-12);
    }
    if (shape == VolumeMethod::BOUNDING_BOX) return;
    const V3 c = load(w.body_center, b);
    double wx = 1.0, wy = 1.0, wz = 1.0;
    if (shape == VolumeMethod::BOUNDING_ELLIPSOID) {
        wx = 1.0 / w.body_axes[3 * b];
        wy = 1.0 / w.body_axes[3 * b + 1];
        wz = 1.0 / w.body_axes[3 * b + 2];
    }
    double s2 = 0.0;
    for (index i = begin; i < end; ++i) {
        const double dx = (q[3 * i] - c.x) * wx, dy = (q[3 * i + 1] - c.y) * wy,
                     dz = (q[3 * i + 2] - c.z) * wz;
        s2 = std::max(s2, dx * dx + dy * dy + dz * dz);
    }
    const double s = std::sqrt(s2);
    for (int k = 0; k < 3; ++k)
        w.body_axes[3 * b + k] = shape == VolumeMethod::BOUNDING_SPHERE ? s : s * w.body_axes[3 * b + k];
}

/// New velocity for v against normal n, relative to velocity u.
inline V3 respond(V3 v, V3 u, V3 n, double e, double keep) {
    const V3 rel = v - u;
    const double vn = dot(rel, n);
    if (vn >= 0.0) return v;
    const V3 t = rel - vn * n;
    return u - (e * vn) * n + keep * t;
}

/// The bounding-object contacts of the whole model; q, qd (N, 3) change in place.
inline void contacts_bounding(const Model& m, double* q, double* qd, const ContactBuffers& w) {
    const index bodies = m.bodies.count;
    body_motion(m, q, qd, w);
    for (index b = 0; b < bodies; ++b) {
        fit(q, m.bodies.particle_range[2 * b], m.bodies.particle_range[2 * b + 1],
            m.bodies.contact_shape[b], b, w);
        store(w.body_dv, b, {0.0, 0.0, 0.0});
    }
    const double e = m.soft_contacts.restitution;
    const double keep = 1.0 - m.soft_contacts.friction;
    for (index a = 0; a < bodies; ++a)
        for (index b = 0; b < bodies; ++b) {
            if (a == b || w.body_mass[b] == 0.0) continue;
            bool overlap = true;
            for (int k = 0; k < 3; ++k)
                if (w.body_hi[3 * a + k] < w.body_lo[3 * b + k] ||
                    w.body_hi[3 * b + k] < w.body_lo[3 * a + k])
                    overlap = false;
            if (!overlap) continue;
            const V3 c = load(w.body_center, b);
            const double ax = w.body_axes[3 * b], ay = w.body_axes[3 * b + 1],
                         az = w.body_axes[3 * b + 2];
            const double iax = 1.0 / (ax * ax), iay = 1.0 / (ay * ay), iaz = 1.0 / (az * az);
            const V3 u = load(w.body_velocity, b);
            const double share = 1.0 / w.body_mass[b];
            const index shape = m.bodies.contact_shape[b];
            for (index i = m.bodies.particle_range[2 * a]; i < m.bodies.particle_range[2 * a + 1];
                 ++i) {
                if (m.particles.inv_mass[i] == 0.0) continue;
                double dx = q[3 * i] - c.x, dy = q[3 * i + 1] - c.y, dz = q[3 * i + 2] - c.z;
                V3 n{0.0, 0.0, 0.0};
                if (shape == VolumeMethod::BOUNDING_BOX) {
                    const double px = ax - std::fabs(dx), py = ay - std::fabs(dy),
                                 pz = az - std::fabs(dz);
                    if (px <= 0.0 || py <= 0.0 || pz <= 0.0) continue;
                    if (px <= py && px <= pz) {
                        n.x = dx >= 0.0 ? 1.0 : -1.0;
                        q[3 * i] = c.x + n.x * ax;
                    } else if (py <= pz) {
                        n.y = dy >= 0.0 ? 1.0 : -1.0;
                        q[3 * i + 1] = c.y + n.y * ay;
                    } else {
                        n.z = dz >= 0.0 ? 1.0 : -1.0;
                        q[3 * i + 2] = c.z + n.z * az;
                    }
                } else {
                    double f = dx * dx * iax + dy * dy * iay + dz * dz * iaz;
                    if (f >= 1.0) continue;
                    if (f == 0.0) {
                        dx = 0.0;
                        dy = ay;
                        dz = 0.0;
                        f = 1.0;
                    }
                    const double s = 1.0 / std::sqrt(f);  // along the ray from the centre to F = 1
                    store(q, i, {c.x + s * dx, c.y + s * dy, c.z + s * dz});
                    const V3 g{s * dx * iax, s * dy * iay, s * dz * iaz};
                    const double gn = std::sqrt(dot(g, g));
                    n = {g.x / gn, g.y / gn, g.z / gn};
                }
                const V3 v = load(qd, i);
                const V3 nv = respond(v, u, n, e, keep);
                const double mi = m.particles.mass[i] * share;
                add_to(w.body_dv, b, -(mi * (nv - v)));
                store(qd, i, nv);
            }
        }
    for (index b = 0; b < bodies; ++b) {
        const V3 dv = load(w.body_dv, b);
        if (dv.x == 0.0 && dv.y == 0.0 && dv.z == 0.0) continue;  // nothing hit this body
        for (index i = m.bodies.particle_range[2 * b]; i < m.bodies.particle_range[2 * b + 1]; ++i)
            if (m.particles.inv_mass[i] > 0.0) add_to(qd, i, dv);
    }
}

/// Closest point on triangle (a, b, c) to p, with its barycentric weights (wa, wb, wc).
struct TrianglePoint {
    V3 x;
    double wa, wb, wc;
};

/// The closest point to p on triangle (a, b, c) by Voronoi regions (Ericson, Real-Time
/// Collision Detection, 5.1.5).
inline TrianglePoint closest_point_on_triangle(V3 p, V3 a, V3 b, V3 c) {
    const V3 ab = b - a, ac = c - a, ap = p - a;
    const double d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0.0 && d2 <= 0.0) return {a, 1.0, 0.0, 0.0};
    const V3 bp = p - b;
    const double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0.0 && d4 <= d3) return {b, 0.0, 1.0, 0.0};
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {  // on edge ab
        const double v = d1 / (d1 - d3);
        return {a + v * ab, 1.0 - v, v, 0.0};
    }
    const V3 cp = p - c;
    const double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0.0 && d5 <= d6) return {c, 0.0, 0.0, 1.0};
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {  // on edge ac
        const double w = d2 / (d2 - d6);
        return {a + w * ac, 1.0 - w, 0.0, w};
    }
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {  // on edge bc
        const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return {b + w * (c - b), 0.0, 1.0 - w, w};
    }
    const double denom = 1.0 / (va + vb + vc);  // inside the face
    const double v = vb * denom, w = vc * denom;
    return {a + v * ab + w * ac, 1.0 - v - w, v, w};
}

/// floor(v) as a grid cell index. NaN and values outside int64 give INT64_MIN, the x86
/// conversion's "integer indefinite" (a plain cast would be undefined behaviour).
inline index cell_of(double v) {
    const double f = std::floor(v);
    if (!(f >= -9223372036854775808.0 && f < 9223372036854775808.0))
        return std::numeric_limits<index>::min();
    return static_cast<index>(f);
}

/// Bucket in [0, table) of grid cell (ix, iy, iz): the usual three-prime hash with
/// wrap-around int64 products, then a non-negative modulo (Python's; for a power-of-two
/// table, as the buffers make it, the same value as a mask, without a division).
inline index cell_hash(index ix, index iy, index iz, index table) {
    auto times = [](index a, std::uint64_t prime) {
        return static_cast<index>(static_cast<std::uint64_t>(a) * prime);
    };
    const index h = times(ix, 73856093u) ^ times(iy, 19349663u) ^ times(iz, 83492791u);
    if ((table & (table - 1)) == 0) return h & (table - 1);
    const index r = h % table;
    return r < 0 ? r + table : r;
}

/// First and last grid cell covered by [min(a, b, c) - margin, max(a, b, c) + margin]
/// (inv = 1 / cell size).
inline void cell_range(double a, double b, double c, double margin, double inv, index& lo,
                       index& hi) {
    lo = cell_of((std::min(std::min(a, b), c) - margin) * inv);
    hi = cell_of((std::max(std::max(a, b), c) + margin) * inv);
}

/// Spatial hash of the triangles into w.hash_* (a counting sort): cells(t, r) gives triangle
/// t's cell range r = (x0, y0, z0, x1, y1, z1). Counts the entries first; returns that count,
/// and stores nothing when it exceeds the entries' capacity (the caller grows the buffer).
/// Every bucket index is reduced modulo w.hash_table and every entry index is below the
/// count, so nothing is written outside the buffers.
template <class Cells>
inline index hash_triangles(const Model& m, const ContactBuffers& w, Cells cells) {
    const index table = w.hash_table;
    for (index h = 0; h < table; ++h) w.hash_count[h] = 0;
    index total = 0;
    for (int pass = 0; pass < 2; ++pass) {
        if (pass == 1) {
            if (total > w.hash_entries->capacity) return total;
            w.hash_start[0] = 0;
            for (index h = 0; h < table; ++h) {
                w.hash_start[h + 1] = w.hash_start[h] + w.hash_count[h];
                w.hash_count[h] = 0;
            }
        }
        for (index t = 0; t < m.triangles.count; ++t) {
            index r[6];
            cells(t, r);
            for (index ix = r[0]; ix <= r[3]; ++ix)
                for (index iy = r[1]; iy <= r[4]; ++iy)
                    for (index iz = r[2]; iz <= r[5]; ++iz) {
                        const index h = cell_hash(ix, iy, iz, table);
                        if (pass == 0) {
                            ++w.hash_count[h];
                            ++total;
                        } else {
                            w.hash_entries->data[w.hash_start[h] + w.hash_count[h]] = t;
                            ++w.hash_count[h];
                        }
                    }
        }
    }
    return total;
}

/// The triangles' boxes at q, grown by the contact margin, hashed on the contact grid
/// (hash_triangles' contract).
inline index build_triangle_hash(const Model& m, const double* q, const ContactBuffers& w) {
    const double inv = 1.0 / m.soft_contacts.cell_size, margin = m.soft_contacts.margin;
    return hash_triangles(m, w, [&](index t, index* r) {
        const index* tri = m.triangles.indices + 3 * t;
        const V3 a = load(q, tri[0]), b = load(q, tri[1]), c = load(q, tri[2]);
        cell_range(a.x, b.x, c.x, margin, inv, r[0], r[3]);
        cell_range(a.y, b.y, c.y, margin, inv, r[1], r[4]);
        cell_range(a.z, b.z, c.z, margin, inv, r[2], r[5]);
    });
}

/// Whether any two bodies' bounds, grown by the margin, overlap (w.body_lo, body_hi).
inline bool any_bodies_near(const Model& m, const ContactBuffers& w) {
    bool any = false;
    for (index a = 0; a < m.bodies.count; ++a)
        for (index b = a + 1; b < m.bodies.count; ++b) {
            bool near = true;
            for (int k = 0; k < 3; ++k)
                if (w.body_hi[3 * a + k] + m.soft_contacts.margin < w.body_lo[3 * b + k] ||
                    w.body_hi[3 * b + k] + m.soft_contacts.margin < w.body_lo[3 * a + k])
                    near = false;
            any = any || near;
        }
    return any;
}

/// The nearest triangle of another body than `body` within the contact margin of p, from
/// p's hash bucket; -1 if none. Fills `point` with the closest point on it.
inline index nearest_triangle(const Model& m, const double* q, const ContactBuffers& w, V3 p,
                              index body, double inv, TrianglePoint& point) {
    const double margin = m.soft_contacts.margin;
    const index h = cell_hash(cell_of(p.x * inv), cell_of(p.y * inv), cell_of(p.z * inv),
                              w.hash_table);
    double best = margin * margin;
    index best_t = -1;
    for (index e = w.hash_start[h]; e < w.hash_start[h + 1]; ++e) {
        const index t = w.hash_entries->data[e];
        const index b = m.triangles.body[t];
        if (b == body) continue;
        const double* lo = w.body_lo + 3 * b;
        const double* hi = w.body_hi + 3 * b;
        const bool inside_box = lo[0] - margin <= p.x && p.x <= hi[0] + margin &&
                                lo[1] - margin <= p.y && p.y <= hi[1] + margin &&
                                lo[2] - margin <= p.z && p.z <= hi[2] + margin;
        if (!inside_box) continue;
        const index* tri = m.triangles.indices + 3 * t;
        const TrianglePoint c =
            closest_point_on_triangle(p, load(q, tri[0]), load(q, tri[1]), load(q, tri[2]));
        const V3 d = p - c.x;
        const double d2 = d.x * d.x + d.y * d.y + d.z * d.z;
        if (d2 < best) {
            best = d2;
            best_t = t;
            point = c;
        }
    }
    return best_t;
}

/// The surface contacts of the whole model; q, qd (N, 3) change in place. A hash that needs
/// more entries than its buffer holds grows the buffer (HashEntries::grow) and is built
/// again. Returns 0, or the entries needed when the buffer could not grow to them (then
/// nothing was resolved).
inline index contacts_surface(const Model& m, double* q, double* qd, const ContactBuffers& w) {
    body_motion(m, q, qd, w);
    if (!any_bodies_near(m, w)) return 0;
    index needed = build_triangle_hash(m, q, w);
    if (needed > w.hash_entries->capacity) {
        HashEntries& entries = *w.hash_entries;
        if (entries.grow == nullptr || !entries.grow(entries, needed)) return needed;
        needed = build_triangle_hash(m, q, w);
    }
    const double inv = 1.0 / m.soft_contacts.cell_size;
    const double keep = 1.0 - m.soft_contacts.friction;
    for (index a = 0; a < m.bodies.count; ++a)
        for (index i = m.bodies.particle_range[2 * a]; i < m.bodies.particle_range[2 * a + 1]; ++i) {
            const V3 p = load(q, i);
            TrianglePoint c{{0.0, 0.0, 0.0}, 0.0, 0.0, 0.0};
            const index t = nearest_triangle(m, q, w, p, a, inv, c);
            if (t < 0) continue;
            const index i0 = m.triangles.indices[3 * t], i1 = m.triangles.indices[3 * t + 1],
                        i2 = m.triangles.indices[3 * t + 2];
            V3 n = cross(load(q, i1) - load(q, i0), load(q, i2) - load(q, i0));
            const double nn = std::sqrt(dot(n, n));
            if (nn == 0.0) continue;  // a degenerate triangle has no normal
            n = {n.x / nn, n.y / nn, n.z / nn};
            const double depth = dot(p - c.x, n);
            if (depth >= 0.0) continue;  // outside the other body
            const double w0 = m.particles.inv_mass[i0], w1 = m.particles.inv_mass[i1],
                         w2 = m.particles.inv_mass[i2], wp = m.particles.inv_mass[i];
            const double weight = wp + c.wa * c.wa * w0 + c.wb * c.wb * w1 + c.wc * c.wc * w2;
            if (weight == 0.0) continue;  // all pinned
            const index corner[3] = {i0, i1, i2};
            const double corner_w[3] = {w0, w1, w2}, bary[3] = {c.wa, c.wb, c.wc};
            // positions: separate along the triangle normal, shared by inverse mass
            const double lam = -depth / weight;
            add_to(q, i, (lam * wp) * n);
            for (int k = 0; k < 3; ++k) add_to(q, corner[k], -((lam * corner_w[k] * bary[k]) * n));
            // velocities: normal impulse (restitution) and tangential (friction)
            const V3 rv = load(qd, i) - (c.wa * load(qd, i0) + c.wb * load(qd, i1) +
                                         c.wc * load(qd, i2));
            const double vn = dot(rv, n);
            if (vn >= 0.0) continue;  // separating already
            const V3 tangent = rv - vn * n;
            const double jn = -(1.0 + m.soft_contacts.restitution) * vn / weight;
            const double jt = -(1.0 - keep) / weight;
            const V3 j = jn * n + jt * tangent;
            add_to(qd, i, wp * j);
            for (int k = 0; k < 3; ++k) add_to(qd, corner[k], -((corner_w[k] * bary[k]) * j));
        }
    return 0;
}

}  // namespace softbody::SOFTBODY_KERNELS::soft
