// Body volume by each method (softbody.volume): exact by the divergence theorem with its
// gradient dV/dx (the area-weighted vertex normals the pressure force uses), the paper's
// bounding box, sphere and ellipsoid, and Monte Carlo along seeded vertical lines.
// Geometry, not a force: gas.hpp turns volumes into pressures, forces and energies.
#pragma once

#include "model.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::volume {

constexpr double kSixth = 1.0 / 6.0;
constexpr double kPi = 3.14159265358979323846;

/// Exact volume of body b [m^3]: 1/6 sum_t n_t . (a_t - r), n_t = (b - a) x (c - a), with r
/// the body's first vertex so round-off stays of the body's size far from the origin. With
/// grad (N, 3) non-null its rows of the body get sum over faces of n_t / 6, exactly dV/dx.
inline double exact(const Model& m, index b, const double* q, double* grad) {
    const index p0 = m.bodies.particle_range[2 * b], p1 = m.bodies.particle_range[2 * b + 1];
    const V3 r = load(q, p0);
    if (grad)
        for (index k = 3 * p0; k < 3 * p1; ++k) grad[k] = 0.0;
    double six_v = 0.0;
    for (index t = m.bodies.tri_range[2 * b]; t < m.bodies.tri_range[2 * b + 1]; ++t) {
        const index i = m.triangles.indices[3 * t], j = m.triangles.indices[3 * t + 1],
                    k = m.triangles.indices[3 * t + 2];
        const V3 a = load(q, i);
        const V3 n = cross(load(q, j) - a, load(q, k) - a);
        if (grad) {
            const V3 g = kSixth * n;
            add_to(grad, i, g);
            add_to(grad, j, g);
            add_to(grad, k, g);
        }
        six_v += dot(a - r, n);
    }
    return six_v / 6.0;
}

/// Axis-aligned bounds lo, hi (3,) [m] of particles [begin, end).
inline void bounds(const double* q, index begin, index end, double* lo, double* hi) {
    for (int k = 0; k < 3; ++k) {
        lo[k] = std::numeric_limits<double>::infinity();
        hi[k] = -std::numeric_limits<double>::infinity();
    }
    for (index i = begin; i < end; ++i)
        for (int k = 0; k < 3; ++k) {
            const double x = q[3 * i + k];
            if (x < lo[k]) lo[k] = x;
            if (x > hi[k]) hi[k] = x;
        }
}

/// Volume [m^3] of a body's bounding box (method 1), sphere (2) or ellipsoid (3).
inline double bounding(const double* q, index begin, index end, index method, const double* lo,
                       const double* hi) {
    const double hx = 0.5 * (hi[0] - lo[0]), hy = 0.5 * (hi[1] - lo[1]),
                 hz = 0.5 * (hi[2] - lo[2]);
    if (method == VolumeMethod::BOUNDING_BOX) return 8.0 * hx * hy * hz;
    const double cx = lo[0] + hx, cy = lo[1] + hy, cz = lo[2] + hz;
    if (method == VolumeMethod::BOUNDING_SPHERE) {
        double r2 = 0.0;
        for (index i = begin; i < end; ++i) {
            const double dx = q[3 * i] - cx, dy = q[3 * i + 1] - cy, dz = q[3 * i + 2] - cz;
            r2 = std::max(r2, dx * dx + dy * dy + dz * dz);
        }
        return 4.0 / 3.0 * kPi * std::pow(r2, 1.5);
    }
    // ellipsoid with semi-axes s (hx, hy, hz); a flat direction gets a tiny floor so a planar
    // body has a small finite ellipsoid instead of a division by zero
    const double tiny = 1e-12 * std::max(std::max(hx, hy), std::max(hz, 1e-300));
    const double ix = 1.0 / std::max(hx, tiny), iy = 1.0 / std::max(hy, tiny),
                 iz = 1.0 / std::max(hz, tiny);
    double s2 = 0.0;
    for (index i = begin; i < end; ++i) {
        const double dx = (q[3 * i] - cx) * ix, dy = (q[3 * i + 1] - cy) * iy,
                     dz = (q[3 * i + 2] - cz) * iz;
        s2 = std::max(s2, dx * dx + dy * dy + dz * dz);
    }
    return 4.0 / 3.0 * kPi * std::pow(s2, 1.5) / (ix * iy * iz);
}

