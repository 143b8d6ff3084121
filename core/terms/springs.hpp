// Damped Hooke springs between particles (mesh edges, bending springs, user springs).
//
// For a spring from i to j with direction u = (x_j - x_i) / L the force on i is
//     f_i = [k (L - L0) + c (v_j - v_i) . u] u,   f_j = -f_i,
// whose elastic part is -dE/dx_i for E = 1/2 k (L - L0)^2. Its stiffness K = df/dx is
// k [u u^T + max(0, 1 - L0/L) (I - u u^T)] between the two ends (the compressive part of the
// geometric stiffness dropped, so -K stays positive semi-definite), its damping C = c u u^T.
//
// Forms: force (edge-major) and lane_pair / lane_force (the vertex-major pass); energy and
// energies (per body, by Springs::body); prepare + jacobian_product (the implicit
// solvers' K p and C p); smoother_blocks (their multigrid smoother); projection + project
// (projective dynamics' local step and right-hand side); bound_weights, add_root_sums,
// row_bounds and damping_ratios (the stability estimate's Gershgorin bound: per part the
// largest sqrt(w) (R_i / m_i + R_j / m_j), R_i the sum of sqrt(w) at i).
#pragma once

#include <cstring>
#include <vector>

#include "model.hpp"
#include "simd.hpp"
#include "terms/term.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::springs {

/// Accumulate every spring's damped force into f (N, 3) [N] at q, qd (N, 3).
inline void force(const Model& m, const double* q, const double* qd, double* f) {
    const index* ends = m.springs.indices;
    for (index s = 0; s < m.springs.count; ++s) {
        const index i = ends[2 * s], j = ends[2 * s + 1];
        const V3 d = load(q, j) - load(q, i);
        const double length = std::sqrt(dot(d, d));
        if (length == 0.0) continue;  // direction undefined: a saddle point of the energy
        const V3 u = (1.0 / length) * d;
        const double rel = dot(load(qd, j) - load(qd, i), u);
        const double mag =
            m.springs.stiffness[s] * (length - m.springs.rest_length[s]) + m.springs.damping[s] * rel;
        const V3 fi = mag * u;
        add_to(f, i, fi);
        add_to(f, j, -fi);
    }
}

/// Vertex-major: the damped force at the lanes' particles `self` of springs to `o` (rest
/// length, stiffness, damping per lane), added to fx, fy, fz [N]. Each spring is met at both
/// ends, with d, u and the magnitude negated exactly at the other end, so its two forces are
/// equal and opposite. d = o - self is passed in (the ring pass shares it with the faces).
/// Lanes with d = 0 (padding that points at the particle itself) get nothing. V: lanes of
/// doubles (Rows), or of floats (RowsF) for the float32 force pass.
template <class V, class R>
inline void lane_pair(const R& self, const R& o, V dx, V dy, V dz, V rest, V stiffness,
                      V damping, V& fx, V& fy, V& fz) {
    const V length2 = dx * dx + dy * dy + dz * dz;
    const V inv = vrsqrt(length2);
    const V length = length2 * inv;
    const V ux = inv * dx, uy = inv * dy, uz = inv * dz;
    const V rel = (o.vx - self.vx) * ux + (o.vy - self.vy) * uy + (o.vz - self.vz) * uz;
    const V mag = stiffness * (length - rest) + damping * rel;
    const auto live = length2 != V{};
    fx += select(live, mag * ux);
    fy += select(live, mag * uy);
    fz += select(live, mag * uz);
}

/// Vertex-major: the springs off the particles' rings (bending and user springs), slots of
/// group g from lane0, added to fx, fy, fz [N].
inline void lane_force(const Model& m, const double* rows, index g, int lane0, const Rows& self,
                       vd& fx, vd& fy, vd& fz) {
    for (index s = m.slots.spring_start[g]; s < m.slots.spring_start[g + 1]; ++s) {
        const index e = kGroup * s + lane0;
        const Rows o = load_rows(rows, m.slots.spring_other + e);
        lane_pair(self, o, o.x - self.x, o.y - self.y, o.z - self.z,
                  load_lanes(m.slots.spring_rest_length + e), load_lanes(m.slots.spring_stiffness + e),
                  load_lanes(m.slots.spring_damping + e), fx, fy, fz);
    }
}

