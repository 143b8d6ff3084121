// Every array and value of the model the kernels read, declared once. From this table come
// the C++ Model's parts and members (model.hpp), the binding's reading and checking of a
// softbody.Model (bindings/core_model.hpp), and softbody._core.model_fields(), which
// tests/test_model_fields.py holds the Python Model's fields to (name, dtype, shape).
//
// Counts: X(symbol, part, member, python field whose first dimension defines it).
// Fields:  F(part, member, python name, type, shape, check, unit, description), in parts;
//   type   f64 / i64: an array (const double* / const index*); f64_value / i64_value: a
//          number; vec3: three numbers held in the model
//   shape  of an array, in the counts' symbols
//   check  none; index(lo, hi): every entry in [lo, hi); range(count): rows [begin, end)
//          within [0, count]; finite_nonneg: finite and >= 0; finite
#pragma once

#define SOFTBODY_MODEL_COUNTS(X)                  \
    X(N, particles, count, particle_mass)         \
    X(S, springs, count, spring_indices)          \
    X(A, attachments, count, attachment_particle) \
    X(T, triangles, count, tri_indices)           \
    X(B, bodies, count, body_particle_range)      \
    X(M, volumes, mc_count, mc_samples)           \
    X(K, gases, schedule_count, schedule_time)    \
    X(P, pins, count, pin_particle)               \
    X(C, colliders, count, collider_kind)         \
    X(V, vents, count, vent_body)                 \
    X(O, orifices, count, orifice_bodies)         \
    X(I, inflators, count, inflator_body)         \
    X(Q, inflators, table_count, inflator_time)   \
    X(H, bending, count, bending_hinges)          \
    X(Tm, membranes, count, membrane_indices)     \
    X(CV, collider_meshes, vertex_count, collider_mesh_vertices) \
    X(CT, collider_meshes, tri_count, collider_mesh_triangles)   \
    X(CN, collider_meshes, node_count, collider_mesh_node_children)

#define SOFTBODY_FIELDS_PARTICLES(F)                                                              \
    F(particles, mass, particle_mass, f64, (N), none, "kg",                                       \
      "particle masses")                                                                          \
    F(particles, inv_mass, particle_inv_mass, f64, (N), none, "1/kg",                             \
      "inverse masses; 0 for pinned particles")                                                   \
    F(particles, body, particle_body, i64, (N), index(-1, B), "",                                 \
      "body of each particle; -1 for a free particle")

#define SOFTBODY_FIELDS_GRAVITY(F)                                                                \
    F(gravity, acceleration, gravity, vec3, (3), finite, "m/s^2",                                 \
      "gravitational acceleration")

#define SOFTBODY_FIELDS_SPRINGS(F)                                                                \
    F(springs, indices, spring_indices, i64, (S, 2), index(0, N), "",                             \
      "particle pair of each spring")                                                             \
    F(springs, rest_length, spring_rest_length, f64, (S), none, "m",                              \
      "spring rest lengths")                                                                      \
    F(springs, stiffness, spring_stiffness, f64, (S), none, "N/m",                                \
      "spring stiffnesses")                                                                       \
    F(springs, damping, spring_damping, f64, (S), none, "N s/m",                                  \
      "spring damping coefficients")                                                              \
    F(springs, body, spring_body, i64, (S), index(-1, B), "",                                     \
      "body of each spring; -1 for a user's spring")

#define SOFTBODY_FIELDS_ATTACHMENTS(F)                                                            \
    F(attachments, particle, attachment_particle, i64, (A), index(0, N), "",                      \
      "particle tied by each attachment spring")                                                  \
    F(attachments, rest_length, attachment_rest_length, f64, (A), none, "m",                      \
      "attachment rest lengths")                                                                  \
    F(attachments, stiffness, attachment_stiffness, f64, (A), none, "N/m",                        \
      "attachment stiffnesses")                                                                   \
    F(attachments, damping, attachment_damping, f64, (A), none, "N s/m",                          \
      "attachment damping coefficients")

#define SOFTBODY_FIELDS_TRIANGLES(F)                                                              \
    F(triangles, indices, tri_indices, i64, (T, 3), index(0, N), "",                              \
      "particle indices of each surface triangle, outward-wound")                                 \
    F(triangles, body, tri_body, i64, (T), index(0, B), "",                                       \
      "body of each triangle")                                                                    \
    F(triangles, edge_owner, tri_edge_owner, i64, (T, 3), index(0, 2), "",                        \
      "1 where the triangle owns its edge k (corner k to corner k + 1): every mesh edge has "     \
      "one owner (surface contacts' edge-edge pairs)")

