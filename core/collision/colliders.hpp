// Rigid colliders (paper, section 3.5, with continuous detection): their poses over time, and
// particles against them. A particle found inside is put back on the surface (for a solid
// collider, where its path of this step entered it plus the rest of the path along the
// surface, as the plane's projection does), its approaching normal velocity relative to the
// surface reflected and scaled by the restitution, its tangential part scaled by
// (1 - friction); the collider receives the opposite impulse. Port of softbody.collision.
#pragma once

#include "model.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::colliders {

constexpr double kTwoPi = 6.28318530717958647692;

/// Rodrigues rotation (3, 3) about unit axis a by angle [rad].
inline void rotate_about(V3 a, double angle, double* out) {
    const double s = std::sin(angle), c = std::cos(angle), t = 1.0 - c;
    out[0] = c + a.x * a.x * t;
    out[1] = a.x * a.y * t - a.z * s;
    out[2] = a.x * a.z * t + a.y * s;
    out[3] = a.y * a.x * t + a.z * s;
    out[4] = c + a.y * a.y * t;
    out[5] = a.y * a.z * t - a.x * s;
    out[6] = a.z * a.x * t - a.y * s;
    out[7] = a.z * a.y * t + a.x * s;
    out[8] = c + a.z * a.z * t;
}

/// Pose (collider_q (C, 3), collider_rot (C, 3, 3)) and velocity (v (C, 3) [m/s], w (C, 3)
/// [rad/s]) of every collider at time t [s]. A collider with a finite Control target moves
/// in a straight line from q_start to it over `duration` [s], `fraction` of which has passed.
inline void poses(const Model& m, const Control& c, double fraction, double duration, double t,
                  const double* q_start, double* cq, double* crot, double* cv, double* cw) {
    for (index k = 0; k < m.colliders.count; ++k) {
        store(cw, k, {0.0, 0.0, 0.0});
        store(cv, k, {0.0, 0.0, 0.0});
        const double* rest_rot = m.colliders.rotation + 9 * k;
        double* rot = crot + 9 * k;
        if (std::isfinite(c.collider_target[3 * k])) {
            const V3 d = load(c.collider_target, k) - load(q_start, k);
            store(cq, k, load(q_start, k) + fraction * d);
            store(cv, k, (1.0 / duration) * d);
            continue;
        }
        const index motion = m.colliders.motion[k];
        const V3 center = load(m.colliders.center, k);
        const V3 vec = load(m.colliders.motion_vector, k);
        if (motion == MotionKind::ROTATION) {  // rotation about a pivot
            const double rate = std::sqrt(dot(vec, vec));
            double r[9];
            if (rate > 0.0)
                rotate_about((1.0 / rate) * vec, rate * t, r);
            else
                rotate_about({1.0, 0.0, 0.0}, 0.0, r);
            const V3 p = load(m.colliders.motion_pivot, k);
            const V3 d = center - p;
            for (int i = 0; i < 3; ++i) {
                cq[3 * k + i] =
                    (&p.x)[i] + (r[3 * i] * d.x + r[3 * i + 1] * d.y + r[3 * i + 2] * d.z);
                for (int j = 0; j < 3; ++j)
                    rot[3 * i + j] = r[3 * i] * rest_rot[j] + r[3 * i + 1] * rest_rot[3 + j] +
                                     r[3 * i + 2] * rest_rot[6 + j];
            }
            store(cw, k, vec);
            store(cv, k, cross(vec, load(cq, k) - p));
            continue;
        }
        for (int j = 0; j < 9; ++j) rot[j] = rest_rot[j];
        if (motion == MotionKind::STATIC) {
            store(cq, k, center);
        } else if (motion == MotionKind::TRANSLATION) {  // constant velocity
            store(cq, k, center + t * vec);
            store(cv, k, vec);
        } else {  // oscillation a sin(omega t)
            const double omega = kTwoPi * m.colliders.motion_frequency[k];
            store(cq, k, center + std::sin(omega * t) * vec);
            store(cv, k, (omega * std::cos(omega * t)) * vec);
        }
    }
}

struct Hit {
    bool hit = false;
    V3 x{0.0, 0.0, 0.0};  // corrected position [m]
    V3 n{0.0, 0.0, 0.0};  // surface normal toward the allowed side
};