/// Per spring the unit direction u (S, 3), axial stiffness a = k and transverse stiffness
/// b = k max(0, 1 - L0/L) (S,) at q: what jacobian_product reads.
inline void prepare(const Model& m, const double* q, double* u, double* a, double* b) {
    for (index s = 0; s < m.springs.count; ++s) {
        const V3 d = load(q, m.springs.indices[2 * s + 1]) - load(q, m.springs.indices[2 * s]);
        const double length = std::sqrt(dot(d, d));
        const double k = m.springs.stiffness[s];
        if (length == 0.0) {
            store(u, s, {0.0, 0.0, 0.0});
            a[s] = 0.0;
            b[s] = k;
            continue;
        }
        store(u, s, (1.0 / length) * d);
        a[s] = k;
        b[s] = k * std::max(0.0, 1.0 - m.springs.rest_length[s] / length);
    }
}

/// out += alpha_c C p + alpha_k K p for p (N, 3): per spring the block (a - b) u u^T + b I
/// (stiffness) and c u u^T (damping) acting on p_j - p_i, opposite on j. u, a, b from
/// prepare (or any blocks of that form: the stability estimate splits them).
inline void jacobian_product(const Model& m, const double* u, const double* a, const double* b,
                             double alpha_c, double alpha_k, const double* p, double* out) {
    for (index s = 0; s < m.springs.count; ++s) {
        const index i = m.springs.indices[2 * s], j = m.springs.indices[2 * s + 1];
        const V3 d = load(p, j) - load(p, i);
        const V3 us = load(u, s);
        const double ud = dot(us, d);
        const double iso = alpha_k * b[s];
        const double axial = alpha_k * (a[s] - b[s]) * ud + alpha_c * m.springs.damping[s] * ud;
        const V3 w = iso * d + axial * us;
        add_to(out, i, w);
        add_to(out, j, -w);
    }
}

/// The springs' share of the implicit system M - h C - h^2 K for its finest-level smoother:
/// per spring the block alpha u u^T + beta I with alpha = h c + h^2 (a - b), beta = h^2 b,
/// packed per particle entry (entry_ptr (N + 1,), entry_spring (2 S,)) into coef (2 S, 5)
/// as u, alpha, beta, and each particle's springs' blocks added to its diagonal block in
/// block (N, 3, 3) (which holds m I and the terms before). u, a, b from prepare; h [s].
inline void smoother_blocks(const Model& m, double h, const double* u, const double* a,
                            const double* b, const index* entry_ptr, const index* entry_spring,
                            double* coef, double* block) {
    for (index i = 0; i < m.particles.count; ++i) {
        double* d = block + 9 * i;
        double b00 = d[0], b11 = d[4], b22 = d[8], b01 = d[1], b02 = d[2], b12 = d[5];
        for (index e = entry_ptr[i]; e < entry_ptr[i + 1]; ++e) {
            const index s = entry_spring[e];
            const V3 us = load(u, s);
            const double alpha = h * m.springs.damping[s] + h * h * (a[s] - b[s]);
            const double beta = h * h * b[s];
            double* c = coef + 5 * e;
            c[0] = us.x, c[1] = us.y, c[2] = us.z, c[3] = alpha, c[4] = beta;
            b00 += alpha * us.x * us.x + beta;
            b11 += alpha * us.y * us.y + beta;
            b22 += alpha * us.z * us.z + beta;
            b01 += alpha * us.x * us.y;
            b02 += alpha * us.x * us.z;
            b12 += alpha * us.y * us.z;
        }
        d[0] = b00, d[4] = b11, d[8] = b22;
        d[1] = d[3] = b01;
        d[2] = d[6] = b02;
        d[5] = d[7] = b12;
    }
}

