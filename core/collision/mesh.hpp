// Mesh colliders: any closed, outward-wound triangle mesh as a rigid collider, particles
// against its triangles. The triangles are stored in the collider's local frame (its pose
// is the collider's centre and rotation) with a bounding-volume tree over them, built once
// in Python (softbody.collision.mesh_collider). Per particle and step:
//   1. continuous: the particle's path of this step relative to the collider (from its start
//      position in the collider's frame at the step's start to its end position in the frame
//      at the step's end) is traced through the tree; the first triangle it enters through
//      (from the front) catches it, even where the path went on through a thin part;
//   2. otherwise an inside test at the end position: the closest point on the mesh, and the
//      sign of the offset against the angle-weighted pseudo-normal of the closest feature
//      (face, edge or vertex; Baerentzen & Aanaes 2005) says inside. The search is bounded
//      by the path's length plus the margin (a point it cannot reach is farther from the
//      surface than its path: outside, unless it started inside); beyond that bound a ray's
//      crossing parity decides, so a vertex deep inside (placed there) is still pushed out. A particle outside but
//      within the margin of the surface and approaching it is a resting contact: caught too
//      (so that a body at rest feels the friction every step, as on the analytic colliders).
// A caught particle goes to the surface point plus `margin` along the contact normal (so
// that its next path starts strictly outside) and responds as against the analytic
// colliders (colliders::respond): restitution, friction, the opposite impulse to the
// collider.
// Then edge contacts, so that no soft edge passes through the mesh and no mesh edge through a
// soft triangle while every soft vertex stays outside (edge_contacts below), at the step's
// end positions, in the collider's frame, after the vertex contacts. The mesh's edges are
// flagged once in Python (collider_mesh_sharp_edges): sharp (convex, faces more than
// sharp_angle apart: a box's edges), bent (any other edge not flat), or neither (a flat
// face's tessellation; or the edge contacts off). Per soft triangle, one walk of the tree
// finds the mesh triangles near its box and within the margin of its plane; those wholly on
// one side of its plane can be neither cut by its edges nor reach through it (a flagged
// sharp edge still meets its resting contacts). Three tests:
//   1. ridges: the triangle's edges (each soft edge once) against the sharp edges found
//      (those whose box meets the triangle's box): a soft edge that passes through one of
//      the sharp edge's two faces with its closest point to the edge inside the edge's wedge
//      (behind both faces), along the edge's length (not past its ends, where the common
//      perpendicular runs along the edge's line, far from the surface) and below the edge
//      (the common perpendicular in the cone of the two face normals: on a nearly flat edge
//      it may run along the surface) is pushed out along the two edges' common
//      perpendicular to `margin` beyond the edge; one resting on the edge within the margin
//      (in the cone of its two face normals) and approaching it is held there.
//   2. corners and caps: a sharp or bent edge through the soft triangle whose end projects
//      into the triangle and lies beyond it (along the end's pseudo-normal) pushes the
//      triangle past that end by the margin; repeated (up to kRounds) while one did, since a
//      smooth surface's cap through a large soft triangle may hold vertices that no crossing
//      edge ends at.
//   3. chords: the triangle's edges against the faces found (segment-triangle; again
//      through the tree once something moved them): a soft edge whose ends are outside but
//      which passes through the surface cuts a chord, across a smooth patch as across a
//      ridge, whatever the edges' angles. Between successive crossings the points at 1/4,
//      1/2 and 3/4 are tested with the inside test above; the deepest goes to its closest
//      surface point plus the margin (along the direction to it; on its first push taken
//      back along its path, below), and the edge is tested again (up to kRounds). A flat
//      face cannot be cut between two outside vertices, and a chord under a concave edge
//      alone cannot exist (a straight segment entering a valley leaves it on the inside), so
//      2 with the bent edges and 3 with the faces test for every crossing the two surfaces
//      can have.
// The soft side moves with barycentric weights w_k, mass-weighted (particle k by w_k / m_k /
// sum_l w_l^2 / m_l times the contact point's move, cut where pinned particles carry most of
// the weight: push()), and the contact point's velocity relative to the collider takes
// restitution and friction as a vertex's does; the collider receives the opposite impulse.
// A ridge's, a cap's or a chord's first push of a step puts the contact point where its path
// of the step crossed the level it is pushed to, as a vertex goes back to where its path
// entered: so a sheet resting on a smooth mesh's corners and chords is held where it rests,
// as one resting on the mesh's faces by its vertices. Such a move runs along the surface and may carry a neighbouring soft
// edge, already cleared, back through it (pushed straight out, a contact only lifts its
// particles): after the pass, every soft triangle at a particle so moved (by more than a
// quarter of the margin, summed over the step's held pushes) is treated again, with
// straight pushes only (the balloon-ring scene's ring was otherwise cut).
// Concave edges take part only in 2.
#pragma once

#include <algorithm>
#include <limits>
#include <vector>

#include "collision/colliders.hpp"
#include "collision/soft.hpp"
#include "collision/thick.hpp"
#include "model.hpp"
#include "vec.hpp"

namespace softbody::SOFTBODY_KERNELS::mesh_collider {

constexpr int kStack = 96;  // tree depth bound; the median split keeps it near log2(T)

/// R^T d: a world vector d in the frame whose axes are the columns of r (3, 3).
inline V3 to_local(const double* r, V3 d) {
    return {r[0] * d.x + r[3] * d.y + r[6] * d.z, r[1] * d.x + r[4] * d.y + r[7] * d.z,
            r[2] * d.x + r[5] * d.y + r[8] * d.z};
}

/// R l: a local vector l in world coordinates.
inline V3 to_world(const double* r, V3 l) {
    return {r[0] * l.x + r[1] * l.y + r[2] * l.z, r[3] * l.x + r[4] * l.y + r[5] * l.z,
            r[6] * l.x + r[7] * l.y + r[8] * l.z};
}

inline V3 unit(V3 a) {
    const double n = std::sqrt(dot(a, a));
    return n > 0.0 ? (1.0 / n) * a : a;
}

/// Squared distance from p to the box [lo, hi].
inline double box_distance2(const double* b, V3 p) {
    double d2 = 0.0;
    for (int k = 0; k < 3; ++k) {
        const double x = (&p.x)[k];
        const double e = x < b[k] ? b[k] - x : (x > b[3 + k] ? x - b[3 + k] : 0.0);
        d2 += e * e;
    }
    return d2;
}

/// Whether the segment a + s (b - a), s in [0, s_max], meets the box [lo, hi] (slabs).
inline bool segment_meets_box(const double* box, V3 a, V3 b, double s_max) {
    double s0 = 0.0, s1 = s_max;
    for (int k = 0; k < 3; ++k) {
        const double o = (&a.x)[k], d = (&b.x)[k] - o, lo = box[k], hi = box[3 + k];
        if (d == 0.0) {
            if (o < lo || o > hi) return false;
            continue;
        }
        double t0 = (lo - o) / d, t1 = (hi - o) / d;
        if (t0 > t1) std::swap(t0, t1);
        s0 = std::max(s0, t0);
        s1 = std::min(s1, t1);
        if (s0 > s1) return false;
    }
    return true;
}

/// Closest point to p on triangle (a, b, c) (Ericson, Real-Time Collision Detection 5.1.5),
/// and its feature: 0, 1, 2 a corner; 3, 4, 5 the edge from corner k - 3 to the next; 6 the
/// face.
inline V3 closest_on_triangle(V3 p, V3 a, V3 b, V3 c, int& feature) {
    const V3 ab = b - a, ac = c - a, ap = p - a;
    const double d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0.0 && d2 <= 0.0) return feature = 0, a;
    const V3 bp = p - b;
    const double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0.0 && d4 <= d3) return feature = 1, b;
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
        feature = 3;
        return a + (d1 / (d1 - d3)) * ab;
    }
    const V3 cp = p - c;
    const double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0.0 && d5 <= d6) return feature = 2, c;
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
        feature = 5;
        return a + (d2 / (d2 - d6)) * ac;
    }
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
        feature = 4;
        return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
    }
    const double denom = 1.0 / (va + vb + vc);
    feature = 6;
    return a + (vb * denom) * ab + (vc * denom) * ac;
}

