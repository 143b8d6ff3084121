// What every solver's time loop shares: the blow-up checks, the start of a run (collider
// start poses, pinned particles aimed at their targets) and the contacts that end a step
// (paper, step 5: soft-soft contacts, then rigid colliders, last, so that no particle ends a
// step inside a collider).
#pragma once

#include <vector>

#include "collision/colliders.hpp"
#include "collision/soft.hpp"
#include "collision/thick.hpp"
#include "collision/thick_system.hpp"
#include "model.hpp"
#include "simd.hpp"
#include "solvers/gas_state.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::loop {

/// A closed body whose volume is not finite and positive, or outside [ratio_min, ratio_max]
/// times its rest volume.
inline RunResult check_volumes(const Model& m, const double* volume, double ratio_min,
                               double ratio_max) {
    for (index b = 0; b < m.bodies.count; ++b) {
        if (m.bodies.closed[b] == 0) continue;  // an open surface encloses no volume
        const double v = volume[b];
        if (!(std::isfinite(v) && v > 0.0)) return {BAD_VOLUME, 0, b, v};
        const double r = v / m.bodies.rest_volume[b];
        if (r < ratio_min) return {SHRUNK, 0, b, r};
        if (r > ratio_max) return {EXPLODED, 0, b, r};
    }
    return {};
}

/// The first particle with a non-finite position or velocity, or faster than max_speed
/// [m/s]: a pass over the particles in order (check_particles runs it when one may fail).
inline RunResult first_bad_particle(const Model& m, const double* q, const double* qd,
                                    double max_speed) {
    const double limit = max_speed * max_speed;
    for (index i = 0; i < m.particles.count; ++i) {
        double s = 0.0;
        bool bad = false;
        for (int k = 0; k < 3; ++k) {
            if (!(std::isfinite(q[3 * i + k]) && std::isfinite(qd[3 * i + k]))) bad = true;
            s += qd[3 * i + k] * qd[3 * i + k];
        }
        if (bad) return {NONFINITE, 0, i, std::numeric_limits<double>::quiet_NaN()};
        if (s > limit) return {RUNAWAY, 0, i, std::sqrt(s)};
    }
    return {};
}

/// The particle checks after a filter: none can fail when no value was seen not finite and
/// 3 squares of the largest velocity component are within the limit (speed^2 <= 3 max
/// component^2); otherwise the exact pass decides.
inline RunResult check_seen(const Model& m, const double* q, const double* qd, double max_speed,
                            bool any_bad, double most) {
    if (!any_bad && 3.0 * most * most <= max_speed * max_speed) return {};
    return first_bad_particle(m, q, qd, max_speed);
}

/// A particle with a non-finite position or velocity, or faster than max_speed [m/s]. Every
/// step asks, and almost always none is: a first pass over the flat arrays, kLanes values
/// at a time with no early exit, finds whether any value is not finite (x - x is then not
/// 0) and the largest velocity component; only when one is not finite or 3 of its squares
/// could pass the limit does the exact pass run (speed^2 <= 3 max component^2).
inline RunResult check_particles(const Model& m, const double* q, const double* qd,
                                 double max_speed) {
    const index count = 3 * m.particles.count;
    vi bad{};
    vd largest{};
    index k = 0;
    for (; k + kLanes <= count; k += kLanes) {
        const vd x = load_lanes(q + k), v = load_lanes(qd + k);
        bad |= (x - x != 0.0) | (v - v != 0.0);
        const vd a = v < 0.0 ? -v : v;
        largest = a > largest ? a : largest;
    }
    bool any_bad = false;
    double most = 0.0;
    for (int l = 0; l < kLanes; ++l) {
        any_bad |= bad[l] != 0;
        most = std::max(most, largest[l]);
    }
    for (; k < count; ++k) {
        any_bad |= !(std::isfinite(q[k]) && std::isfinite(qd[k]));
        most = std::max(most, std::fabs(qd[k]));
    }
    return check_seen(m, q, qd, max_speed, any_bad, most);
}

inline void copy(const double* from, double* to, index count) {
    for (index k = 0; k < count; ++k) to[k] = from[k];
}

/// Before the first step: the colliders' start poses, and pinned particles' velocities to
/// reach their Control targets at the end of the run.
inline void begin_run(const Model& m, const Control& c, const RunParams& p, const StateView& s,
                      const ContactBuffers& w) {
    copy(s.collider_q, w.collider_q_start, 3 * m.colliders.count);
    if (!c.pin_active) return;
    const double inv = 1.0 / (static_cast<double>(p.steps) * p.dt);
    for (index k = 0; k < m.pins.count; ++k) {
        const index i = m.pins.particle[k];
        for (int d = 0; d < 3; ++d) s.qd[3 * i + d] = (c.pin_target[3 * k + d] - s.q[3 * i + d]) * inv;
    }
}