/// Projective dynamics' local step for one spring (or attachment): k p + c_h q [N] for an
/// edge d (now) that was e at the step's start, c_h = c / h. p is d's projection onto the
/// sphere |d| = rest, the minimiser of Hooke's energy 1/2 k (|d| - L0)^2 in its projective
/// form k / 2 |d - p|^2; q its projection onto the plane u . (d - e) = 0 (u = d / |d|), whose
/// c / (2 h) |d - q|^2 is the damper c (u . (v_j - v_i)) u of backward Euler. Both lie along
/// d: p = rest d / |d|, q = (d . e / |d|^2) d, so one division and one square root. A
/// zero-length edge has no direction: both are d (no force, as in `force`).
inline V3 projection(V3 d, V3 e, double rest, double k, double c_h) {
    const double length2 = dot(d, d);
    if (length2 == 0.0) return (k + c_h) * d;
    const double inv2 = 1.0 / length2;
    const double s = k * rest * std::sqrt(inv2) + c_h * dot(d, e) * inv2;
    return s * d;
}

/// Projective dynamics: the springs' part of the global step's right-hand side, added to
/// rhs (N, 3) [N]: A_s^T (k p + c / h q) per spring at the iterate x (N, 3), its edges at
/// the step's start from x0 (N, 3); h [s] the step. A pinned end (inverse mass 0) is no
/// unknown: its row is the identity and the spring's pull on it, (k + c / h) x_pinned,
/// moves to the free end's side.
inline void project(const Model& m, double h, const double* x, const double* x0, double* rhs) {
    const double inv_h = 1.0 / h;
    const double* inv_mass = m.particles.inv_mass;
    for (index s = 0; s < m.springs.count; ++s) {
        const index i = m.springs.indices[2 * s], j = m.springs.indices[2 * s + 1];
        const double k = m.springs.stiffness[s], c_h = m.springs.damping[s] * inv_h;
        const V3 t = projection(load(x, j) - load(x, i), load(x0, j) - load(x0, i),
                                m.springs.rest_length[s], k, c_h);
        const bool free_i = inv_mass[i] > 0.0, free_j = inv_mass[j] > 0.0;
        if (free_i) {
            add_to(rhs, i, -t);
            if (!free_j) add_to(rhs, i, (k + c_h) * load(x, j));
        }
        if (free_j) {
            add_to(rhs, j, t);
            if (!free_i) add_to(rhs, j, (k + c_h) * load(x, i));
        }
    }
}

/// Elastic energy 1/2 k (L - L0)^2 [J] of every spring at q (N, 3), each added to its body's
/// entry of body_energy (B,) (Springs::body: a body's edge and bending springs; a
/// user's spring, body -1, counts in the total only); returns the total [J].
inline double energies(const Model& m, const double* q, double* body_energy) {
    double total = 0.0;
    for (index s = 0; s < m.springs.count; ++s) {
        const V3 d = load(q, m.springs.indices[2 * s + 1]) - load(q, m.springs.indices[2 * s]);
        const double stretch = std::sqrt(dot(d, d)) - m.springs.rest_length[s];
        const double e = 0.5 * m.springs.stiffness[s] * stretch * stretch;
        total += e;
        if (m.springs.body[s] >= 0) body_energy[m.springs.body[s]] += e;
    }
    return total;
}

/// Stiffness bound (softbody.stability): the norms of a spring's blocks by part, the weights
/// its Gershgorin rows add up. Part kDamped is the axial block k u u^T (spring damping acts
/// on it), kTransverse the geometric k |1 - L0/L| (I - u u^T) (k at L = 0, no direction),
/// kWhole the whole block k max(1, |1 - L0/L|) (the two parts are orthogonal) and kDamping
/// the damper c u u^T (its rows bound a damping rate [1/s], not a squared frequency).
enum BoundPart { kDamped = 0, kTransverse = 1, kWhole = 2, kDamping = 3, kBoundParts = 4 };

/// |1 - L0 / L| for a spring (or attachment) of length L, rest length L0 [m]; 1 at L = 0.
inline double stretch_factor(double length, double rest_length) {
    return length > 0.0 ? std::abs(1.0 - rest_length / length) : 1.0;
}