#define SOFTBODY_FIELDS_BODIES(F)                                                                 \
    F(bodies, particle_range, body_particle_range, i64, (B, 2), range(N), "",                     \
      "[begin, end) particles of each body")                                                      \
    F(bodies, tri_range, body_tri_range, i64, (B, 2), range(T), "",                               \
      "[begin, end) triangles of each body")                                                      \
    F(bodies, rest_volume, body_rest_volume, f64, (B), none, "m^3",                               \
      "volume at the initial positions by the body's own method")                                 \
    F(bodies, closed, body_closed, i64, (B), index(0, 2), "",                                     \
      "1 for a closed body holding gas; 0 for an open surface (cloth)")                           \
    F(bodies, contact_shape, body_contact_shape, i64, (B), index(0, VolumeMethod::MONTE_CARLO),   \
      "",                                                                                         \
      "bounding object of each body for bounding soft contacts; 1 box, 2 sphere, 3 ellipsoid "    \
      "(VolumeMethod numbering)")

#define SOFTBODY_FIELDS_VOLUMES(F)                                                                \
    F(volumes, method, body_volume_method, i64, (B), index(0, VolumeMethod::kCount), "",          \
      "VolumeMethod of each body")                                                                \
    F(volumes, mc_range, body_mc_range, i64, (B, 2), range(M), "",                                \
      "[begin, end) rows of mc_samples of each Monte Carlo body")                                 \
    F(volumes, mc_samples, mc_samples, f64, (M, 2), none, "",                                     \
      "seeded sample points in [0, 1)^2 for Monte Carlo volumes")

#define SOFTBODY_FIELDS_GASES(F)                                                                  \
    F(gases, law, body_gas_law, i64, (B), index(0, GasLaw::kCount), "",                           \
      "GasLaw of each body")                                                                      \
    F(gases, value, body_gas_value, f64, (B), none, "J or Pa",                                    \
      "driving gas value of each body; nRT [J] (isothermal, adiabatic) or P0 [Pa] (fixed)")       \
    F(gases, gamma, body_gas_gamma, f64, (B), none, "",                                           \
      "adiabatic exponent of each body's gas")                                                    \
    F(gases, reference_volume, body_gas_reference_volume, f64, (B), none, "m^3",                  \
      "volume at which an adiabatic gas has P = nRT / V")                                         \
    F(gases, ambient_pressure, body_ambient_pressure, f64, (B), none, "Pa",                       \
      "pressure outside each body")                                                               \
    F(gases, schedule_range, body_schedule_range, i64, (B, 2), range(K), "",                      \
      "[begin, end) rows of the gas schedule of each body; empty for none")                       \
    F(gases, schedule_time, schedule_time, f64, (K), none, "s",                                   \
      "gas schedule times")                                                                       \
    F(gases, schedule_value, schedule_value, f64, (K), none, "J or Pa",                           \
      "gas schedule values (nRT [J] or P0 [Pa])")                                                 \
    F(gases, molar_mass, body_gas_molar_mass, f64, (B), finite_nonneg, "kg/mol",                  \
      "molar mass of each body's gas (0.028965 for air)")                                         \
    F(gases, temperature, body_gas_temperature, f64, (B), finite_nonneg, "K",                     \
      "temperature of each body's gas at the initial positions (State starts from it)")          \
    F(gases, ambient_temperature, body_ambient_temperature, f64, (B), finite_nonneg, "K",         \
      "temperature of the air outside each body: what flows in through its vents and leaks")     \
    F(gases, leak, body_leak_coefficient, f64, (B), finite_nonneg, "kg/(s m^2 Pa)",               \
      "fabric leakage of each body: mass flow per area per pressure difference; 0 for none")     \
    F(gases, flow_paths, body_flow_paths, i64, (B), index(0, 1 << 30), "",                        \
      "vents, orifices and leaks each body's gas can leave through (the outflow limiter)")

#define SOFTBODY_FIELDS_PINS(F)                                                                   \
    F(pins, particle, pin_particle, i64, (P), index(0, N), "",                                    \
      "pinned (kinematic) particles; Control.pin_target moves them")