/// A crossing a mesh collider's edge contacts left (colliders::contacts' `crossed`: a soft
/// edge still through the mesh after their rounds, or with every particle pinned): w.crossing
/// says where (the first particle, mesh_collider::crossing_code); returns -1 (CROSSED).
inline index mesh_crossing(const index* crossed, const ContactBuffers& w) {
    w.crossing[0] = crossed[0];
    w.crossing[1] = crossed[1];
    return -1;
}

/// Whether no collider can catch a particle whose positions stay in the box [lo, hi] (world
/// frame; over a step whose every path, from q_start to the end, lies in it): at their
/// step's-end poses (cq (C, 3), crot (C, 3, 3)), a plane has the box's corners all on its
/// free side, a box container holds the box inside, a solid sphere or box does not meet it
/// (its world bounding box), and a mesh collider that does not move in the step (cv, cw
/// (C, 3) zero: its start pose is its end pose) has its tree root's bounds grown by its
/// margin, mapped to world, apart from it (a moving one is taken as near). Each test
/// keeps a room of 1e-9 of the box's extent for the round-off of the positions in it.
inline bool colliders_far(const Model& m, const double* cq, const double* crot, const double* cv,
                          const double* cw, const double* lo, const double* hi) {
    double extent = 0.0;
    for (int d = 0; d < 3; ++d)
        extent = std::max(extent, std::max(std::fabs(lo[d]), std::fabs(hi[d])));
    const double room = 1e-9 * (extent + 1.0);
    for (index k = 0; k < m.colliders.count; ++k) {
        const index kind = m.colliders.kind[k];
        const V3 c = load(cq, k), size = load(m.colliders.size, k);
        const double* r = crot + 9 * k;
        const V3 ax{r[0], r[3], r[6]}, ay{r[1], r[4], r[7]}, az{r[2], r[5], r[8]};
        auto corner = [&](int j) {
            return V3{(j & 1) ? hi[0] : lo[0], (j & 2) ? hi[1] : lo[1], (j & 4) ? hi[2] : lo[2]};
        };
        if (kind == ColliderKind::PLANE) {  // local +y is the normal
            for (int j = 0; j < 8; ++j)
                if (!(dot(corner(j) - c, ay) > room)) return false;
            continue;
        }
        if (kind == ColliderKind::BOX_CONTAINER) {
            for (int j = 0; j < 8; ++j) {
                const V3 d = corner(j) - c;
                if (!(std::fabs(dot(ax, d)) < size.x - room &&
                      std::fabs(dot(ay, d)) < size.y - room &&
                      std::fabs(dot(az, d)) < size.z - room))
                    return false;
            }
            continue;
        }
        // the collider's world box [a, b]
        double a[3], b[3];
        if (kind == ColliderKind::SPHERE) {
            for (int d = 0; d < 3; ++d) {
                a[d] = (&c.x)[d] - size.x;
                b[d] = (&c.x)[d] + size.x;
            }
        } else {
            V3 centre = c, half = size;
            if (kind == ColliderKind::MESH) {
                const index root = m.colliders.mesh_root[k];
                if (root < 0) continue;  // no mesh: it catches nothing
                for (int d = 0; d < 3; ++d)
                    if (cv[3 * k + d] != 0.0 || cw[3 * k + d] != 0.0) return false;
                const double* rb = m.collider_meshes.node_bounds + 6 * root;
                const double margin = m.colliders.mesh_margin[k];
                const V3 mid{0.5 * (rb[0] + rb[3]), 0.5 * (rb[1] + rb[4]), 0.5 * (rb[2] + rb[5])};
                centre = c + mid.x * ax + mid.y * ay + mid.z * az;
                half = V3{0.5 * (rb[3] - rb[0]) + margin, 0.5 * (rb[4] - rb[1]) + margin,
                          0.5 * (rb[5] - rb[2]) + margin};
            }
            for (int d = 0; d < 3; ++d) {
                const double reach = std::fabs(r[3 * d]) * half.x +
                                     std::fabs(r[3 * d + 1]) * half.y +
                                     std::fabs(r[3 * d + 2]) * half.z;
                a[d] = (&centre.x)[d] - reach;
                b[d] = (&centre.x)[d] + reach;
            }
        }
        bool apart = false;
        for (int d = 0; d < 3; ++d) apart |= a[d] > hi[d] + room || b[d] < lo[d] - room;
        if (!apart) return false;
    }
    return true;
}