/// The weights w (S, kBoundParts) [N/m] (kDamping: [N s/m]) of every spring at q (N, 3).
inline void bound_weights(const Model& m, const double* q, double* w) {
    for (index s = 0; s < m.springs.count; ++s) {
        const V3 d = load(q, m.springs.indices[2 * s + 1]) - load(q, m.springs.indices[2 * s]);
        const double k = m.springs.stiffness[s];
        const double stretch = stretch_factor(std::sqrt(dot(d, d)), m.springs.rest_length[s]);
        double* ws = w + kBoundParts * s;
        ws[kDamped] = k;
        ws[kTransverse] = k * stretch;
        ws[kWhole] = k * std::max(1.0, stretch);
        ws[kDamping] = m.springs.damping[s];
    }
}

/// Gershgorin on the spring-by-spring matrix M^-1/2 K M^-1/2 (for any directions u): the
/// row sums R_i = sum of sqrt(w) over the springs at i, added into root_sum
/// (N, kBoundParts) at both ends of every spring.
inline void add_root_sums(const Model& m, const double* w, double* root_sum) {
    for (index s = 0; s < m.springs.count; ++s) {
        double* ri = root_sum + kBoundParts * m.springs.indices[2 * s];
        double* rj = root_sum + kBoundParts * m.springs.indices[2 * s + 1];
        for (int part = 0; part < kBoundParts; ++part) {
            const double r = std::sqrt(w[kBoundParts * s + part]);
            ri[part] += r;
            rj[part] += r;
        }
    }
}

/// The springs' Gershgorin bound of each part, max over springs (i, j) of
/// sqrt(w) (R_i / m_i + R_j / m_j) [1/s^2] (kDamping: [1/s]), into bound (kBoundParts,)
/// where larger: exact for one spring, the Anderson-Morley bound for equal springs.
/// root_sum from every spring-like term's add_root_sums; pinned ends (1 / m = 0) add none.
inline void row_bounds(const Model& m, const double* w, const double* root_sum, double* bound) {
    const double* inv = m.particles.inv_mass;
    for (index s = 0; s < m.springs.count; ++s) {
        const index i = m.springs.indices[2 * s], j = m.springs.indices[2 * s + 1];
        for (int part = 0; part < kBoundParts; ++part) {
            const double row = std::sqrt(w[kBoundParts * s + part]) *
                               (root_sum[kBoundParts * i + part] * inv[i] +
                                root_sum[kBoundParts * j + part] * inv[j]);
            bound[part] = std::max(bound[part], row);
        }
    }
}

/// The damping per stiffness c / k [s] of the springs with k > 0, folded into [lo, hi];
/// pure_damper set where a spring has c > 0 and k = 0 (it may damp any mode).
inline void damping_ratios(const Model& m, double& lo, double& hi, bool& pure_damper) {
    for (index s = 0; s < m.springs.count; ++s) {
        const double k = m.springs.stiffness[s], c = m.springs.damping[s];
        if (k > 0.0) {
            lo = std::min(lo, c / k);
            hi = std::max(hi, c / k);
        } else if (k == 0.0 && c > 0.0) {
            pure_damper = true;
        }
    }
}

/// XPBD's step for one distance constraint C = |d| - L0 of stiffness k [N/m] and damping c
/// [N s/m] over a substep h [s] (Macklin et al. 2016, eq. 26, with alpha = 1 / k and
/// beta = c, multiplied through by k h^2 so that k = 0 is a pure damper): the multiplier's
/// change dlambda = -(k h^2 C + lambda + c h u . e) / ((k h^2 + c h) w + 1) [N s^2], with e
/// the edge's change since the substep's start and w the ends' inverse masses summed.
inline double xpbd_delta(double stretch, double lambda, double u_dot_e, double k, double c,
                         double h, double w) {
    const double kh2 = k * h * h, ch = c * h;
    return -(kh2 * stretch + lambda + ch * u_dot_e) / ((kh2 + ch) * w + 1.0);
}

/// Rows of ConstraintPass::spring_coef, each (S,) per entry of spring_order.
enum CoefRow { kRest = 0, kStretch = 1, kDamp = 2, kLambda = 3, kWi = 4, kWj = 5, kCoefRows = 6 };