#define SOFTBODY_FIELDS_DRAG(F)                                                                   \
    F(drag, coefficient, body_drag_coefficient, f64, (B), finite_nonneg, "",                      \
      "aerodynamic drag coefficient C_d of each body's faces, >= 0; 0 leaves the body out of "    \
      "the drag term (core/terms/drag.hpp)")                                                      \
    F(drag, air_density, air_density, f64_value, (), finite_nonneg, "kg/m^3",                     \
      "density rho of the air the bodies move through, >= 0")                                     \
    F(drag, wind, wind, vec3, (3), finite, "m/s",                                                 \
      "velocity of the air; Control.wind overrides it per call")

#define SOFTBODY_FIELDS_SOFT_CONTACTS(F)                                                          \
    F(soft_contacts, mode, soft_contact_mode, i64_value, (), index(0, SoftContactMode::kCount),   \
      "",                                                                                         \
      "soft-soft contacts: a SoftContactMode; 0 none, 1 bounding objects, 2 surfaces")            \
    F(soft_contacts, restitution, soft_contact_restitution, f64_value, (), none, "",              \
      "restitution of soft-soft contacts, in [0, 1]")                                             \
    F(soft_contacts, friction, soft_contact_friction, f64_value, (), none, "",                    \
      "fraction of tangential relative speed a soft-soft contact removes, in [0, 1]")             \
    F(soft_contacts, margin, contact_margin, f64_value, (), none, "m",                            \
      "distance within which surface contacts look for the nearest triangle")                     \
    F(soft_contacts, cell_size, contact_cell_size, f64_value, (), none, "m",                      \
      "grid cell of the surface contacts' spatial hash")                                          \
    F(soft_contacts, thickness, contact_thickness, f64_value, (), finite_nonneg, "m",             \
      "distance surface contacts keep between two sheets; 0: vertices against the other "       \
      "body's triangles without one (collision/soft.hpp), > 0: collision/thick.hpp")              \
    F(soft_contacts, self_contact, soft_self_contact, i64_value, (), index(0, 2), "",             \
      "1: surface contacts with a thickness act within a body too")

#define SOFTBODY_FIELDS_COLLIDERS(F)                                                              \
    F(colliders, kind, collider_kind, i64, (C), index(0, ColliderKind::kCount), "",               \
      "ColliderKind of each rigid collider")                                                      \
    F(colliders, center, collider_center, f64, (C, 3), none, "m",                                 \
      "collider centres at t = 0; a plane: a point on it")                                        \
    F(colliders, rotation, collider_rotation, f64, (C, 3, 3), none, "",                           \
      "collider orientations at t = 0; a plane's normal is column 1")                             \
    F(colliders, size, collider_size, f64, (C, 3), none, "m",                                     \
      "box half-extents, sphere radius (repeated), or a mesh's bounding-box "                      \
      "half-extents")                                                                             \
    F(colliders, restitution, collider_restitution, f64, (C), none, "",                           \
      "restitution of each collider")                                                             \
    F(colliders, friction, collider_friction, f64, (C), none, "",                                 \
      "fraction of tangential speed each collider removes at contact")                            \
    F(colliders, motion, collider_motion, i64, (C), index(0, MotionKind::kCount), "",             \
      "MotionKind of each collider")                                                              \
    F(colliders, motion_vector, collider_motion_vector, f64, (C, 3), none, "",                    \
      "angular velocity [rad/s], velocity [m/s] or amplitude [m] of the motion")                  \
    F(colliders, motion_pivot, collider_motion_pivot, f64, (C, 3), none, "m",                     \
      "pivot of rotating colliders")                                                              \
    F(colliders, motion_frequency, collider_motion_frequency, f64, (C), none, "Hz",               \
      "frequency of oscillating colliders")                                                       \
    F(colliders, mesh_range, collider_mesh_range, i64, (C, 2), range(CT), "",                     \
      "[begin, end) rows of collider_mesh_triangles of each mesh collider; empty for the others") \
    F(colliders, mesh_root, collider_mesh_root, i64, (C), index(-1, CN), "",                      \
      "root row of each mesh collider's bounding-volume tree; -1 for the others")                \
    F(colliders, mesh_margin, collider_mesh_margin, f64, (C), finite_nonneg, "m",                 \
      "distance outside its surface a mesh collider puts the particles it catches; 0 for the "   \
      "others")