/// One mesh collider's arrays (rows of the model's collider_meshes part).
struct View {
    const Model& m;
    V3 vertex(index v) const { return load(m.collider_meshes.vertices, v); }
    V3 corner(index t, int k) const {
        return vertex(m.collider_meshes.triangles[3 * t + k]);
    }
    const double* bounds(index node) const { return m.collider_meshes.node_bounds + 6 * node; }
    index begin(index node) const { return m.collider_meshes.node_tris[2 * node]; }
    index end(index node) const { return m.collider_meshes.node_tris[2 * node + 1]; }
    index child(index node, int k) const { return m.collider_meshes.node_children[2 * node + k]; }
    /// The triangle across edge k of triangle t when that edge is sharp (convex, owned by
    /// t); -2 when it is bent but not sharp (owned by t); -1 otherwise.
    index sharp_twin(index t, int k) const { return m.collider_meshes.sharp_edges[3 * t + k]; }
    /// Whether edge k of triangle t takes part in edge contacts (sharp or bent, owned by t).
    bool takes_part(index t, int k) const { return sharp_twin(t, k) != -1; }
    /// Whether a tree node's triangles hold an edge that takes part in edge contacts.
    bool has_sharp(index node) const { return m.collider_meshes.node_sharp[node] != 0; }
    V3 face_normal(index t) const {
        return unit(cross(corner(t, 1) - corner(t, 0), corner(t, 2) - corner(t, 0)));
    }
    /// The pseudo-normal of feature f of triangle t (closest_on_triangle's numbering).
    V3 pseudo_normal(index t, int f) const {
        if (f < 3) return load(m.collider_meshes.vertex_normals, m.collider_meshes.triangles[3 * t + f]);
        if (f < 6) return load(m.collider_meshes.edge_normals, 3 * t + (f - 3));
        return unit(cross(corner(t, 1) - corner(t, 0), corner(t, 2) - corner(t, 0)));
    }
};

struct Nearest {
    double d2 = std::numeric_limits<double>::infinity();
    V3 x{0.0, 0.0, 0.0};  // closest point on the mesh
    V3 n{0.0, 0.0, 0.0};  // pseudo-normal of its feature
};

/// The closest point on the mesh below `root` to p (local frame), with its pseudo-normal,
/// among those nearer than sqrt(bound2); none (d2 = bound2) when there is none.
inline Nearest nearest(const View& v, index root, V3 p,
                       double bound2 = std::numeric_limits<double>::infinity()) {
    Nearest best;
    best.d2 = bound2;
    index stack[kStack];
    int top = 0;
    stack[top++] = root;
    while (top > 0) {
        const index node = stack[--top];
        if (box_distance2(v.bounds(node), p) >= best.d2) continue;
        const index b = v.begin(node), e = v.end(node);
        if (e > b) {
            for (index t = b; t < e; ++t) {
                int f = 6;
                const V3 x = closest_on_triangle(p, v.corner(t, 0), v.corner(t, 1), v.corner(t, 2), f);
                const V3 d = p - x;
                const double d2 = dot(d, d);
                if (d2 < best.d2) best = {d2, x, v.pseudo_normal(t, f)};
            }
            continue;
        }
        if (top + 2 > kStack) continue;  // deeper than any tree the builder makes
        const index l = v.child(node, 0), r = v.child(node, 1);
        // the nearer child last, so that it is searched first
        if (box_distance2(v.bounds(l), p) < box_distance2(v.bounds(r), p)) {
            stack[top++] = r;
            stack[top++] = l;
        } else {
            stack[top++] = l;
            stack[top++] = r;
        }
    }
    return best;
}

/// The first triangle the segment a -> b enters through its front (against its outward
/// normal): the fraction s in [0, 1] along it, and the triangle's unit normal; s > 1: none.
inline double first_entry(const View& v, index root, V3 a, V3 b, V3& normal) {
    double s_best = 2.0;
    const V3 d = b - a;
    index stack[kStack];
    int top = 0;
    stack[top++] = root;
    while (top > 0) {
        const index node = stack[--top];
        if (!segment_meets_box(v.bounds(node), a, b, std::min(s_best, 1.0))) continue;
        const index tb = v.begin(node), te = v.end(node);
        if (te > tb) {
            for (index t = tb; t < te; ++t) {
                const V3 p0 = v.corner(t, 0), e1 = v.corner(t, 1) - p0, e2 = v.corner(t, 2) - p0;
                const V3 n = cross(e1, e2);
                const double dn = dot(d, n);
                if (!(dn < 0.0)) continue;  // parallel, or leaving through it
                // Moller-Trumbore, edges included (a path through an edge meets one of its
                // triangles)
                const V3 h = cross(d, e2);
                const double det = dot(e1, h);
                if (det == 0.0) continue;
                const double inv = 1.0 / det;
                const V3 sv = a - p0;
                const double u = inv * dot(sv, h);
                constexpr double kTol = 1e-9;
                if (u < -kTol || u > 1.0 + kTol) continue;
                const V3 qv = cross(sv, e1);
                const double w = inv * dot(d, qv);
                if (w < -kTol || u + w > 1.0 + kTol) continue;
                const double s = inv * dot(e2, qv);
                if (s < 0.0 || s > 1.0 || s >= s_best) continue;
                s_best = s;
                normal = unit(n);
            }
            continue;
        }
        if (top + 2 > kStack) continue;
        stack[top++] = v.child(node, 0);
        stack[top++] = v.child(node, 1);
    }
    return s_best;
}

/// Whether p lies inside the closed mesh, by the parity of the crossings of a ray from p
/// to `far` (outside the mesh's box); -1 when it passed within round-off of an edge (the
/// caller tries another direction).
inline int inside_by_ray(const View& v, index root, V3 p, V3 far) {
    const V3 d = far - p;
    int crossings = 0;
    index stack[kStack];
    int top = 0;
    stack[top++] = root;
    while (top > 0) {
        const index node = stack[--top];
        if (!segment_meets_box(v.bounds(node), p, far, 1.0)) continue;
        const index tb = v.begin(node), te = v.end(node);
        if (te > tb) {
            for (index t = tb; t < te; ++t) {
                const V3 p0 = v.corner(t, 0), e1 = v.corner(t, 1) - p0, e2 = v.corner(t, 2) - p0;
                const V3 h = cross(d, e2);
                const double det = dot(e1, h);
                if (std::fabs(det) < 1e-300) continue;
                const double inv = 1.0 / det;
                const V3 sv = p - p0;
                const double u = inv * dot(sv, h);
                const V3 qv = cross(sv, e1);
                const double w = inv * dot(d, qv);
                const double s = inv * dot(e2, qv);
                if (s <= 0.0 || s > 1.0) continue;
                constexpr double kEdge = 1e-9;
                if (u < -kEdge || w < -kEdge || u + w > 1.0 + kEdge) continue;
                if (u < kEdge || w < kEdge || u + w > 1.0 - kEdge) return -1;  // on an edge
                ++crossings;
            }
            continue;
        }
        if (top + 2 > kStack) continue;
        stack[top++] = v.child(node, 0);
        stack[top++] = v.child(node, 1);
    }
    return crossings % 2;
}