inline void slab(double l0, double l1, double h, int k, double& s_in, double& s_out, int& axis,
                 double& side) {
    const double d = l1 - l0;
    if (d == 0.0) {
        if (std::fabs(l0) > h) {
            s_in = std::numeric_limits<double>::infinity();
            s_out = -std::numeric_limits<double>::infinity();
        }
        return;
    }
    double a = (-h - l0) / d, b = (h - l0) / d, enter_side = -1.0;
    if (a > b) {
        std::swap(a, b);
        enter_side = 1.0;
    }
    if (a > s_in) {
        s_in = a;
        axis = k;
        side = enter_side;
    }
    s_out = std::min(s_out, b);
}

inline double clamp_inward(double& value, double h) {
    if (value > h) {
        value = h;
        return -1.0;
    }
    if (value < -h) {
        value = -h;
        return 1.0;
    }
    return 0.0;
}

/// Where a particle whose path p0 + s' u (s' in [0, 1]) entered a solid at s, through the
/// surface with outward normal n there, is put: the entry, plus the rest of the path's part
/// along the surface's tangent plane, (1 - s) (u - (u . n) n). So a particle sliding along
/// the surface keeps its motion along it, as on a plane (where this is the projection of
/// the step's end): friction acts on the velocity alone (respond). Outside a convex solid:
/// the tangent plane supports it.
inline V3 entered(V3 p0, V3 u, double s, V3 n) {
    const V3 along = u - dot(u, n) * n;
    return p0 + s * u + (1.0 - s) * along;
}

/// Whether a particle at p (at p0 when the step began) violates collider kind `kind` with
/// centre c, rotation r (3, 3; columns are its local axes) and half extents h. A solid's
/// path entry goes to entered().
inline Hit contact(index kind, V3 c, const double* r, V3 h, V3 p, V3 p0) {
    Hit out;
    const V3 ax{r[0], r[3], r[6]}, ay{r[1], r[4], r[7]}, az{r[2], r[5], r[8]};
    const V3 d = p - c;
    if (kind == ColliderKind::PLANE) {  // plane: local +y is the normal
        const double dist = dot(d, ay);
        if (dist >= 0.0) return out;
        return {true, p - dist * ay, ay};
    }
    if (kind == ColliderKind::BOX_CONTAINER) {  // container: clamp into the box
        double lx = dot(ax, d), ly = dot(ay, d), lz = dot(az, d);
        if (std::fabs(lx) <= h.x && std::fabs(ly) <= h.y && std::fabs(lz) <= h.z) return out;
        const double mx = clamp_inward(lx, h.x), my = clamp_inward(ly, h.y),
                     mz = clamp_inward(lz, h.z);
        if (mx == 0.0 && my == 0.0 && mz == 0.0) return out;
        const double norm = std::sqrt(mx * mx + my * my + mz * mz);
        const V3 x = c + lx * ax + ly * ay + lz * az;
        const V3 n = (mx * ax + my * ay + mz * az);
        return {true, x, {n.x / norm, n.y / norm, n.z / norm}};
    }
    // solid sphere: did the path enter it? |p0 + s (p - p0) - c| = r
    if (kind == ColliderKind::SPHERE) {
        const double radius = h.x;
        const double d2 = dot(d, d);
        const V3 e = p0 - c, u = p - p0;
        const double a = dot(u, u), b = dot(e, u), cc = dot(e, e) - radius * radius;
        if (a > 0.0 && cc >= 0.0 && b < 0.0 && b * b - a * cc >= 0.0) {
            const double s = (-b - std::sqrt(b * b - a * cc)) / a;
            if (s <= 1.0) {
                const V3 rel = p0 + s * u - c;
                const V3 n{rel.x / radius, rel.y / radius, rel.z / radius};
                return {true, entered(p0, u, s, n), n};
            }
        }
        if (d2 >= radius * radius) return out;
        double dist = std::sqrt(d2);
        V3 dir = d;
        if (dist == 0.0) {
            dir = {0.0, 1.0, 0.0};
            dist = 1.0;
        }
        const V3 n{dir.x / dist, dir.y / dist, dir.z / dist};
        return {true, c + radius * n, n};
    }
    // solid box: the path's entry first, else the nearest face for a particle already inside
    double lx = dot(ax, d), ly = dot(ay, d), lz = dot(az, d);
    const V3 e = p0 - c;
    const double bx = dot(ax, e), by = dot(ay, e), bz = dot(az, e);
    double s_in = -std::numeric_limits<double>::infinity();
    double s_out = std::numeric_limits<double>::infinity();
    int axis = -1;
    double side = 0.0;
    slab(bx, lx, h.x, 0, s_in, s_out, axis, side);
    slab(by, ly, h.y, 1, s_in, s_out, axis, side);
    slab(bz, lz, h.z, 2, s_in, s_out, axis, side);
    const bool entry = axis >= 0 && 0.0 <= s_in && s_in <= s_out && s_in <= 1.0;
    if (entry) {
        const V3 n = side * (axis == 0 ? ax : axis == 1 ? ay : az);
        return {true, entered(p0, p - p0, s_in, n), n};
    }
    if (std::fabs(lx) < h.x && std::fabs(ly) < h.y && std::fabs(lz) < h.z) {
        const double ox = h.x - std::fabs(lx), oy = h.y - std::fabs(ly), oz = h.z - std::fabs(lz);
        if (ox <= oy && ox <= oz) {
            axis = 0;
            side = lx >= 0.0 ? 1.0 : -1.0;
            lx = side * h.x;
        } else if (oy <= oz) {
            axis = 1;
            side = ly >= 0.0 ? 1.0 : -1.0;
            ly = side * h.y;
        } else {
            axis = 2;
            side = lz >= 0.0 ? 1.0 : -1.0;
            lz = side * h.z;
        }
    } else {
        return out;
    }
    const V3 n = side * (axis == 0 ? ax : axis == 1 ? ay : az);
    return {true, c + lx * ax + ly * ay + lz * az, n};
}