// Mesh colliders' triangles in their collider's local frame (core/collision/mesh.hpp): the
// vertices and triangles of every mesh collider, each collider's rows one block, its
// triangles in the order of its tree's leaves.
#define SOFTBODY_FIELDS_COLLIDER_MESHES(F)                                                        \
    F(collider_meshes, vertices, collider_mesh_vertices, f64, (CV, 3), finite, "m",               \
      "mesh collider vertices in their collider's local frame")                                   \
    F(collider_meshes, triangles, collider_mesh_triangles, i64, (CT, 3), index(0, CV), "",        \
      "vertex rows of each mesh collider triangle, outward-wound")                                \
    F(collider_meshes, vertex_normals, collider_mesh_vertex_normals, f64, (CV, 3), finite, "",    \
      "angle-weighted pseudo-normal of each mesh collider vertex (unit)")                         \
    F(collider_meshes, edge_normals, collider_mesh_edge_normals, f64, (CT, 3, 3), finite, "",     \
      "pseudo-normal (unit mean of its two faces' normals) of each triangle's edges (corner k "  \
      "to corner k + 1)")                                                                         \
    F(collider_meshes, sharp_edges, collider_mesh_sharp_edges, i64, (CT, 3), index(-2, CT), "",   \
      "the triangle across edge k of each triangle where that edge is sharp and convex and this " \
      "triangle owns it (its first vertex row below its second): the edge contacts; -2 where it " \
      "is bent but not sharp (and owned); else -1")                                              \
    F(collider_meshes, node_children, collider_mesh_node_children, i64, (CN, 2), index(0, CN),    \
      "",                                                                                         \
      "the two child rows of each inner tree node (after its own row); 0 0 for a leaf")          \
    F(collider_meshes, node_tris, collider_mesh_node_tris, i64, (CN, 2), range(CT), "",           \
      "[begin, end) triangle rows of each leaf; empty for an inner node")                         \
    F(collider_meshes, node_sharp, collider_mesh_node_sharp, i64, (CN), index(0, 2), "",          \
      "1 where a tree node's triangles hold a sharp or bent edge (collider_mesh_sharp_edges "     \
      "!= -1), else 0")                                                                           \
    F(collider_meshes, node_bounds, collider_mesh_node_bounds, f64, (CN, 2, 3), finite, "m",      \
      "lower and upper corner of each tree node's box, in the local frame")

#define SOFTBODY_FIELDS_VENTS(F)                                                                  \
    F(vents, body, vent_body, i64, (V), index(0, B), "",                                          \
      "body each vent lets gas out of (to its ambient pressure)")                                \
    F(vents, area, vent_area, f64, (V), finite_nonneg, "m^2",                                     \
      "open area of each vent")                                                                   \
    F(vents, discharge, vent_discharge_coefficient, f64, (V), finite_nonneg, "",                  \
      "discharge coefficient C_d of each vent")                                                   \
    F(vents, open_pressure, vent_open_pressure, f64, (V), none, "Pa",                             \
      "gauge pressure P - P_ambient at which each vent opens and stays open; inf: never by "     \
      "pressure")                                                                                 \
    F(vents, open_time, vent_open_time, f64, (V), none, "s",                                      \
      "time at which each vent opens; -inf: open from the start, inf: never by time")

#define SOFTBODY_FIELDS_ORIFICES(F)                                                               \
    F(orifices, bodies, orifice_bodies, i64, (O, 2), index(0, B), "",                             \
      "the two bodies (chambers) each orifice joins")                                             \
    F(orifices, area, orifice_area, f64, (O), finite_nonneg, "m^2",                               \
      "open area of each orifice")                                                                \
    F(orifices, discharge, orifice_discharge_coefficient, f64, (O), finite_nonneg, "",            \
      "discharge coefficient C_d of each orifice")

#define SOFTBODY_FIELDS_INFLATORS(F)                                                              \
    F(inflators, body, inflator_body, i64, (I), index(0, B), "",                                  \
      "body each inflator fills")                                                                 \
    F(inflators, temperature, inflator_temperature, f64, (I), finite_nonneg, "K",                 \
      "temperature of the gas each inflator delivers")                                            \
    F(inflators, range, inflator_range, i64, (I, 2), range(Q), "",                                \
      "[begin, end) rows of each inflator's mass-flow table")                                     \
    F(inflators, time, inflator_time, f64, (Q), finite, "s",                                      \
      "mass-flow table times, increasing within each inflator")                                   \
    F(inflators, mass_flow, inflator_mass_flow, f64, (Q), finite_nonneg, "kg/s",                  \
      "mass-flow table values, piecewise linear in time")