/// Where a particle whose path in the collider's frame went from l0 to l1 must be (local
/// frame): hit.x on the surface plus margin along hit.n (unit, outward), or no hit. `band`:
/// the particle is outside but nearer the surface than the margin (a resting contact: the
/// caller responds only when it approaches).
inline colliders::Hit resolve(const View& v, index root, double margin, V3 l0, V3 l1,
                              bool& band) {
    colliders::Hit out;
    band = false;
    const double* b = v.bounds(root);
    const double box[6] = {b[0] - margin, b[1] - margin, b[2] - margin,
                           b[3] + margin, b[4] + margin, b[5] + margin};
    if (!segment_meets_box(box, l0, l1, 1.0)) return out;  // far from the mesh
    V3 n{0.0, 0.0, 0.0};
    const double s = first_entry(v, root, l0, l1, n);
    V3 p = l1;
    if (s <= 1.0) {
        p = l0 + s * (l1 - l0) + margin * n;
        out = {true, p, n};
    }
    // the end position (or the entry point put outside) must be outside and at least the
    // margin away: else to the closest point of the surface plus the margin
    if (p.x < box[0] || p.y < box[1] || p.z < box[2] || p.x > box[3] || p.y > box[4] ||
        p.z > box[5])
        return out;
    // A point outside within reach of its path's length (plus the margin band) of the
    // surface, or inside, is found by the nearest-point search bounded by that reach: a
    // path from outside to inside crossed the surface within it. Past the reach, a ray's
    // parity says whether the point is (deep) inside; only then the unbounded search.
    const double reach = std::sqrt(dot(l1 - l0, l1 - l0)) + 4.0 * margin;
    Nearest near = nearest(v, root, p, reach * reach);
    if (!(near.d2 < reach * reach)) {
        // rays out of the box by its nearest sides (short rays meet few nodes), each a little
        // off the axis so that it does not run along the mesh's axis-aligned edges
        double exit[6];
        for (int k = 0; k < 3; ++k) {
            exit[2 * k] = b[3 + k] - (&p.x)[k];
            exit[2 * k + 1] = (&p.x)[k] - b[k];
        }
        const double pad = margin + 1e-3 * std::sqrt(dot(V3{b[3] - b[0], b[4] - b[1], b[5] - b[2]},
                                                         V3{b[3] - b[0], b[4] - b[1], b[5] - b[2]}));
        int in = -1;
        bool tried[6] = {false, false, false, false, false, false};
        for (int attempt = 0; attempt < 3 && in < 0; ++attempt) {
            int side = -1;
            for (int k = 0; k < 6; ++k)
                if (!tried[k] && (side < 0 || exit[k] < exit[side])) side = k;
            tried[side] = true;
            const int axis = side / 2;
            V3 dir{0.0123, 0.0317, 0.0211};
            (&dir.x)[axis] = side % 2 == 0 ? 1.0 : -1.0;
            in = inside_by_ray(v, root, p, p + (exit[side] + 2.0 * pad) * dir);
        }
        if (in == 0) return out;
        near = nearest(v, root, p);
    }
    const V3 off = p - near.x;
    const bool inside = dot(off, near.n) < 0.0;
    if (!inside && !(near.d2 < margin * margin)) return out;
    const double dist = std::sqrt(near.d2);
    const double sign = inside ? -1.0 : 1.0;
    const V3 normal = dist > 0.0 ? (sign / dist) * off : near.n;
    band = !inside && !out.hit;
    return {true, near.x + margin * normal, normal};
}

/// Whether the boxes [lo, hi] and b (lo, hi) meet.
inline bool boxes_meet(const double* lo, const double* hi, const double* b) {
    for (int k = 0; k < 3; ++k)
        if (hi[k] < b[k] || b[3 + k] < lo[k]) return false;
    return true;
}

/// Whether the box b (lo, hi) lies wholly farther than `reach` from the plane through x
/// with normal n (not unit: reach is in units of |n| m).
inline bool box_beside_plane(const double* b, V3 x, V3 n, double reach) {
    const V3 centre{0.5 * (b[0] + b[3]), 0.5 * (b[1] + b[4]), 0.5 * (b[2] + b[5])};
    const double spread = 0.5 * ((b[3] - b[0]) * std::fabs(n.x) + (b[4] - b[1]) * std::fabs(n.y) +
                                 (b[5] - b[2]) * std::fabs(n.z));
    return std::fabs(dot(centre - x, n)) > spread + reach;
}

/// Each leaf of the tree below `root` whose box meets the box [lo, hi] (local frame) and
/// comes within `reach` of the plane through x with normal n (reach in units of |n| m):
/// calls visit(begin, end) with its triangle rows. `all` false: only the subtrees holding an
/// edge that takes part in edge contacts (flat tessellation costs nothing).
template <class Visit>
inline void each_leaf(const View& v, index root, const double* lo, const double* hi, V3 x, V3 n,
                      double reach, bool all, Visit visit) {
    index stack[kStack];
    int top = 0;
    stack[top++] = root;
    while (top > 0) {
        const index node = stack[--top];
        if ((!all && !v.has_sharp(node)) || !boxes_meet(lo, hi, v.bounds(node)) ||
            box_beside_plane(v.bounds(node), x, n, reach))
            continue;
        const index tb = v.begin(node), te = v.end(node);
        if (te > tb) {
            visit(tb, te);
            continue;
        }
        if (top + 2 > kStack) continue;
        stack[top++] = v.child(node, 0);
        stack[top++] = v.child(node, 1);
    }
}

/// Whether the box of the segment a-b meets the box [lo, hi].
inline bool segment_box_meets(V3 a, V3 b, const double* lo, const double* hi) {
    for (int d = 0; d < 3; ++d)
        if (std::max((&a.x)[d], (&b.x)[d]) < lo[d] || hi[d] < std::min((&a.x)[d], (&b.x)[d]))
            return false;
    return true;
}

/// Whether segment a-b meets triangle (p0, p1, p2), its edges included (Moller-Trumbore
/// with a tolerance: a soft edge through the sharp edge itself meets both its faces); s: the
/// fraction along a-b where it does.
inline bool segment_meets_triangle(V3 a, V3 b, V3 p0, V3 p1, V3 p2, double& s) {
    const V3 d = b - a, e1 = p1 - p0, e2 = p2 - p0;
    const V3 h = cross(d, e2);
    const double det = dot(e1, h);
    if (!(std::fabs(det) > 1e-300)) return false;
    const double inv = 1.0 / det;
    const V3 sv = a - p0;
    const double u = inv * dot(sv, h);
    const V3 qv = cross(sv, e1);
    const double w = inv * dot(d, qv);
    s = inv * dot(e2, qv);
    constexpr double kTol = 1e-9;
    return u >= -kTol && w >= -kTol && u + w <= 1.0 + kTol && s >= 0.0 && s <= 1.0;
}

inline bool segment_meets_triangle(V3 a, V3 b, V3 p0, V3 p1, V3 p2) {
    double s = 0.0;
    return segment_meets_triangle(a, b, p0, p1, p2, s);
}

constexpr double kFreeWeight = 0.25;  // push(): below it, the free particles' share is cut
constexpr int kCrossings = 16;  // most crossings of one soft edge through the mesh kept
constexpr int kRounds = 4;      // most pushes of one soft edge (chords) or triangle (caps)
// held pushes' take-back of a particle [margins] up to which its soft triangles are not
// treated again: moved along the surface by less, an edge whose chord was pushed out to the
// margin stays outside
constexpr double kDragged = 0.25;

/// Adds s to the ascending list s_out of count entries (at most kCrossings: then dropped).
inline void add_crossing(double* s_out, int& count, double s) {
    if (count >= kCrossings) return;
    int at = count++;
    while (at > 0 && s_out[at - 1] > s) {
        s_out[at] = s_out[at - 1];
        --at;
    }
    s_out[at] = s;
}