/// The thickness contacts with rigid colliders (contacts() below, the colliders at their
/// step's-end poses). Where no collider can be involved (colliders_far, below) the stage
/// alone: the colliders would change nothing. There, where the step's motion would make
/// a stage without T sweep (a bound on its largest displacement over kMostSkin g / 2), the
/// stage with its common translation T, as without colliders (a body falling far above
/// the ground then finds no pair from its fall, and keeps its list; where the stage
/// without T keeps a list anyway, T spares no sweep, and the symplectic ball drop's fall
/// measured 20 % slower with it, more of its time in the list's gathers). The stage
/// moves a particle only along q0 + T + s u (u = q - q0 - T, s in [0, 1]: between
/// q0 + T and q) plus response moves of at most h / 2, so every position it leaves, and
/// every straight path from q0 to one (the colliders' continuous tests), lies in the box
/// of all particles' q0, q0 + T and q grown by h / 2 (a box is convex). Where that box is
/// apart from every collider (colliders_far: each collider's reach, a mesh's margin
/// included, outside it), the colliders catch no particle: they change nothing, and the
/// stage alone takes the step (a sweeping one with T: the no-collider path's step, to the
/// bit). Otherwise the stage first, on the solver's positions (its bound keeps
/// every pair from crossing along the step), without T: its bound then holds particles
/// back toward their start, outside the colliders, where q0 + T may lie inside one (a
/// sheet resting on the ground would follow a ball's fall onto it into the ground, be put
/// back by it, and leave the ball nearer than h to it).
/// Then the colliders; where they caught a particle, the stage again, from the same start,
/// holding the caught particles where the colliders left them (pinned for it: inverse
/// mass 0, their motion counted in full by its bound, so that no pair crosses along the
/// straight paths to those positions; its response moves the other side); then
/// the colliders again for the particles that second pass moved (only they: the others'
/// contacts were resolved, and a second response would apply their friction twice); and a
/// check that no edge now passes through a triangle near a particle that moved in the
/// contacts (thick_system::collider_crossing): the stage cannot hold back a caught
/// particle that a collider carried farther than its pairs' distances allow, nor see the
/// last push. The colliders acting last alone let a particle resting on one follow the
/// stage's T into it and be pushed back, unbounded, through a sheet falling onto it.
/// The momentum the second pass's response gives the free side (the particles it does not
/// hold) comes through the caught particles from the colliders holding them: each such
/// collider receives its opposite (Newton's third law; the stage's pairs among free
/// particles conserve momentum), so that the ground under a ball resting on a cloth
/// receives both weights. Shared among several catching colliders by the mass each caught
/// (exact for one, which holds all the caught particles; an apportionment for several, the
/// stage not telling which caught particle a free one pressed on).
/// Returns contacts()'s codes.
inline index thick_with_colliders(const Model& m, const RunParams& p, const StateView& s,
                                  const double* q_start, const ContactBuffers& w,
                                  colliders::Seen* seen) {
    const index n = m.particles.count, n3 = 3 * m.particles.count;
    // the stage translated where no collider can be involved: the box of every particle's
    // q_start, q_start + T and q, grown by h / 2, apart from every collider. One pass: the
    // box of the start positions and the box of the displacements d_i = q_i - q_start_i
    // with 0; their sum (Minkowski) holds q_start_i + 0, q_start_i + T (T, a mean of the
    // bodies' d_i, lies in their box) and q_i = q_start_i + d_i.
    const double inf = std::numeric_limits<double>::infinity();
    double lo[3] = {inf, inf, inf}, hi[3] = {-inf, -inf, -inf};
    double lo_d[3] = {0.0, 0.0, 0.0}, hi_d[3] = {0.0, 0.0, 0.0};
    for (index k = 0; k < n3; k += 3)
        for (int d = 0; d < 3; ++d) {
            const double a = q_start[k + d], u = s.q[k + d] - a;
            lo[d] = std::min(lo[d], a);
            hi[d] = std::max(hi[d], a);
            lo_d[d] = std::min(lo_d[d], u);
            hi_d[d] = std::max(hi_d[d], u);
        }
    const double grow = 0.5 * m.soft_contacts.thickness;
    for (int d = 0; d < 3; ++d) {
        lo[d] += lo_d[d] - grow;
        hi[d] += hi_d[d] + grow;
    }
    double reach = 0.0;  // a bound on the largest |d_i|: the stage's mu without T
    for (int d = 0; d < 3; ++d) {
        const double e = std::max(-lo_d[d], hi_d[d]);
        reach += e * e;
    }
    const bool sweeps = std::sqrt(reach) > 0.5 * thick::kMostSkin * m.soft_contacts.margin;
    const bool far = n > 0 && colliders_far(m, s.collider_q, s.collider_rot, w.collider_v,
                                            w.collider_w, lo, hi);
    // near a collider, the stage's swept gather grown by a slack of h / 16 (Stage::slack), so
    // that the second pass below takes its pairs from its rows where each particle stays
    // within that of its path from q_start to the solver's q (reuse_swept: the others' pairs
    // gathered again). The first pass's bound leaves a particle on its path, its response
    // moves a few up to h / 2 off it, the colliders move the caught ones: at the implicit
    // ball drop's impact about 0.5 % of the particles end more than h / 20 off (3 in
    // 10,242 more than h / 5), while each h of slack would add half the pairs again
    const double slack = far ? 0.0 : m.soft_contacts.thickness / 16.0;
    w.list[1] = -1;  // no rows of this step yet
    if (!far) copy(s.q, w.q_solved, n3);  // for the second pass and the crossing check
    index needed = thick::contacts(m, q_start, s.q, s.qd, w, far && sweeps, p.dt, slack);
    // far from every collider they catch nothing: the step is the stage's alone
    if (needed != 0 || far) return needed;
    copy(s.q, w.q_collided, n3);
    index crossed[2] = {-1, -1};
    // the mass each collider caught, to share the second pass's reaction among several
    std::vector<double> caught_mass(m.colliders.count > 1 ? m.colliders.count : 0, 0.0);
    colliders::contacts(m, s.collider_q, s.collider_rot, w.collider_v, w.collider_w, q_start,
                        s.q, s.qd, s.collider_impulse, seen, p.dt, crossed, w.q_collided,
                        caught_mass.empty() ? nullptr : caught_mass.data());
    if (crossed[0] >= 0) return mesh_crossing(crossed, w);
    auto moved = [](const double* a, const double* b, index i) {
        return a[3 * i] != b[3 * i] || a[3 * i + 1] != b[3 * i + 1] || a[3 * i + 2] != b[3 * i + 2];
    };
    bool caught = false;
    for (index i = 0; i < n; ++i) {
        const bool mine = moved(s.q, w.q_collided, i);
        w.held_inv_mass[i] = mine ? 0.0 : m.particles.inv_mass[i];
        caught |= mine;
    }
    if (!caught) return 0;
    Model held = m;
    held.particles.inv_mass = w.held_inv_mass;
    copy(s.q, w.q_collided, n3);
    auto free_momentum = [&] {  // of the particles the second pass does not hold [kg m/s]
        V3 sum{0.0, 0.0, 0.0};
        for (index i = 0; i < n; ++i)
            if (w.held_inv_mass[i] > 0.0) sum = sum + m.particles.mass[i] * load(s.qd, i);
        return sum;
    };
    const V3 before = free_momentum();
    needed = thick::contacts(held, q_start, s.q, s.qd, w, false, p.dt, slack,
                             far ? nullptr : w.q_solved);
    if (needed != 0) return needed;
    const V3 given = free_momentum() - before;  // through the caught particles
    if (caught_mass.empty()) {
        add_to(s.collider_impulse, 0, -1.0 * given);
    } else {
        double total = 0.0;
        for (const double c : caught_mass) total += c;
        for (index k = 0; k < m.colliders.count && total > 0.0; ++k)
            add_to(s.collider_impulse, k, (-caught_mass[k] / total) * given);
    }
    bool any = false;  // the colliders again, for the particles the second pass moved
    for (index i = 0; i < n; ++i) {
        const bool mine = moved(s.q, w.q_collided, i);
        w.held_inv_mass[i] = mine ? m.particles.inv_mass[i] : 0.0;
        any |= mine;
    }
    if (any)
        colliders::contacts(held, s.collider_q, s.collider_rot, w.collider_v, w.collider_w,
                            q_start, s.q, s.qd, s.collider_impulse, seen, p.dt);
    return thick_system::collider_crossing(m, s.q, w.q_solved, w) ? -1 : 0;
}