/// XPBD's constants of every spring for the substep p.h, per entry r of p.spring_order,
/// into the rows of p.spring_coef (kCoefRows, S): L0, k h^2 / D, c h / D and 1 / D with
/// D = (k h^2 + c h) w + 1 (xpbd_delta's terms; w = w_i + w_j the ends' inverse masses),
/// and w_i, w_j, so that the pass divides by nothing but the length. A spring between two
/// pinned particles (w = 0) gets zeros: it moves nothing.
inline void constraint_coefficients(const Model& m, const ConstraintPass& p) {
    const index* ends = m.springs.indices;
    const double* inv = m.particles.inv_mass;
    const index count = m.springs.count;
    const double h = p.h;
    double* coef = p.spring_coef;
    for (index r = 0; r < count; ++r) {
        const index s = p.spring_order[r];
        const double wi = inv[ends[2 * s]], wj = inv[ends[2 * s + 1]];
        const double w = wi + wj;
        const double kh2 = m.springs.stiffness[s] * h * h, ch = m.springs.damping[s] * h;
        const double inv_d = w == 0.0 ? 0.0 : 1.0 / ((kh2 + ch) * w + 1.0);
        coef[kRest * count + r] = m.springs.rest_length[s];
        coef[kStretch * count + r] = kh2 * inv_d;
        coef[kDamp * count + r] = ch * inv_d;
        coef[kLambda * count + r] = inv_d;
        coef[kWi * count + r] = wi;
        coef[kWj * count + r] = wj;
    }
}

/// Positions x, y, z of the particles idx[0 .. kLanes-1] (one lane each) written into
/// their rows (kRow doubles each: the ConstraintPass layout), with each row's fourth double
/// rewritten as s (its own value, which the caller read with load_rows): an in-register
/// transpose and one 4-double store per particle, where a scatter costs a store per double.
/// The particles are distinct.
inline void store_positions(double* rows, const index* idx, vd x, vd y, vd z, vd s) {
#if defined(__AVX512F__)
    // pairs (x, y) and (z, s) of the even and odd lanes, then each lane's two pairs side by
    // side: e0 holds lanes 0 and 2, e1 4 and 6, e2 1 and 3, e3 5 and 7
    const __m512d a0 = _mm512_unpacklo_pd(x, y), a1 = _mm512_unpackhi_pd(x, y);
    const __m512d b0 = _mm512_unpacklo_pd(z, s), b1 = _mm512_unpackhi_pd(z, s);
    const __m512d c0 = _mm512_shuffle_f64x2(a0, b0, 0x44), c1 = _mm512_shuffle_f64x2(a0, b0, 0xEE);
    const __m512d c2 = _mm512_shuffle_f64x2(a1, b1, 0x44), c3 = _mm512_shuffle_f64x2(a1, b1, 0xEE);
    const __m512d e0 = _mm512_shuffle_f64x2(c0, c0, 0xD8), e1 = _mm512_shuffle_f64x2(c1, c1, 0xD8);
    const __m512d e2 = _mm512_shuffle_f64x2(c2, c2, 0xD8), e3 = _mm512_shuffle_f64x2(c3, c3, 0xD8);
    _mm256_storeu_pd(rows + kRow * idx[0], _mm512_castpd512_pd256(e0));
    _mm256_storeu_pd(rows + kRow * idx[2], _mm512_extractf64x4_pd(e0, 1));
    _mm256_storeu_pd(rows + kRow * idx[4], _mm512_castpd512_pd256(e1));
    _mm256_storeu_pd(rows + kRow * idx[6], _mm512_extractf64x4_pd(e1, 1));
    _mm256_storeu_pd(rows + kRow * idx[1], _mm512_castpd512_pd256(e2));
    _mm256_storeu_pd(rows + kRow * idx[3], _mm512_extractf64x4_pd(e2, 1));
    _mm256_storeu_pd(rows + kRow * idx[5], _mm512_castpd512_pd256(e3));
    _mm256_storeu_pd(rows + kRow * idx[7], _mm512_extractf64x4_pd(e3, 1));
#elif defined(__AVX2__)
    const __m256d a0 = _mm256_unpacklo_pd(x, y), a1 = _mm256_unpackhi_pd(x, y);
    const __m256d b0 = _mm256_unpacklo_pd(z, s), b1 = _mm256_unpackhi_pd(z, s);
    _mm256_storeu_pd(rows + kRow * idx[0], _mm256_permute2f128_pd(a0, b0, 0x20));
    _mm256_storeu_pd(rows + kRow * idx[1], _mm256_permute2f128_pd(a1, b1, 0x20));
    _mm256_storeu_pd(rows + kRow * idx[2], _mm256_permute2f128_pd(a0, b0, 0x31));
    _mm256_storeu_pd(rows + kRow * idx[3], _mm256_permute2f128_pd(a1, b1, 0x31));
#else
    double* r = rows + kRow * idx[0];
    r[0] = x[0], r[1] = y[0], r[2] = z[0], r[3] = s[0];
#endif
}