/// Adds to the ascending list s_out (count entries) the fractions along segment a-b (local
/// frame) where it passes through triangles tb..te of the mesh (segment_meets_triangle: a
/// segment through an edge is listed once per triangle).
inline void leaf_crossings(const View& v, index tb, index te, V3 a, V3 b, double* s_out,
                           int& count) {
    for (index t = tb; t < te; ++t) {
        double s = 0.0;
        if (segment_meets_triangle(a, b, v.corner(t, 0), v.corner(t, 1), v.corner(t, 2), s))
            add_crossing(s_out, count, s);
    }
}

/// The fractions s along segment a-b (local frame) where it passes through a triangle of
/// the mesh below `root`, ascending, at most kCrossings of them; returns how many.
inline int segment_crossings(const View& v, index root, V3 a, V3 b, double* s_out) {
    int count = 0;
    index stack[kStack];
    int top = 0;
    stack[top++] = root;
    while (top > 0) {
        const index node = stack[--top];
        if (!segment_meets_box(v.bounds(node), a, b, 1.0)) continue;
        const index tb = v.begin(node), te = v.end(node);
        if (te > tb) {
            leaf_crossings(v, tb, te, a, b, s_out, count);
            continue;
        }
        if (top + 2 > kStack) continue;
        stack[top++] = v.child(node, 0);
        stack[top++] = v.child(node, 1);
    }
    return count;
}

/// The deepest point inside the mesh of the segment a-b (local frame) whose crossings of the
/// surface are s (count of them, ascending): between each two successive crossings, the
/// points at 1/4, 1/2 and 3/4 of the way, the one farthest inside (by the nearest feature's
/// pseudo-normal, as the vertex contacts' inside test). Returns its fraction along a-b (-1
/// when no sample is inside: a graze) and its nearest surface point `near`.
inline double deepest_inside(const View& v, index root, V3 a, V3 b, const double* s, int count,
                             Nearest& near) {
    double best_s = -1.0, best_d2 = 0.0;
    for (int k = 0; k + 1 < count; ++k) {
        for (int q = 1; q <= 3; ++q) {
            const double f = s[k] + 0.25 * q * (s[k + 1] - s[k]);
            const V3 x = a + f * (b - a);
            const Nearest at = nearest(v, root, x);
            if (!(dot(x - at.x, at.n) < 0.0) || !(at.d2 > best_d2)) continue;  // outside
            best_s = f;
            best_d2 = at.d2;
            near = at;
        }
    }
    return best_s;
}

/// The CROSSED result's value for a crossing the edge contacts leave (a chord still through
/// after kRounds pushes or with both ends pinned; a cap likewise): -1 - T - code, below the
/// thickness contacts' -1 - triangle (softbody.sim.simulator decodes it), with code =
/// 2 (k S + x) + kind, S = max(N, T): kind 0 a soft edge (x its second particle; the result's
/// `where` its first), kind 1 a soft triangle (x the triangle; `where` its first corner);
/// k the collider.
inline index crossing_code(const Model& m, index k, index x, bool triangle) {
    const index span = std::max(m.particles.count, m.triangles.count);
    return -1 - m.triangles.count - (2 * (k * span + x) + (triangle ? 1 : 0));
}

/// A mesh collider's pose, velocities and coefficients at the step's end.
struct Frame {
    const Model& m;
    V3 c;             // the collider's centre [m]
    const double* r;  // its rotation (3, 3)
    V3 vc, wc;        // its velocity [m/s] and angular velocity [rad/s]
    double e, keep;   // restitution, 1 - friction
    // the positions (N, 3) at the step's start and the collider's pose then (push(): where
    // a contact point's path crossed the level it goes to); none: straight out
    const double* q_start = nullptr;
    V3 c0{0.0, 0.0, 0.0};
    const double* r0 = nullptr;
};

/// The soft side of one edge or corner contact: particles idx[0..n) with barycentric
/// weights w (n) at the contact point x_local, local positions l (n, updated). The contact
/// point moves by `move` (local frame), and its velocity relative to the collider, when
/// approaching along the unit normal (local), takes restitution and friction. Returns false
/// (nothing changed) when every particle is pinned, or when `resting` and the contact point
/// is not approaching (within the margin but leaving). Where the free particles' weights sum
/// to less than kFreeWeight (the contact point lies by pinned ones, such as those the
/// thickness stage holds in its second pass), the move and the velocity change are scaled by
/// that sum over kFreeWeight: a free particle then moves at most about 1 / kFreeWeight times
/// the move, not move / w, which folds the soft surface through itself as w goes to 0.
/// `stick` (a ridge's, a cap's or a chord's first push of the step): the move also takes the
/// contact point back along its path of the step, to where it crossed the level it goes to
/// (below); `held` (when given) receives the length [m] of that take-back (0: none).
inline bool push(const Frame& f, int n, const index* idx, const double* w, V3* l, V3 x_local,
                 V3 move, V3 normal, bool resting, double* q, double* qd, V3& j,
                 colliders::Seen* seen, bool stick = false, double* held = nullptr) {
    const Model& m = f.m;
    double sum = 0.0, free_weight = 0.0;
    V3 vel{0.0, 0.0, 0.0};
    for (int k = 0; k < n; ++k) {
        const double inv = m.particles.inv_mass[idx[k]];
        sum += w[k] * w[k] * inv;
        if (inv > 0.0) free_weight += w[k];
        vel = vel + w[k] * load(qd, idx[k]);
    }
    if (!(sum > 0.0)) return false;
    const V3 nw = to_world(f.r, normal);
    const V3 xw = f.c + to_world(f.r, x_local);
    const V3 rel = vel - (f.vc + cross(f.wc, xw - f.c));
    const double vn = dot(rel, nw);
    if (resting && vn >= 0.0) return false;  // within the margin but leaving: free
    if (stick && f.q_start != nullptr) {
        // The contact point goes back to where its path of this step (from its position at
        // the step's start, in the collider's frame then) crossed the level it is pushed
        // to (the plane through its target, across `normal`; from the start's own place
        // when it began below it), as a vertex goes back to where its path entered
        // (resolve(); the analytic sphere and box likewise): of its motion into the
        // surface, the part along the surface after that crossing is undone; the part
        // along the normal is the push's. Pushed straight out instead, a sheet resting on
        // a smooth mesh's corners and chords is never held back but by the friction on
        // its velocity, and slides off where the analytic shape holds it.
        V3 x0{0.0, 0.0, 0.0}, x1{0.0, 0.0, 0.0};
        for (int k = 0; k < n; ++k) {
            x1 = x1 + w[k] * l[k];
            x0 = x0 + w[k] * to_local(f.r0, load(f.q_start, idx[k]) - f.c0);
        }
        const V3 path = x1 - x0;
        const double h1 = -dot(move, normal);       // the end's height over the level
        const double h0 = h1 - dot(path, normal);   // the start's
        if (h1 < 0.0 && h0 > h1) {  // it moved down through (or below) the level
            const double s = h0 > 0.0 ? h0 / (h0 - h1) : 0.0;
            const V3 back = (1.0 - s) * (path - dot(path, normal) * normal);
            move = move - back;
            if (held != nullptr) *held = std::sqrt(dot(back, back));
        }
    }
    const double gain = free_weight < kFreeWeight ? free_weight / kFreeWeight : 1.0;
    move = gain * move;
    const V3 dx = to_world(f.r, move);
    V3 dv{0.0, 0.0, 0.0};
    if (vn < 0.0) {
        const V3 tangent = rel - vn * nw;
        dv = gain * ((-(1.0 + f.e) * vn) * nw + (f.keep - 1.0) * tangent);
        j = j - (free_weight / sum) * dv;
    }
    for (int k = 0; k < n; ++k) {
        const index i = idx[k];
        const double share = w[k] * m.particles.inv_mass[i] / sum;
        if (share == 0.0) continue;
        store(q, i, load(q, i) + share * dx);
        store(qd, i, load(qd, i) + share * dv);
        l[k] = l[k] + share * move;
        if (seen != nullptr) seen->add(load(q, i), load(qd, i));
    }
    return true;
}