/// A particle found at hit.x with normal hit.n: moved there, and its velocity relative to
/// the surface (moving at u) reflected and scaled by the restitution e in the normal
/// direction, its tangential part scaled by keep = 1 - friction; j gathers the impulse the
/// collider receives [N s].
inline void respond(const Model& m, index i, const Hit& hit, V3 u, double e, double keep,
                    double* q, double* qd, V3& j) {
    const V3 v_old = load(qd, i);
    const V3 v = v_old - u;
    const double vn = dot(v, hit.n);
    store(q, i, hit.x);
    if (vn >= 0.0) return;  // separating already: only the position is corrected
    const V3 tangent = v - vn * hit.n;
    const V3 v_new = u - (e * vn) * hit.n + keep * tangent;
    j = j - m.particles.mass[i] * (v_new - v_old);
    store(qd, i, v_new);
}

/// What a pass saw of the values it wrote: whether one was not finite, and the largest
/// velocity component [m/s] (the particle checks' filter, loop::check_particles).
struct Seen {
    bool bad = false;
    double most = 0.0;
    void add(V3 x, V3 v) {
        bad |= !(std::isfinite(x.x) && std::isfinite(x.y) && std::isfinite(x.z) &&
                 std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z));
        most = std::max(most, std::max(std::fabs(v.x), std::max(std::fabs(v.y), std::fabs(v.z))));
    }
};

}  // namespace softbody::SOFTBODY_KERNELS::colliders

namespace softbody::SOFTBODY_KERNELS::mesh_collider {
// collision/mesh.hpp (included at the end of this file)
inline void contacts(const Model& m, index k, V3 c, const double* r, V3 vc, V3 wc, double e,
                     double keep, double dt, const double* q_start, double* q, double* qd, V3& j,
                     colliders::Seen* seen, index* crossed);
}  // namespace softbody::SOFTBODY_KERNELS::mesh_collider