/// XPBD's step for the springs at entries [r, r + kLanes) of the colouring, one per lane
/// (no two share a particle: their updates are independent, loaded and stored at once,
/// each end's row in one load): xpbd_delta with constraint_coefficients' constants, times
/// p.relaxation, each spring's two ends moved along its direction by their inverse masses.
/// A zero-length spring has no direction: it moves nothing.
inline void constrain_lanes(const ConstraintPass& p, index count, index r) {
    const index* ii = p.spring_ends + r;
    const index* jj = p.spring_ends + count + r;
    // x, y, z the iterate; vx, vy, vz the substep's start (the rows' second triple)
    const Rows a = load_rows(p.rows, ii), b = load_rows(p.rows, jj);
    const double* coef = p.spring_coef + r;
    const vd d[3] = {b.x - a.x, b.y - a.y, b.z - a.z};
    const vd start[3] = {b.vx - a.vx, b.vy - a.vy, b.vz - a.vz};
    vd u[3];
    vd length2{}, u_dot_e{};
    for (int k = 0; k < 3; ++k) length2 += d[k] * d[k];
    const vi live = length2 != 0.0;
    const vd inv_length = select(live, splat(1.0) / vsqrt(length2));
    for (int k = 0; k < 3; ++k) {
        u[k] = inv_length * d[k];
        u_dot_e += u[k] * (d[k] - start[k]);
    }
    const vd stretch = length2 * inv_length - load_lanes(coef + kRest * count);
    double* lambda = p.spring_lambda + r;
    const vd dl = select(live, -(load_lanes(coef + kStretch * count) * stretch +
                                 load_lanes(coef + kDamp * count) * u_dot_e +
                                 load_lanes(coef + kLambda * count) * load_lanes(lambda))) *
                  p.relaxation;
    store_lanes(lambda, load_lanes(lambda) + dl);
    const vd di = load_lanes(coef + kWi * count) * dl, dj = load_lanes(coef + kWj * count) * dl;
    store_positions(p.rows, ii, a.x - di * u[0], a.y - di * u[1], a.z - di * u[2], a.vx);
    store_positions(p.rows, jj, b.x + dj * u[0], b.y + dj * u[1], b.z + dj * u[2], b.vx);
}

/// The same step for the one spring at entry r.
inline void constrain_one(const ConstraintPass& p, index count, index r) {
    double* ri = p.rows + kRow * p.spring_ends[r];
    double* rj = p.rows + kRow * p.spring_ends[count + r];
    const double* coef = p.spring_coef + r;
    const V3 d = load(rj, 0) - load(ri, 0);
    const double length2 = dot(d, d);
    if (length2 == 0.0) return;
    const double inv_length = 1.0 / std::sqrt(length2);
    const V3 u = inv_length * d;
    const V3 e = d - (load(rj, 1) - load(ri, 1));
    const double stretch = length2 * inv_length - coef[kRest * count];
    const double dl = -(coef[kStretch * count] * stretch + coef[kDamp * count] * dot(u, e) +
                        coef[kLambda * count] * p.spring_lambda[r]) *
                      p.relaxation;
    p.spring_lambda[r] += dl;
    add_to(ri, 0, -(coef[kWi * count] * dl) * u);
    add_to(rj, 0, (coef[kWj * count] * dl) * u);
}