/// Mesh collider k's edges and faces against the soft bodies' edges and triangles (the
/// header's edge contacts), at the positions q (N, 3) the vertex contacts left; q, qd change
/// in place, j gathers the impulse the collider receives [N s]. c, r, vc, wc: the collider's
/// pose and velocities at the step's end. Kept out of line: inlined into the collider
/// stage, its size slowed the vertex contacts of a mesh collider (even one without edge
/// contacts) by about 10 % in benchmarks/mesh_collider.py.
[[gnu::noinline]] inline void edge_contacts(const Model& m, index k, V3 c, const double* r,
                                            V3 vc, V3 wc, double e, double keep, double* q,
                                            double* qd, V3& j, colliders::Seen* seen,
                                            index* crossed = nullptr,
                                            const double* q_start = nullptr,
                                            V3 c0 = {0.0, 0.0, 0.0}, const double* r0 = nullptr) {
    const index root = m.colliders.mesh_root[k];
    const View v{m};
    if (root < 0 || !v.has_sharp(root)) return;  // edge contacts off
    const Frame f{m, c, r, vc, wc, e, keep, q_start, c0, r0 != nullptr ? r0 : r};
    const double margin = m.colliders.mesh_margin[k];
    const double* rb = v.bounds(root);
    // a crossing left: the first soft particle, and crossing_code()'s value
    auto report = [&](index first, index second, bool triangle) {
        if (crossed == nullptr || crossed[0] >= 0) return;
        crossed[0] = first;
        crossed[1] = crossing_code(m, k, second, triangle);
    };
    double root_box[6];
    for (int d = 0; d < 3; ++d) {
        root_box[d] = rb[d] - margin;
        root_box[3 + d] = rb[3 + d] + margin;
    }
    // how far held pushes took each particle back along its path (push()'s `stick`; the
    // contact points' take-backs summed, per particle) [m], and the particles with any: moves
    // along the surface, which may carry a neighbouring soft edge, already cleared, back
    // into it (kept across steps, all zero between calls)
    thread_local std::vector<double> drag;
    thread_local std::vector<index> dragged;
    if (drag.size() < static_cast<size_t>(m.particles.count)) drag.resize(m.particles.count, 0.0);
    auto mark = [&](int n, const index* idx, double held) {
        if (!(held > 0.0)) return;
        for (int a = 0; a < n; ++a) {
            if (drag[idx[a]] == 0.0) dragged.push_back(idx[a]);
            drag[idx[a]] += held;
        }
    };
    // a chord: the soft edge idx (local ends ls, updated) through the faces, at the `known`
    // crossings (cut, ascending) or (known < 0) those found anew, pushed out at its deepest
    // sample (up to kRounds); `hold`: its first push takes the contact point back along its
    // path (push()'s `stick`). Returns whether it moved the edge.
    auto chord = [&](const index* idx, V3* ls, double* cut, int known, bool hold) {
        bool moved = false;
        for (int round = 0; round <= kRounds; ++round) {
            const int count = round == 0 && known >= 0
                                  ? known
                                  : segment_crossings(v, root, ls[0], ls[1], cut);
            if (count == 0) break;
            Nearest near;
            const double at = deepest_inside(v, root, ls[0], ls[1], cut, count, near);
            if (at < 0.0) break;  // grazing the surface
            if (round == kRounds) {  // pushed in every round and still through
                report(idx[0], idx[1], false);
                break;
            }
            const V3 x = ls[0] + at * (ls[1] - ls[0]);
            const double dist = std::sqrt(near.d2);
            const V3 n = dist > 0.0 ? (1.0 / dist) * (near.x - x) : near.n;
            const double w[2] = {1.0 - at, at};
            double held = 0.0;
            if (!push(f, 2, idx, w, ls, near.x, (near.x + margin * n) - x, n, false, q, qd, j,
                      seen, hold && round == 0, &held)) {
                report(idx[0], idx[1], false);  // both ends pinned
                break;
            }
            mark(2, idx, held);
            moved = true;
        }
        return moved;
    };
    // soft triangle t's ridges, corners and caps, and chords; `hold`: their first pushes take
    // the contact point back along its path (push()'s `stick`)
    auto treat = [&](index t, bool hold) {
        const index* tri = m.triangles.indices + 3 * t;
        V3 l[3];
        double lo[3], hi[3];
        auto place = [&] {  // the soft triangle's local corners and its box plus the margin
            for (int d = 0; d < 3; ++d) {
                lo[d] = std::numeric_limits<double>::infinity();
                hi[d] = -std::numeric_limits<double>::infinity();
            }
            for (int a = 0; a < 3; ++a) {
                l[a] = to_local(r, load(q, tri[a]) - c);
                for (int d = 0; d < 3; ++d) {
                    lo[d] = std::min(lo[d], (&l[a].x)[d] - margin);
                    hi[d] = std::max(hi[d], (&l[a].x)[d] + margin);
                }
            }
        };
        place();
        if (!boxes_meet(lo, hi, root_box)) return;
        bool capped = false;  // a collider edge through the triangle pushed it this round
        bool pushed = false;  // anything moved the triangle's corners
        bool check = false;   // the round after kRounds: a cap still there is reported
        bool first = true;    // the first round: push() takes the contact back along its path
        auto visit = [&](index mt, int mk) {
            const V3 p = v.corner(mt, mk), pq = v.corner(mt, (mk + 1) % 3);
            const index twin = v.sharp_twin(mt, mk);
            // the soft triangle's edges (each soft edge by its owner) against a sharp edge
            for (int a = 0; a < 3 && twin >= 0 && !check; ++a) {
                if (m.triangles.edge_owner[3 * t + a] == 0) continue;
                const V3 n1 = v.face_normal(mt), n2 = v.face_normal(twin);
                const V3 ne = v.pseudo_normal(mt, 3 + mk);
                const int b = (a + 1) % 3;
                double s = 0.0, u = 0.0;
                thick::closest_segments(l[a], l[b], p, pq, s, u);
                const V3 xs = l[a] + s * (l[b] - l[a]), xm = p + u * (pq - p);
                const V3 d = xs - xm;
                const double dist = std::sqrt(dot(d, d));
                const double d1 = dot(d, n1), d2 = dot(d, n2);
                bool inside = false;
                if ((d1 < 0.0 && d2 < 0.0) || dist == 0.0) {
                    // behind both faces: inside when the soft edge passes through one of them.
                    // Only across the edge's length: past its ends the common perpendicular
                    // runs along the edge's line, far from the surface a chord there cuts
                    // (the chords below push it out to its nearest surface)
                    if (!(u > 0.0 && u < 1.0)) continue;
                    // and only along a direction in the cone of the faces' normals: on a
                    // nearly flat edge (a low sharp_angle) the wedge is nearly a half-space
                    // and the common perpendicular of two nearly parallel edges may run
                    // along the surface, far from the chord's depth
                    const V3 along = cross(n1, n2), out = -1.0 * d;
                    if (dot(cross(n1, out), along) < 0.0 || dot(cross(out, n2), along) < 0.0)
                        continue;
                    const index* t1 = m.collider_meshes.triangles + 3 * mt;
                    const index* t2 = m.collider_meshes.triangles + 3 * twin;
                    inside = segment_meets_triangle(
                                 l[a], l[b], v.vertex(t1[0]), v.vertex(t1[1]), v.vertex(t1[2])) ||
                             segment_meets_triangle(
                                 l[a], l[b], v.vertex(t2[0]), v.vertex(t2[1]), v.vertex(t2[2]));
                    if (!inside) continue;
                } else if (!(d1 >= 0.0 && d2 >= 0.0 && dist < margin)) {
                    continue;  // beside a face (the vertex contacts' business), or far
                }
                const V3 n = dist > 0.0 ? (inside ? -1.0 / dist : 1.0 / dist) * d : ne;
                const index idx[2] = {tri[a], tri[b]};
                const double w[2] = {1.0 - s, s};
                V3 ls[2] = {l[a], l[b]};
                double held = 0.0;
                if (push(f, 2, idx, w, ls, xm, (xm + margin * n) - xs, n, !inside, q, qd, j,
                         seen, first, &held)) {
                    mark(2, idx, held);
                    l[a] = ls[0];
                    l[b] = ls[1];
                    pushed = true;
                }
            }
            // a corner or a cap through the soft triangle: the edge's end beyond it
            if (!segment_meets_triangle(p, pq, l[0], l[1], l[2])) return;
            const V3 tn = unit(cross(l[1] - l[0], l[2] - l[0]));
            double best = std::numeric_limits<double>::infinity();
            soft::TrianglePoint at{};
            V3 nbest{0.0, 0.0, 0.0};
            for (int end = 0; end < 2; ++end) {
                const index vi = m.collider_meshes.triangles[3 * mt + (mk + end) % 3];
                const V3 x = v.vertex(vi);
                const V3 nv = load(m.collider_meshes.vertex_normals, vi);
                const double side = dot(tn, nv);
                if (side == 0.0) continue;
                const V3 n = side > 0.0 ? tn : -1.0 * tn;
                const soft::TrianglePoint tp = soft::closest_point_on_triangle(x, l[0], l[1], l[2]);
                if (!(tp.wa > 0.0 && tp.wb > 0.0 && tp.wc > 0.0)) continue;  // beside it
                const double h = dot(x - tp.x, n);  // > 0: the end beyond the triangle
                if (h < 0.0 || h >= best) continue;
                best = h;
                at = tp;
                nbest = n;
            }
            if (!std::isfinite(best)) return;
            if (check) return report(tri[0], t, true);
            const double w[3] = {at.wa, at.wb, at.wc};
            double held = 0.0;
            const bool moved = push(f, 3, tri, w, l, at.x, (best + margin) * nbest, nbest, false,
                                    q, qd, j, seen, first, &held);
            if (!moved) report(tri[0], t, true);  // every corner pinned
            mark(3, tri, held);
            capped |= moved;
            pushed |= capped;
        };
        // One walk over the leaves near the triangle: its own edges' crossings of the faces
        // (the chords below; every leaf, flat ones too) and the flagged edges near it (ridges,
        // corners, caps). A cap of a smooth surface may hold vertices beyond the triangle
        // that no crossing edge ends at: once pushed past the crossing edges' ends, their
        // edges cross next, so the flagged edges are walked again while a cap was pushed.
        double cuts[3][kCrossings];
        int cut_count[3] = {0, 0, 0};
        for (int round = 0; round <= kRounds; ++round) {
            check = round == kRounds;  // pushed in every round: only look whether one is left
            first = round == 0 && hold;
            capped = false;
            // a mesh triangle wholly on one side of the soft triangle's plane can neither be
            // crossed by a soft edge nor have an edge through the soft triangle: most near a
            // soft surface lying on the mesh are, and are passed over, whole subtrees farther
            // than the margin from the plane first (a sharp edge within the margin is still
            // visited: its resting contacts cross nothing)
            const V3 tn = cross(l[1] - l[0], l[2] - l[0]);
            const double reach = margin * std::sqrt(dot(tn, tn));
            each_leaf(v, root, lo, hi, l[0], tn, reach, round == 0, [&](index tb, index te) {
                for (index mt = tb; mt < te; ++mt) {
                    const V3 p0 = v.corner(mt, 0), p1 = v.corner(mt, 1), p2 = v.corner(mt, 2);
                    const double h0 = dot(p0 - l[0], tn), h1 = dot(p1 - l[0], tn),
                                 h2 = dot(p2 - l[0], tn);
                    const bool straddles = !((h0 > 0.0 && h1 > 0.0 && h2 > 0.0) ||
                                             (h0 < 0.0 && h1 < 0.0 && h2 < 0.0));
                    for (int a = 0; a < 3 && straddles && round == 0 && !pushed; ++a) {
                        double cut = 0.0;
                        if (m.triangles.edge_owner[3 * t + a] != 0 &&
                            segment_meets_triangle(l[a], l[(a + 1) % 3], p0, p1, p2, cut))
                            add_crossing(cuts[a], cut_count[a], cut);
                    }
                    for (int mk = 0; mk < 3; ++mk)
                        if (v.takes_part(mt, mk) && (straddles || v.sharp_twin(mt, mk) >= 0) &&
                            segment_box_meets(v.corner(mt, mk), v.corner(mt, (mk + 1) % 3), lo, hi))
                            visit(mt, mk);
                }
            });
            if (!capped || check) break;
            place();
        }
        // chords: the triangle's own edges (each soft edge once, by its owner) through the
        // faces, found in the walk above unless something moved since (then again)
        for (int a = 0; a < 3; ++a) {
            if (m.triangles.edge_owner[3 * t + a] == 0) continue;
            const index idx[2] = {tri[a], tri[(a + 1) % 3]};
            V3 ls[2] = {l[a], l[(a + 1) % 3]};
            pushed |= chord(idx, ls, cuts[a], pushed ? -1 : cut_count[a], hold);
            l[a] = ls[0];
            l[(a + 1) % 3] = ls[1];
        }
    };
    // every soft triangle, its first pushes held (taken back along their paths); then each
    // with a particle that held pushes moved along the surface by more than kDragged margins
    // (its edges shared with triangles treated before that move) again, with straight
    // pushes
    for (index t = 0; t < m.triangles.count; ++t) treat(t, true);
    if (dragged.empty()) return;
    const double far = kDragged * margin;
    bool any = false;
    for (const index i : dragged) any |= drag[i] > far;
    for (index t = 0; t < m.triangles.count && any; ++t) {
        const index* tri = m.triangles.indices + 3 * t;
        if (drag[tri[0]] > far || drag[tri[1]] > far || drag[tri[2]] > far) treat(t, false);
    }
    for (const index i : dragged) drag[i] = 0.0;
    dragged.clear();
}

