// Soft body against soft body with the paper's bounding objects (section 3.5): bodies whose
// bounding boxes overlap are tested vertex by vertex against the other body's bounding box,
// sphere or ellipsoid, fitted each step. A vertex inside moves out to the surface; its
// velocity relative to the other body's mean velocity is reflected (restitution, friction),
// and the opposite impulse goes to the other body, spread over its particles by mass, so
// momentum is conserved. Port of softbody.collision.soft (the ``bounding`` mode).
#pragma once

#include "model.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::soft {

/// Bounds (B, 3), mass-weighted velocity (B, 3) and mass (B,) of each body over all its
/// particles (pinned ones too).
inline void body_motion(const Model& m, const double* q, const double* qd,
                        const ContactBuffers& w) {
    const double inf = std::numeric_limits<double>::infinity();
    for (index b = 0; b < m.body_count; ++b) {
        double lo[3] = {inf, inf, inf}, hi[3] = {-inf, -inf, -inf};
        double px = 0.0, py = 0.0, pz = 0.0, mass = 0.0;
        for (index i = m.body_particle_range[2 * b]; i < m.body_particle_range[2 * b + 1]; ++i) {
            for (int k = 0; k < 3; ++k) {
                lo[k] = std::min(lo[k], q[3 * i + k]);
                hi[k] = std::max(hi[k], q[3 * i + k]);
            }
            const double mi = m.particle_mass[i];
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
    if (shape == 1) return;
    const V3 c = load(w.body_center, b);
    double wx = 1.0, wy = 1.0, wz = 1.0;
    if (shape == 3) {
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
        w.body_axes[3 * b + k] = shape == 2 ? s : s * w.body_axes[3 * b + k];
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
    const index bodies = m.body_count;
    body_motion(m, q, qd, w);
    for (index b = 0; b < bodies; ++b) {
        fit(q, m.body_particle_range[2 * b], m.body_particle_range[2 * b + 1],
            m.body_contact_shape[b], b, w);
        store(w.body_dv, b, {0.0, 0.0, 0.0});
    }
    const double e = m.soft_contact_restitution;
    const double keep = 1.0 - m.soft_contact_friction;
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
            const index shape = m.body_contact_shape[b];
            for (index i = m.body_particle_range[2 * a]; i < m.body_particle_range[2 * a + 1];
                 ++i) {
                if (m.particle_inv_mass[i] == 0.0) continue;
                double dx = q[3 * i] - c.x, dy = q[3 * i + 1] - c.y, dz = q[3 * i + 2] - c.z;
                V3 n{0.0, 0.0, 0.0};
                if (shape == 1) {
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
                const double mi = m.particle_mass[i] * share;
                add_to(w.body_dv, b, -(mi * (nv - v)));
                store(qd, i, nv);
            }
        }
    for (index b = 0; b < bodies; ++b) {
        const V3 dv = load(w.body_dv, b);
        if (dv.x == 0.0 && dv.y == 0.0 && dv.z == 0.0) continue;  // nothing hit this body
        for (index i = m.body_particle_range[2 * b]; i < m.body_particle_range[2 * b + 1]; ++i)
            if (m.particle_inv_mass[i] > 0.0) add_to(qd, i, dv);
    }
}

}  // namespace softbody::SOFTBODY_KERNELS::soft