/// Contacts at the end of step `step` (of p.steps, ending at time t [s]); q_start (N, 3) is
/// the step's start positions (continuous collider detection, the thickness contacts' bound).
/// Returns 0, or the spatial-hash entries surface soft contacts need when their buffer could
/// not grow to them: then the colliders have moved but no contact was resolved, and the caller
/// undoes the step; or -1 when the thickness contacts found a crossing at the step's start,
/// or the colliders pushed an edge through a triangle, or a mesh collider's edge contacts
/// left a crossing (w.crossing says where; contact_failure makes any of them a RunResult).
inline index contacts(const Model& m, const Control& c, const RunParams& p, index step, double t,
                      const StateView& s, const double* q_start, const ContactBuffers& w,
                      colliders::Seen* seen = nullptr) {
    if (m.colliders.count > 0) {
        const double fraction = (static_cast<double>(step) + 1.0) / static_cast<double>(p.steps);
        colliders::poses(m, c, fraction, static_cast<double>(p.steps) * p.dt, t,
                         w.collider_q_start, s.collider_q, s.collider_rot, w.collider_v,
                         w.collider_w);
    }
    if (m.soft_contacts.mode == SoftContactMode::BOUNDING) {
        soft::contacts_bounding(m, s.q, s.qd, w);
    } else if (m.soft_contacts.mode == SoftContactMode::SURFACE && m.soft_contacts.thickness > 0.0) {
        if (m.colliders.count > 0) return thick_with_colliders(m, p, s, q_start, w, seen);
        const index needed = thick::contacts(m, q_start, s.q, s.qd, w, true, p.dt);
        if (needed != 0) return needed;
    } else if (m.soft_contacts.mode == SoftContactMode::SURFACE) {
        const index needed = soft::contacts_surface(m, s.q, s.qd, w);
        if (needed > 0) return needed;
    }
    if (m.colliders.count > 0) {
        index crossed[2] = {-1, -1};
        colliders::contacts(m, s.collider_q, s.collider_rot, w.collider_v, w.collider_w, q_start,
                            s.q, s.qd, s.collider_impulse, seen, p.dt, crossed);
        if (crossed[0] >= 0) return mesh_crossing(crossed, w);
    }
    return 0;
}