/// The roots in [0, 1] of c0 + c1 t + c2 t^2 (at most 2, ascending, into t; returns how
/// many), with `scale` the size of the terms for what counts as zero: a quadratic whose
/// leading term is below round-off of it is solved as linear (Citardauq form otherwise, no
/// cancellation), one whose every term is: none (the caller's degenerate case). Roots within
/// round-off outside [0, 1] are clamped in.
inline int roots01(double c0, double c1, double c2, double scale, double* t) {
    constexpr double kEps = 1e-12, kSlack = 1e-9;
    const double zero = kEps * scale;
    int count = 0;
    auto keep = [&](double x) {
        if (!(x >= -kSlack && x <= 1.0 + kSlack)) return;
        t[count++] = std::min(1.0, std::max(0.0, x));
    };
    if (std::fabs(c2) <= zero) {
        if (std::fabs(c1) > zero) keep(-c0 / c1);
        return count;
    }
    double disc = c1 * c1 - 4.0 * c2 * c0;
    if (disc < 0.0) {
        if (disc < -zero * scale) return 0;
        disc = 0.0;  // a touching (double) root within round-off
    }
    const double qq = -0.5 * (c1 + (c1 >= 0.0 ? 1.0 : -1.0) * std::sqrt(disc));
    keep(qq / c2);
    if (qq != 0.0) keep(c0 / qq);
    if (count == 2 && t[1] < t[0]) std::swap(t[0], t[1]);
    return count;
}