/// Monte Carlo volume [m^3] of triangles [t_begin, t_end) from vertical lines through the
/// samples (S, 2) in [0, 1)^2 of the xz rectangle of lo, hi: the inside length of a line is
/// the sum of sign(n_y) y over the triangles it crosses (exits minus entries).
inline double monte_carlo(const Model& m, const double* q, index t_begin, index t_end,
                          const double* lo, const double* hi, const double* samples,
                          index sample_count) {
    if (sample_count == 0) return std::numeric_limits<double>::quiet_NaN();
    const double wx = hi[0] - lo[0], wz = hi[2] - lo[2];
    const double y0 = 0.5 * (lo[1] + hi[1]);
    double total = 0.0;
    for (index t = t_begin; t < t_end; ++t) {
        const index i = m.triangles.indices[3 * t], j = m.triangles.indices[3 * t + 1],
                    k = m.triangles.indices[3 * t + 2];
        const double ax = q[3 * i], az = q[3 * i + 2], bx = q[3 * j], bz = q[3 * j + 2];
        const double cx = q[3 * k], cz = q[3 * k + 2];
        const double ay = q[3 * i + 1] - y0, by = q[3 * j + 1] - y0, cy = q[3 * k + 1] - y0;
        const double det = (bx - ax) * (cz - az) - (cx - ax) * (bz - az);  // -n_y
        if (det == 0.0) continue;  // a vertical triangle is crossed by no line
        const double inv = 1.0 / det;
        const double xmin = std::min(ax, std::min(bx, cx)), xmax = std::max(ax, std::max(bx, cx));
        const double zmin = std::min(az, std::min(bz, cz)), zmax = std::max(az, std::max(bz, cz));
        const double sign = det < 0.0 ? 1.0 : -1.0;  // exit (n_y > 0) adds y, entry subtracts
        for (index s = 0; s < sample_count; ++s) {
            const double px = lo[0] + samples[2 * s] * wx;
            if (px < xmin || px > xmax) continue;
            const double pz = lo[2] + samples[2 * s + 1] * wz;
            if (pz < zmin || pz > zmax) continue;
            const double l1 = ((px - ax) * (cz - az) - (cx - ax) * (pz - az)) * inv;
            const double l2 = ((bx - ax) * (pz - az) - (px - ax) * (bz - az)) * inv;
            if (l1 < 0.0 || l2 < 0.0 || l1 + l2 > 1.0) continue;
            total += sign * (ay + l1 * (by - ay) + l2 * (cy - ay));
        }
    }
    return wx * wz * total / static_cast<double>(sample_count);
}

/// Every body's volume by its own method into gas.volume (B,) [m^3]; with gas.volume_gradient
/// non-null also the exact gradients (N, 3) [m^2] (whatever the method: the pressure force
/// acts through the faces). Bodies with a bounding or Monte Carlo volume get gas.lo/hi. With
/// exact_done, bodies of the exact method keep the volume already in gas.volume.
inline void evaluate(const Model& m, const double* q, const BodyGas& gas,
                     bool exact_done = false) {
    for (index b = 0; b < m.bodies.count; ++b) {
        const index method = m.volumes.method[b];
        if (exact_done && method == VolumeMethod::EXACT) continue;  // the vertex-major pass measured it
        const bool need_exact = method == VolumeMethod::EXACT || gas.volume_gradient != nullptr;
        double v = need_exact ? exact(m, b, q, gas.volume_gradient) : 0.0;
        if (method != VolumeMethod::EXACT) {
            const index begin = m.bodies.particle_range[2 * b], end = m.bodies.particle_range[2 * b + 1];
            double* lo = gas.lo + 3 * b;
            double* hi = gas.hi + 3 * b;
            bounds(q, begin, end, lo, hi);
            if (method == VolumeMethod::MONTE_CARLO) {
                const index s0 = m.volumes.mc_range[2 * b], s1 = m.volumes.mc_range[2 * b + 1];
                v = monte_carlo(m, q, m.bodies.tri_range[2 * b], m.bodies.tri_range[2 * b + 1], lo,
                                hi, m.volumes.mc_samples + 2 * s0, s1 - s0);
            } else {
                v = bounding(q, begin, end, method, lo, hi);
            }
        }
        gas.volume[b] = v;
    }
}

}  // namespace softbody::SOFTBODY_KERNELS::volume