namespace softbody::SOFTBODY_KERNELS::colliders {

/// Resolve every particle against every collider, in collider order. q_start (N, 3) holds
/// the positions at the start of the step; q, qd (N, 3) change in place; impulse (C, 3)
/// [N s] accumulates what each collider receives. A plane (the ground of most scenes)
/// has a loop of its own: one dot product per particle, no path to trace. With `seen`,
/// the particles a collider moved are added to it. dt [s]: the step (a mesh collider's
/// pose at the step's start, for its continuous test; collision/mesh.hpp). With `crossed`
/// (2, set to -1 by the caller): where a mesh collider's edge contacts left a crossing (the
/// first particle, mesh_collider::crossing_code), the first one found. With `caught_mass`
/// (C) and q_before (N, 3; the positions before this call): caught_mass[k] is set to the
/// mass [kg] of the particles collider k moved that no collider before it had moved (each
/// particle counted for the first collider that caught it).
inline void contacts(const Model& m, const double* cq, const double* crot, const double* cv,
                     const double* cw, const double* q_start, double* q, double* qd,
                     double* impulse, Seen* seen = nullptr, double dt = 0.0,
                     index* crossed = nullptr, const double* q_before = nullptr,
                     double* caught_mass = nullptr) {
    double counted = 0.0;  // the mass the colliders before k caught
    for (index k = 0; k < m.colliders.count; ++k) {
        const index kind = m.colliders.kind[k];
        const V3 center = load(cq, k);
        const double* rot = crot + 9 * k;
        const V3 size = load(m.colliders.size, k);
        const V3 vc = load(cv, k), wc = load(cw, k);
        const double e = m.colliders.restitution[k];
        const double keep = 1.0 - m.colliders.friction[k];
        V3 j{0.0, 0.0, 0.0};
        // plane: local +y is the normal (contact() below, unrolled)
        if (kind == ColliderKind::PLANE) {
            const V3 n{rot[1], rot[4], rot[7]};
            for (index i = 0; i < m.particles.count; ++i) {
                const V3 p = load(q, i);
                const double dist = dot(p - center, n);
                if (dist >= 0.0 || m.particles.inv_mass[i] == 0.0) continue;
                const Hit hit{true, p - dist * n, n};
                respond(m, i, hit, vc + cross(wc, hit.x - center), e, keep, q, qd, j);
                if (seen != nullptr) seen->add(load(q, i), load(qd, i));
            }
        } else if (kind == ColliderKind::BOX_CONTAINER) {
            // container: inside the box is free (contact(), unrolled)
            const V3 ax{rot[0], rot[3], rot[6]}, ay{rot[1], rot[4], rot[7]}, az{rot[2], rot[5], rot[8]};
            for (index i = 0; i < m.particles.count; ++i) {
                const V3 d = load(q, i) - center;
                if (std::fabs(dot(ax, d)) <= size.x && std::fabs(dot(ay, d)) <= size.y &&
                    std::fabs(dot(az, d)) <= size.z)
                    continue;
                if (m.particles.inv_mass[i] == 0.0) continue;
                const Hit hit = contact(kind, center, rot, size, load(q, i), load(q_start, i));
                if (!hit.hit) continue;
                respond(m, i, hit, vc + cross(wc, hit.x - center), e, keep, q, qd, j);
                if (seen != nullptr) seen->add(load(q, i), load(qd, i));
            }
        } else if (kind == ColliderKind::MESH) {
            mesh_collider::contacts(m, k, center, rot, vc, wc, e, keep, dt, q_start, q, qd, j,
                                    seen, crossed);
        } else {
            for (index i = 0; i < m.particles.count; ++i) {
                if (m.particles.inv_mass[i] == 0.0) continue;
                const Hit hit = contact(kind, center, rot, size, load(q, i), load(q_start, i));
                if (!hit.hit) continue;
                // the surface's velocity at the contact
                respond(m, i, hit, vc + cross(wc, hit.x - center), e, keep, q, qd, j);
                if (seen != nullptr) seen->add(load(q, i), load(qd, i));
            }
        }
        add_to(impulse, k, j);
        if (caught_mass != nullptr && q_before != nullptr) {
            double moved = 0.0;
            for (index i = 0; i < m.particles.count; ++i)
                if (q[3 * i] != q_before[3 * i] || q[3 * i + 1] != q_before[3 * i + 1] ||
                    q[3 * i + 2] != q_before[3 * i + 2])
                    moved += m.particles.mass[i];
            caught_mass[k] = moved - counted;
            counted = moved;
        }
    }
}

}  // namespace softbody::SOFTBODY_KERNELS::colliders

#include "collision/mesh.hpp"