/// The first time t in [0, 1] at which the soft segment a(t)-b(t) (its ends moving linearly
/// from a0, b0 to a1, b1) touches the fixed segment p-pq (all in the collider's frame), to
/// within `tol` [m]; > 1: never. s, u: the parameters along the soft and the mesh segment
/// there. The lines are coplanar where (b - a) x (pq - p) . (a - p) = 0: with the mesh
/// edge fixed in this frame a quadratic in t (the moving-edge case's cubic of Provot 1997 /
/// Bridson et al. 2002 loses its cubic term), solved exactly (roots01), each root checked by
/// the segments' closest points. Coplanar all along (parallel lines, or a motion within one
/// plane holding the mesh edge): in that plane the first touch is an end of one segment on
/// the other, at a root of an end's signed distance to the other's line (linear for the soft
/// ends against the fixed edge, quadratic for the mesh edge's ends against the moving one).
inline double first_touch(V3 a0, V3 b0, V3 a1, V3 b1, V3 p, V3 pq, double tol, double& s,
                          double& u) {
    const V3 E = pq - p, e0 = b0 - a0, de = (b1 - a1) - e0, r0 = a0 - p, dr = a1 - a0;
    const V3 n0 = cross(e0, E), dn = cross(de, E);
    // the terms' size (within a factor of 3 of the sum of the norms' products)
    const double scale =
        std::sqrt((dot(n0, n0) + dot(dn, dn)) * (dot(r0, r0) + dot(dr, dr) + dot(E, E)));
    double t[6];
    // parallel lines that keep their direction: scale 0, every term 0 (the case below)
    int count = scale > 0.0 ? roots01(dot(n0, r0), dot(n0, dr) + dot(dn, r0), dot(dn, dr),
                                      scale, t)
                            : 0;
    if (count == 0) {
        // coplanar all along (or never, which the checks below then reject): the plane's
        // normal from the mesh edge and whichever of the soft edge's offsets is not along it
        V3 pn = cross(E, r0);
        if (dot(pn, pn) <= 1e-24 * dot(E, E) * dot(r0, r0)) pn = cross(E, r0 + dr);
        if (dot(pn, pn) <= 1e-24 * dot(E, E) * dot(r0 + dr, r0 + dr)) pn = cross(E, e0);
        if (!(dot(pn, pn) > 0.0)) return 2.0;  // all on the mesh edge's line
        const double len = std::sqrt(dot(E, E)) + std::sqrt(dot(e0, e0)) +
                           std::sqrt(dot(r0, r0)) + std::sqrt(dot(dr, dr)) +
                           std::sqrt(dot(de, de));
        const double sc = std::sqrt(dot(pn, pn)) * len * len;
        const V3 ep = cross(E, pn);  // side of x against the mesh edge's line: (x - p) . ep
        // the soft ends a(t) = a0 + t dr and b(t) = b0 + t (dr + de) against the mesh line
        count = roots01(dot(r0, ep), dot(dr, ep), 0.0, sc, t);
        count += roots01(dot(r0 + e0, ep), dot(dr + de, ep), 0.0, sc, t + count);
        // the mesh ends x against the soft line: (x - a(t)) . (e(t) x pn), quadratic in t
        for (const V3 x : {p, pq}) {
            const V3 g0 = x - a0, k0 = cross(e0, pn), k1 = cross(de, pn);
            count += roots01(dot(g0, k0), dot(g0, k1) - dot(dr, k0), -dot(dr, k1), sc,
                             t + count);
        }
        std::sort(t, t + count);
    }
    for (int k = 0; k < count; ++k) {
        const V3 a = a0 + t[k] * (a1 - a0), b = b0 + t[k] * (b1 - b0);
        thick::closest_segments(a, b, p, pq, s, u);
        const V3 d = (a + s * (b - a)) - (p + u * E);
        if (dot(d, d) <= tol * tol) return t[k];
    }
    return 2.0;
}