#define SOFTBODY_FIELDS_BENDING(F)                                                                \
    F(bending, hinges, bending_hinges, i64, (H, 4), index(0, N), "",                              \
      "particles of each hinge (interior edge): its edge x0, x1, then the corners x2 of the "     \
      "triangle (x0, x1, x2) and x3 of (x1, x0, x3); core/terms/bending.hpp")                     \
    F(bending, rest_angle, bending_rest_angle, f64, (H), finite, "rad",                           \
      "rest dihedral angle theta0 of each hinge, in (-pi, pi]; 0 is flat")                        \
    F(bending, stiffness, bending_stiffness, f64, (H), finite_nonneg, "N m",                      \
      "hinge stiffness k = D |e0|^2 / (2 A0) of each hinge; its energy is k (theta - theta0)^2") \
    F(bending, body, bending_body, i64, (H), index(0, B), "",                                     \
      "body of each hinge")

#define SOFTBODY_FIELDS_MEMBRANES(F)                                                              \
    F(membranes, indices, membrane_indices, i64, (Tm, 3), index(0, N), "",                       \
      "particle indices of each membrane triangle (core/terms/membrane.hpp)")                   \
    F(membranes, material, membrane_material, i64, (Tm), index(0, MembraneMaterial::kCount), "", \
      "MembraneMaterial of each membrane triangle")                                             \
    F(membranes, params, membrane_params, f64, (Tm, 2), finite, "Pa or 1",                       \
      "material parameters of each membrane triangle; (mu, 0) neo-Hookean, (c10, c01) "          \
      "Mooney-Rivlin [Pa], (E [Pa], nu) St Venant-Kirchhoff")                                    \
    F(membranes, thickness, membrane_thickness, f64, (Tm), finite_nonneg, "m",                   \
      "rest thickness H of each membrane triangle")                                             \
    F(membranes, rest_area, membrane_rest_area, f64, (Tm), finite_nonneg, "m^2",                 \
      "rest area A0 of each membrane triangle")                                                 \
    F(membranes, rest_inverse, membrane_rest_inverse, f64, (Tm, 2, 2), finite, "1/m",            \
      "inverse rest edge matrix Dm^-1 of each membrane triangle in its 2D rest frame")          \
    F(membranes, damping, membrane_damping, f64, (Tm), finite_nonneg, "s",                       \
      "strain-rate damping time beta of each membrane triangle; 0 for none")                    \
    F(membranes, body, membrane_body, i64, (Tm), index(-1, B), "",                               \
      "body of each membrane triangle")

// The parts: P(struct, member of Model, its fields, members it holds besides them).
#define SOFTBODY_MODEL_PARTS(P)                                                   \
    P(Particles, particles, SOFTBODY_FIELDS_PARTICLES, index count = 0;)          \
    P(Gravity, gravity, SOFTBODY_FIELDS_GRAVITY, )                                \
    P(Springs, springs, SOFTBODY_FIELDS_SPRINGS, index count = 0;)                \
    P(Attachments, attachments, SOFTBODY_FIELDS_ATTACHMENTS, index count = 0;)    \
    P(Triangles, triangles, SOFTBODY_FIELDS_TRIANGLES, index count = 0;)          \
    P(Bodies, bodies, SOFTBODY_FIELDS_BODIES, index count = 0;)                   \
    P(Volumes, volumes, SOFTBODY_FIELDS_VOLUMES, index mc_count = 0;)             \
    P(Gases, gases, SOFTBODY_FIELDS_GASES, index schedule_count = 0;)             \
    P(Pins, pins, SOFTBODY_FIELDS_PINS, index count = 0;)                         \
    P(Drag, drag, SOFTBODY_FIELDS_DRAG, )                                         \
    P(SoftContacts, soft_contacts, SOFTBODY_FIELDS_SOFT_CONTACTS, )               \
    P(Colliders, colliders, SOFTBODY_FIELDS_COLLIDERS, index count = 0;)          \
    P(ColliderMeshes, collider_meshes, SOFTBODY_FIELDS_COLLIDER_MESHES,           \
      index vertex_count = 0; index tri_count = 0; index node_count = 0;)         \
    P(Vents, vents, SOFTBODY_FIELDS_VENTS, index count = 0;)                      \
    P(Orifices, orifices, SOFTBODY_FIELDS_ORIFICES, index count = 0;)             \
    P(Inflators, inflators, SOFTBODY_FIELDS_INFLATORS, index count = 0; index table_count = 0;) \
    P(Bending, bending, SOFTBODY_FIELDS_BENDING, index count = 0;) \
    P(Membranes, membranes, SOFTBODY_FIELDS_MEMBRANES, index count = 0;)