/// XPBD's pass over the springs (ConstraintPass): Gauss-Seidel colour by colour; within a
/// colour (no two springs sharing a particle) kLanes springs at a time, the rest one by one.
inline void constrain(const Model& m, const ConstraintPass& p) {
    const index count = m.springs.count;
    for (index c = 0; c < p.colours; ++c) {
        index r = p.colour_ptr[c];
        const index end = p.colour_ptr[c + 1];
        for (; r + kLanes <= end; r += kLanes) constrain_lanes(p, count, r);
        for (; r < end; ++r) constrain_one(p, count, r);
    }
}

/// The registered term (terms/registry.hpp): its forms for the solvers.
struct Term : TermBase {
    static constexpr const char* kName = "springs";
    static constexpr bool kLane = true, kProjected = true, kFused = true, kEnergy = true;
    static constexpr bool kConstraint = true, kBound = true, kSharedRows = true;
    static constexpr bool kSpectral = true;
    // smoother entries: u (3,), alpha, beta of the entry's spring (smoother_blocks)
    static constexpr bool kStencil = true;
    static constexpr int kStencilWidth = 5;
    /// s += sum over entries of (alpha u u^T + beta I) x_j.
    static void add_entries(const Stencil& st, const double* x, index first, index last,
                            V3& s) {
        double s0 = s.x, s1 = s.y, s2 = s.z;
        for (index e = first; e < last; ++e) {
            const index j = st.neighbor[e];
            const double* c = st.coef + 5 * e;
            const double ux = c[0], uy = c[1], uz = c[2], beta = c[4];
            const double xj0 = x[3 * j], xj1 = x[3 * j + 1], xj2 = x[3 * j + 2];
            const double ax = c[3] * (ux * xj0 + uy * xj1 + uz * xj2);
            s0 += ax * ux + beta * xj0;
            s1 += ax * uy + beta * xj1;
            s2 += ax * uz + beta * xj2;
        }
        s = {s0, s1, s2};
    }
    /// The map: each entry's spring, in [0, S).
    static const char* check_stencil(const Model& m, const Stencil& st, index map_length) {
        if (map_length != st.count) return "map must have one spring per entry";
        for (index e = 0; e < st.count; ++e)
            if (st.map[e] < 0 || st.map[e] >= m.springs.count) return "map holds a bad spring";
        return nullptr;
    }
    /// The stability estimate: R_i, then the springs' rows against them and their c / k.
    static void add_row_sums(const Model& m, const Control&, const double* q,
                             const BoundScratch& s) {
        std::vector<double> w(static_cast<size_t>(kBoundParts * m.springs.count));
        bound_weights(m, q, w.data());
        add_root_sums(m, w.data(), s.root_sum);
    }
    static void bound(const Model& m, const Control&, const double* q, const BoundScratch& s,
                      TermBound& out) {
        std::vector<double> w(static_cast<size_t>(kBoundParts * m.springs.count));
        bound_weights(m, q, w.data());
        row_bounds(m, w.data(), s.root_sum, out.parts);
        damping_ratios(m, out.ratio_min, out.ratio_max, out.pure_dampers);
    }
    static void force(const Eval& e, double* f) { springs::force(e.m, e.q, e.qd, f); }
    static void prepare_constraints(const Model& m, const Control&, const ConstraintPass& p) {
        constraint_coefficients(m, p);
    }
    static void constrain(const Model& m, const Control&, const ConstraintPass& p) {
        springs::constrain(m, p);
    }
    static double energy(const Eval& e, double* body) { return energies(e.m, e.q, body); }
    /// Linearisation: u (S, 3), a (S,), b (S,) (prepare's), one after the other.
    static index linearization_size(const Model& m) { return 5 * m.springs.count; }
    static double* lin_u(const Model&, const Linearization& l) { return l.own; }
    static double* lin_a(const Model& m, const Linearization& l) {
        return l.own + 3 * m.springs.count;
    }
    static double* lin_b(const Model& m, const Linearization& l) {
        return l.own + 4 * m.springs.count;
    }
    static void prepare(const Eval& e, const Linearization& l) {
        springs::prepare(e.m, l.q, lin_u(e.m, l), lin_a(e.m, l), lin_b(e.m, l));
    }
    static void jacobian_product(const Model& m, const Control&, const Linearization& l,
                                 double alpha_c, double alpha_k, const double* p, double* out) {
        springs::jacobian_product(m, lin_u(m, l), lin_a(m, l), lin_b(m, l), alpha_c, alpha_k, p,
                                  out);
    }
    /// The stability estimate's linearisation (the same 5 S doubles): u (S, 3) = d / L
    /// (0 where L = 0), the transverse stiffness t = k |1 - L0/L| (S,) (k where L = 0:
    /// the estimate takes the compressive part too, unlike prepare), and zeros (S,).
    static void prepare_spectral(const Eval& e, const BoundScratch&, const Linearization& l) {
        const Model& m = e.m;
        double* u = lin_u(m, l);
        double* t = lin_a(m, l);
        double* zero = lin_b(m, l);
        for (index s = 0; s < m.springs.count; ++s) {
            const V3 d = load(l.q, m.springs.indices[2 * s + 1]) -
                         load(l.q, m.springs.indices[2 * s]);
            const double length = std::sqrt(dot(d, d));
            const double k = m.springs.stiffness[s];
            zero[s] = 0.0;
            if (length > 0.0) {
                store(u, s, {d.x / length, d.y / length, d.z / length});
                t[s] = k * std::abs(1.0 - m.springs.rest_length[s] / length);
            } else {
                store(u, s, {0.0, 0.0, 0.0});
                t[s] = k * 1.0;
            }
        }
    }
    /// The split: the axial k u u^T damped (its damper c u u^T acts on it), the transverse
    /// t (I - u u^T) undamped, both in the whole; the blocks (a - b) u u^T + b I of
    /// jacobian_product with a, b one of k, t and 0.
    static void spectral_product(const Model& m, const Control&, const Linearization& l,
                                 StiffnessPart part, const double* p, double* out) {
        const double* u = lin_u(m, l);
        const double* t = lin_a(m, l);
        const double* zero = lin_b(m, l);
        const double* k = m.springs.stiffness;
        switch (part) {
            case StiffnessPart::kDamped:
                return springs::jacobian_product(m, u, k, zero, 0.0, 1.0, p, out);
            case StiffnessPart::kUndamped:
                return springs::jacobian_product(m, u, zero, t, 0.0, 1.0, p, out);
            case StiffnessPart::kWhole:
                return springs::jacobian_product(m, u, k, t, 0.0, 1.0, p, out);
            case StiffnessPart::kDamping:
                return springs::jacobian_product(m, u, k, zero, 1.0, 0.0, p, out);
        }
    }
    static void add_smoother_blocks(const Model& m, const Control&, const Linearization& l,
                                    const SmootherBlocks& s) {
        smoother_blocks(m, s.h, lin_u(m, l), lin_a(m, l), lin_b(m, l), s.entries.ptr,
                        s.entries.map, s.entries.coef, s.block);
    }
    /// Jacobi: h c + h^2 a (damping and axial stiffness) at both ends of every spring.
    static void add_jacobi_diagonal(const Model& m, const Control&, const Linearization& l,
                                    double h, double* diag) {
        const double* a = lin_a(m, l);
        for (index s = 0; s < m.springs.count; ++s) {
            const double d = h * m.springs.damping[s] + h * h * a[s];
            diag[m.springs.indices[2 * s]] += d;
            diag[m.springs.indices[2 * s + 1]] += d;
        }
    }
    static void project(const Model& m, const Control&, double h, const double* x,
                        const double* x0, double* rhs) {
        springs::project(m, h, x, x0, rhs);
    }
};

}  // namespace softbody::SOFTBODY_KERNELS::springs