/// Continuous soft-edge against mesh-edge contacts of mesh collider k (f: its pose and
/// velocities at the step's end; c0, r0 its pose at the step's start), before the edge
/// contacts at the step's end: a soft edge that passes wholly over an edge of the mesh
/// within the step (its ends outside at both ends, its chord outside at the end) is
/// otherwise missed; one that ends the step through the mesh's faces is left to them (as
/// before, pushed out the nearest way), and one whose ends move less than the margin
/// relative to the collider ends that way where it touched an edge. Each soft edge (by its owner) moves linearly in the collider's frame
/// from its start (q_start, in the start's frame) to its end (q, after the vertex
/// contacts); against every edge taking part in the edge contacts (sharp or bent) whose box
/// meets the edge's swept box (the tree's has_sharp subtrees), first_touch gives the first
/// time of contact. At the earliest, when the side the soft edge came from is outside the
/// mesh (a point half the margin out along the contact normal: the nearest feature's
/// pseudo-normal test), the soft edge goes back to that side: its contact point to the mesh
/// edge's point plus `margin` along the normal (the two edges' common normal there, toward
/// where the soft point came from), and its velocity relative to the collider takes
/// restitution and friction (push(): mass-weighted by the barycentric weights, free
/// particles only, the opposite impulse to j). Again from the new end (up to kRounds); a hit
/// no free particle can answer (every one pinned) is reported as a crossing.
inline void swept_edge_contacts(const Frame& f, index k, V3 c0, const double* r0,
                                const double* q_start, double* q, double* qd, V3& j,
                                colliders::Seen* seen, index* crossed) {
    const Model& m = f.m;
    const index root = m.colliders.mesh_root[k];
    const View v{m};
    if (root < 0 || !v.has_sharp(root)) return;
    const double margin = m.colliders.mesh_margin[k];
    const double tol = 0.01 * margin;
    const double* rb = v.bounds(root);
    double root_box[6];
    for (int d = 0; d < 3; ++d) {
        root_box[d] = rb[d] - margin;
        root_box[3 + d] = rb[3 + d] + margin;
    }
    // a soft edge moves only as far as its ends (below): none that moved past the margin
    // relative to the collider, nothing to test (a resting or slow soft body: one pass)
    bool moving = false;
    const bool still = dot(f.vc, f.vc) == 0.0 && dot(f.wc, f.wc) == 0.0;  // the frame fixed
    for (index i = 0; i < m.particles.count && !moving; ++i) {
        const V3 d = still ? load(q, i) - load(q_start, i)  // a rotation keeps lengths
                           : to_local(f.r, load(q, i) - f.c) - to_local(r0, load(q_start, i) - c0);
        moving = dot(d, d) > margin * margin;
    }
    if (!moving) return;
    // each end's start in the collider's frame (a rotation per end: no per-step buffer)
    auto start = [&](index i) { return to_local(r0, load(q_start, i) - c0); };
    for (index t = 0; t < m.triangles.count; ++t) {
        for (int a = 0; a < 3; ++a) {
            if (m.triangles.edge_owner[3 * t + a] == 0) continue;
            const index idx[2] = {m.triangles.indices[3 * t + a],
                                  m.triangles.indices[3 * t + (a + 1) % 3]};
            const V3 s0[2] = {start(idx[0]), start(idx[1])};
            for (int round = 0; round < kRounds; ++round) {
                V3 s1[2] = {to_local(f.r, load(q, idx[0]) - f.c),
                            to_local(f.r, load(q, idx[1]) - f.c)};
                // Ends that move less than the margin relative to the collider (no point of
                // the edge moves farther than its ends) cannot carry the edge wholly past a
                // part of the mesh thicker than the margin: where it touched an edge, it ends
                // the step through a face, which the step's-end contacts see. So a resting
                // or slow soft body costs one test per edge.
                const V3 da = s1[0] - s0[0], db = s1[1] - s0[1];
                if (std::max(dot(da, da), dot(db, db)) <= margin * margin) break;
                double lo[3], hi[3];
                for (int d = 0; d < 3; ++d) {
                    const double x0 = (&s0[0].x)[d], x1 = (&s0[1].x)[d], x2 = (&s1[0].x)[d],
                                 x3 = (&s1[1].x)[d];
                    lo[d] = std::min(std::min(x0, x1), std::min(x2, x3)) - tol;
                    hi[d] = std::max(std::max(x0, x1), std::max(x2, x3)) + tol;
                }
                if (!boxes_meet(lo, hi, root_box)) break;
                double t_best = 2.0, s_best = 0.0, u_best = 0.0;
                index mt_best = -1;
                int mk_best = 0;
                index stack[kStack];
                int top = 0;
                stack[top++] = root;
                while (top > 0) {
                    const index node = stack[--top];
                    if (!v.has_sharp(node) || !boxes_meet(lo, hi, v.bounds(node))) continue;
                    const index tb = v.begin(node), te = v.end(node);
                    if (te > tb) {
                        for (index mt = tb; mt < te; ++mt)
                            for (int mk = 0; mk < 3; ++mk) {
                                if (!v.takes_part(mt, mk)) continue;
                                const V3 p = v.corner(mt, mk), pq = v.corner(mt, (mk + 1) % 3);
                                if (!segment_box_meets(p, pq, lo, hi)) continue;
                                double s = 0.0, u = 0.0;
                                const double when =
                                    first_touch(s0[0], s0[1], s1[0], s1[1], p, pq, tol, s, u);
                                if (when >= t_best) continue;
                                t_best = when;
                                s_best = s;
                                u_best = u;
                                mt_best = mt;
                                mk_best = mk;
                            }
                        continue;
                    }
                    if (top + 2 > kStack) continue;
                    stack[top++] = v.child(node, 0);
                    stack[top++] = v.child(node, 1);
                }
                if (mt_best < 0) break;
                // a soft edge that ends the step through the mesh's faces is the step's-end
                // edge contacts' (ridges, chords: pushed out the nearest way); only one that
                // ends wholly outside, past the edge it touched, would be missed
                double cuts[kCrossings];
                if (segment_crossings(v, root, s1[0], s1[1], cuts) > 0) break;
                const V3 p = v.corner(mt_best, mk_best), pq = v.corner(mt_best, (mk_best + 1) % 3);
                const V3 E = pq - p, xm = p + u_best * E;
                // the contact normal: the two edges' common normal there, toward where the
                // soft point came from (against its velocity, or its start's side); along
                // (nearly) parallel edges, the start's offset across the mesh edge
                const V3 at0 = s0[0] + t_best * (s1[0] - s0[0]);
                const V3 at1 = s0[1] + t_best * (s1[1] - s0[1]);
                const V3 vel = (1.0 - s_best) * (s1[0] - s0[0]) + s_best * (s1[1] - s0[1]);
                const V3 from = (s0[0] + s_best * (s0[1] - s0[0])) - xm;
                V3 n = cross(at1 - at0, E);
                const double nn = dot(n, n);
                if (nn > 1e-18 * dot(at1 - at0, at1 - at0) * dot(E, E)) {
                    n = (1.0 / std::sqrt(nn)) * n;
                    const double sv = dot(n, vel), sf = dot(n, from);
                    const double side = std::fabs(sv) > 1e-9 * std::sqrt(dot(vel, vel)) ? -sv : sf;
                    if (side < 0.0) n = -1.0 * n;
                    if (side == 0.0) break;
                } else {
                    n = unit(from - (dot(from, E) / dot(E, E)) * E);
                    if (!(dot(n, n) > 0.0)) break;
                }
                // from outside: a point half the margin out along n is outside the mesh
                const V3 probe = xm + 0.5 * margin * n;
                const Nearest near = nearest(v, root, probe);
                if (dot(probe - near.x, near.n) < 0.0) break;
                // Both ends free: the edge back to where it was at the contact, plus the
                // margin along n (for an edge what the vertex contacts' entry point is for a
                // vertex), each end then responding as a caught vertex does (restitution and
                // friction on its velocity relative to the collider, against n). Soft edges
                // share particles: contact-point impulses applied edge after edge would undo
                // each other's and feed energy in (a strip caught at 120 m/s, restitution 0,
                // left particles moving at +44 and -72 m/s); a vertex's response, once
                // applied, leaves a second one nothing to do. Else the contact point to the
                // margin by push()'s weights, its velocity likewise, the pinned ends held.
                if (m.particles.inv_mass[idx[0]] > 0.0 && m.particles.inv_mass[idx[1]] > 0.0) {
                    const V3 nw = to_world(f.r, n);
                    for (int e = 0; e < 2; ++e) {
                        const V3 x = f.c + to_world(f.r, (e == 0 ? at0 : at1) + margin * n);
                        colliders::respond(m, idx[e], {true, x, nw}, f.vc + cross(f.wc, x - f.c),
                                           f.e, f.keep, q, qd, j);
                        if (seen != nullptr) seen->add(load(q, idx[e]), load(qd, idx[e]));
                    }
                    continue;
                }
                const V3 xs = s1[0] + s_best * (s1[1] - s1[0]);
                const V3 move = (xm + margin * n) - xs;
                const double w[2] = {1.0 - s_best, s_best};
                if (!push(f, 2, idx, w, s1, xm, move, n, false, q, qd, j, seen)) {
                    if (crossed != nullptr && crossed[0] < 0) {
                        crossed[0] = idx[0];
                        crossed[1] = crossing_code(m, k, idx[1], false);
                    }
                    break;
                }
            }
        }
    }
}

/// Mesh collider k (centre c, rotation r at the step's end; velocity vc [m/s], angular
/// velocity wc [rad/s]) against every particle: q_start (N, 3) the positions at the step's
/// start, dt [s] the step (the collider's pose at its start is taken back along vc, wc);
/// q, qd (N, 3) change in place, j gathers the impulse the collider receives [N s].
inline void contacts(const Model& m, index k, V3 c, const double* r, V3 vc, V3 wc, double e,
                     double keep, double dt, const double* q_start, double* q, double* qd, V3& j,
                     colliders::Seen* seen, index* crossed) {
    const index root = m.colliders.mesh_root[k];
    if (root < 0) return;
    const View v{m};
    const double margin = m.colliders.mesh_margin[k];
    // the pose at the step's start
    const V3 c0 = c - dt * vc;
    double r0[9];
    const double rate = std::sqrt(dot(wc, wc));
    if (rate > 0.0 && dt > 0.0) {
        double back[9];
        colliders::rotate_about((1.0 / rate) * wc, -rate * dt, back);
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b)
                r0[3 * a + b] = back[3 * a] * r[b] + back[3 * a + 1] * r[3 + b] +
                                back[3 * a + 2] * r[6 + b];
    } else {
        for (int a = 0; a < 9; ++a) r0[a] = r[a];
    }
    for (index i = 0; i < m.particles.count; ++i) {
        if (m.particles.inv_mass[i] == 0.0) continue;
        const V3 l1 = to_local(r, load(q, i) - c);
        const V3 l0 = to_local(r0, load(q_start, i) - c0);
        bool band = false;
        const colliders::Hit local = resolve(v, root, margin, l0, l1, band);
        if (!local.hit) continue;
        const colliders::Hit hit{true, c + to_world(r, local.x), to_world(r, local.n)};
        // within the margin but leaving: free
        if (band && dot(load(qd, i) - (vc + cross(wc, hit.x - c)), hit.n) >= 0.0) continue;
        colliders::respond(m, i, hit, vc + cross(wc, hit.x - c), e, keep, q, qd, j);
        if (seen != nullptr) seen->add(load(q, i), load(qd, i));
    }
    swept_edge_contacts({m, c, r, vc, wc, e, keep}, k, c0, r0, q_start, q, qd, j, seen, crossed);
    edge_contacts(m, k, c, r, vc, wc, e, keep, q, qd, j, seen, crossed, q_start, c0, r0);
}

}  // namespace softbody::SOFTBODY_KERNELS::mesh_collider