/// The run's outcome when contacts() returned `needed` != 0 at step `step`: NEED_HASH (value:
/// the entries needed), NEED_PAIRS (the thickness contacts' pair list; value: the pairs
/// needed), or CROSSED (where: the edge's particle, value: the triangle).
inline RunResult contact_failure(index needed, index step, const ContactBuffers& w) {
    if (needed < 0) return {CROSSED, step, w.crossing[0], static_cast<double>(w.crossing[1])};
    if (w.list != nullptr && w.list[2] == 1) return {NEED_PAIRS, step, -1, static_cast<double>(needed)};
    return {NEED_HASH, step, -1, static_cast<double>(needed)};
}

/// The end of step `step` (from t to t + p.dt) every solver shares: contacts, then the
/// particle checks. When the spatial hash needs more room (NEED_HASH, with the entries
/// needed) or a particle failed, the state goes back to the step's start (q0, v0) and the
/// result says so; otherwise OK.
inline RunResult end_step(const Model& m, const Control& c, const RunParams& p, index step,
                          double t, const StateView& s, const double* q0, const double* v0,
                          const ContactBuffers& w) {
    const index n3 = 3 * m.particles.count;
    const index needed = contacts(m, c, p, step, t + p.dt, s, q0, w);
    RunResult r = needed != 0 ? contact_failure(needed, step, w)
                              : check_particles(m, s.q, s.qd, p.max_speed);
    if (r.status != OK) {
        copy(q0, s.q, n3);
        copy(v0, s.qd, n3);
        r.steps_done = step;
    }
    return r;
}

/// A whole run, every solver's frame around its steps: the run's start (begin_run), the
/// gas state from the state's temperatures (gas_state::begin), `steps()` (a RunResult:
/// the solver's time loop), then the state's temperatures and scheduled amounts at the
/// time the steps reached (gas_state::finish).
template <class Steps>
inline RunResult run(const Model& m, const Control& c, const RunParams& p, const StateView& s,
                     const ContactBuffers& contact, const BodyGas& gas, Steps steps) {
    begin_run(m, c, p, s, contact);
    gas_state::begin(m, s.q, s, gas);
    const RunResult r = steps();
    gas_state::finish(m, p.time_at(r.steps_done), s.q, s, gas);
    return r;
}

}  // namespace softbody::SOFTBODY_KERNELS::loop
