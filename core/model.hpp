// The plain views the kernels read and write: the model (constant), the control (per call),
// the state (changing) and a solver's scratch. Pointers into NumPy arrays owned by Python
// (bindings/core_model.hpp checks their shapes and indices once) or into buffers a solver owns. Rows of
// (n, 3) arrays are contiguous: x_i is p[3 i .. 3 i + 2].
#pragma once

#include "config.hpp"
#include "enums.hpp"
#include "fields.hpp"
#include "parallel.hpp"

namespace softbody {

/// Doubles per membrane triangle seen from a corner in the vertex-major tables (Slots:
/// ring_membrane, membrane_geometry): u, w, v (terms/membrane.hpp, lane_triangle).
constexpr int kMembraneGeometry = 3;

// The model's parts (SOFTBODY_MODEL_PARTS in fields.hpp), one struct each with its count and
// one member per field: an array as a pointer into NumPy memory, a number or a vec3 by
// value. A term's code names the part it reads (m.springs.stiffness, m.gases.law).
#define SOFTBODY_MEMBER_f64(name) const double* name = nullptr;
#define SOFTBODY_MEMBER_i64(name) const index* name = nullptr;
#define SOFTBODY_MEMBER_f64_value(name) double name = 0.0;
#define SOFTBODY_MEMBER_i64_value(name) index name = 0;
#define SOFTBODY_MEMBER_vec3(name) double name[3] = {0.0, 0.0, 0.0};
#define SOFTBODY_FIELD_MEMBER(part, member, python, type, shape, check, unit, doc) \
    SOFTBODY_MEMBER_##type(member)
#define SOFTBODY_PART_STRUCT(Type, part, fields, extra) \
    struct Type {                                       \
        extra fields(SOFTBODY_FIELD_MEMBER)             \
    };
SOFTBODY_MODEL_PARTS(SOFTBODY_PART_STRUCT)
#undef SOFTBODY_PART_STRUCT

/// Vertex-major neighbour tables (bindings/core_model.hpp derives them from the springs and
/// triangles): particles in groups of 8 lanes; group g's slots are [start[g], start[g + 1]),
/// and slot s holds, for lane l, entry 8 s + l. Each particle lists everything it belongs
/// to, so a pass over particles computes its own forces and writes nothing else's.
///
/// The ring: a particle's neighbours in fan order j_0, j_1, ..., so that consecutive ones
/// make its faces (i, j_{s-1}, j_s) and each neighbour's row serves its edge spring and two
/// faces. A closed fan's slot 0 closes the ring (face (i, j_last, j_0)); a shorter ring is
/// padded with j_0 (no spring, faces of no area).
struct Slots {
    index group_count = 0;                    // G = ceil(N / 8)
    const double* mass = nullptr;             // (8 G,) particle masses, 0 past N [kg]
    const index* reference = nullptr;         // (8 G,) first particle of its body
    const index* ring_start = nullptr;        // (G + 1,)
    const index* ring_other = nullptr;        // (slots, 8) neighbour j_s
    const double* ring_rest_length = nullptr; // (slots, 8) spring on (i, j_s) [m], or 0
    const double* ring_stiffness = nullptr;   // (slots, 8) [N/m], 0 without a spring
    const double* ring_damping = nullptr;     // (slots, 8) [N s/m]
    const double* ring_face = nullptr;        // (slots, 8) 1 where (j_{s-1}, j_s) is a face
    // springs off the rings (bending and user springs), with padding pointing at itself
    const index* spring_start = nullptr;        // (G + 1,)
    const index* spring_other = nullptr;        // (slots, 8)
    const double* spring_rest_length = nullptr; // (slots, 8) [m]
    const double* spring_stiffness = nullptr;   // (slots, 8) [N/m]
    const double* spring_damping = nullptr;     // (slots, 8) [N s/m]
    // faces of particles whose faces make no single fan (not met on a validated mesh)
    const index* face_start = nullptr;  // (G + 1,)
    const index* face_next = nullptr;   // (slots, 8) face (i, j, k) seen from i: j
    const index* face_last = nullptr;   // (slots, 8) and k
    // membrane triangles seen from each corner (terms/membrane.hpp, lane_triangle): per
    // ring slot s, the one on the ring's face (j_{s-1}, j_s) (slot 0: the closing face);
    // the others (a second layer, triangles off the rings) in their own slots, (i, next,
    // last). Each slot's geometry (kMembraneGeometry, 8): u, w, v, the rest frame's
    // gradient vectors of its two neighbours, (u, w) and (0, v) (all 0 for none), and its
    // coefficient row, an index into membrane_rows (R, 8) (row 0 zero).
    const double* ring_membrane = nullptr;       // (ring slots, 3, 8)
    const index* ring_membrane_row = nullptr;    // (ring slots, 8)
    const index* membrane_start = nullptr;       // (G + 1,)
    const index* membrane_next = nullptr;        // (slots, 8)
    const index* membrane_last = nullptr;        // (slots, 8)
    const double* membrane_geometry = nullptr;   // (slots, 3, 8)
    const index* membrane_row = nullptr;         // (slots, 8)
    const double* membrane_rows = nullptr;       // (R, 8) [Pa m]
    bool membrane_damped = false;  // some row has strain-rate damping
    bool membrane_one_row = false;  // every triangle has row 1 (one material)
};

/// Everything fixed after ModelBuilder.finalize (softbody.sim.model.Model), SI units,
/// grouped by what reads it: each term's parameters in its own part, so a term's code names
/// the part it uses (m.springs, m.gases, ...).
struct Model {
#define SOFTBODY_PART_MEMBER(Type, part, fields, extra) Type part;
    SOFTBODY_MODEL_PARTS(SOFTBODY_PART_MEMBER)
#undef SOFTBODY_PART_MEMBER
    Slots slots;  // derived by plan/lanes.cpp
};

/// Inputs held constant over one call (softbody.sim.control.Control).
struct Control {
    const double* gas_override = nullptr;       // (B,) NaN = the model's value or schedule
    const double* particle_f = nullptr;         // (N, 3) [N]
    const double* attachment_anchor = nullptr;  // (A, 3) [m]
    const double* pin_target = nullptr;         // (P, 3) [m]
    bool pin_active = false;
    const double* collider_target = nullptr;  // (C, 3) [m], NaN = prescribed motion
    index grab_particle = -1;
    double grab_target[3] = {0.0, 0.0, 0.0};  // [m]
    double grab_stiffness = 0.0;              // [N/m]
    double grab_damping = 0.0;                // [N s/m]
    double wind[3] = {0.0, 0.0, 0.0};         // [m/s] the air's velocity in this call
    const double* vent_area = nullptr;        // (V,) [m^2], NaN = the model's (a valve)
    const double* orifice_area = nullptr;     // (O,) [m^2], NaN = the model's
    const double* inflator_flow = nullptr;    // (I,) [kg/s], NaN = the inflator's table
};

/// The changing state a run advances in place (softbody.sim.state.State).
struct StateView {
    double* q = nullptr;                 // (N, 3) [m]
    double* qd = nullptr;                // (N, 3) [m/s]
    double* collider_q = nullptr;        // (C, 3) [m]
    double* collider_rot = nullptr;      // (C, 3, 3)
    double* collider_impulse = nullptr;  // (C, 3) [N s], accumulated over the call
    double* gas_moles = nullptr;         // (B,) amount of gas in each body [mol]
    double* gas_temperature = nullptr;   // (B,) its temperature [K]
    double* vent_open = nullptr;         // (V,) 1 once a vent has opened, else 0
};

/// Rows (B,) of BodyGas::work: the schemes' gas stages (solvers/gas_state.hpp).
constexpr int kGasWorkSlots = 9;

/// What the gas terms compute once per force evaluation, per body.
struct BodyGas {
    double* volume = nullptr;           // (B,) [m^3]
    double* pressure = nullptr;         // (B,) [Pa]
    double* volume_gradient = nullptr;  // (N, 3) dV/dx [m^2]
    double* lo = nullptr;               // (B, 3) bounds of bodies with a bounding or MC volume
    double* hi = nullptr;               // (B, 3)
    // The gas state of this evaluation (terms/flows.hpp): amount n [mol] and theta [K], the
    // temperature the gas would have at its reference volume after an isentropic change
    // (the temperature itself for an isothermal gas), so that nRT = R n theta drives the
    // gas law in closed form. Null moles: the model's value drives it (a call without a
    // state: the diagnostics pass the state's value as an override).
    const double* moles = nullptr;      // (B,)
    const double* theta = nullptr;      // (B,)
    // What the flow terms add up at this evaluation (flows.hpp), per body: molar inflow
    // [mol/s], inflow times its temperature [mol K/s] and outflow [mol/s]; the surface area
    // [m^2] (leaks), and the step h [s] the outflow limiter divides by.
    double* flow_in = nullptr;          // (B,)
    double* flow_in_t = nullptr;        // (B,)
    double* flow_out = nullptr;         // (B,)
    double* area = nullptr;             // (B,)
    const double* vent_open = nullptr;  // (V,) the state's latches
    double flow_step = 0.0;
    double* work = nullptr;             // (kGasWork, B) the schemes' gas stages (gas_state.hpp)
};

/// The surface contacts' hash entries (triangle indices): a buffer its owner grows when a
/// step's triangles need more room than it holds (grow: false when it cannot, then the run
/// stops with NEED_HASH), so a run never leaves the core to make room.
struct HashEntries {
    index capacity = 0;      // E, the entries the buffer holds
    index* data = nullptr;   // (E,)
    bool (*grow)(HashEntries& self, index needed) = nullptr;  // null: a fixed buffer
    void* owner = nullptr;
};

/// Scratch for contacts, owned by a solver.
struct ContactBuffers {
    double* body_lo = nullptr;        // (B, 3)
    double* body_hi = nullptr;        // (B, 3)
    double* body_velocity = nullptr;  // (B, 3) mass-weighted mean velocity [m/s]
    double* body_mass = nullptr;      // (B,) [kg]
    double* body_center = nullptr;    // (B, 3)
    double* body_axes = nullptr;      // (B, 3)
    double* body_dv = nullptr;        // (B, 3)
    double* collider_q_start = nullptr;  // (C, 3)
    double* collider_v = nullptr;        // (C, 3)
    double* collider_w = nullptr;        // (C, 3)
    // Surface contacts' spatial hash of triangle boxes (soft_contact_mode 2): bucket h holds
    // hash_entries[hash_start[h] .. hash_start[h + 1]); H is a power of two >= 2 T.
    index hash_table = 0;         // H
    HashEntries* hash_entries = nullptr;  // the entries (triangle indices), grown as needed
    index* hash_start = nullptr;  // (H + 1,)
    index* hash_count = nullptr;  // (H,)
    // Surface contacts with a thickness (collision/thick.hpp): the candidate pairs, kPairSlots
    // entries each (kind, four particles, the distance's bits at the step's start, and at
    // the list's build), grown as needed; the positions before the response (N, 3), each
    // particle's displacement scale (N,), the triangles' boxes (T, 6), and where a crossing
    // was found (particle, triangle).
    static constexpr index kPairSlots = 7;
    HashEntries* pairs = nullptr;
    double* q_pre = nullptr;      // (N, 3)
    double* scale = nullptr;      // (N,)
    double* tri_box = nullptr;    // (T, 6)
    index* crossing = nullptr;    // (2,)
    // The pair list kept between steps: the positions it was built at (N, 3); its pair
    // count (-1: none yet, build it), the rows the last step read (a prefix of w.pairs, their
    // distance at the step's start fresh), and which buffer could not grow (0 the hash, 1 the
    // list); its skin [m] and the steps it has served; each particle's box for a gather
    // (N, 6: lo, hi).
    double* q_build = nullptr;    // (N, 3)
    index* list = nullptr;        // (3,)
    double* list_skin = nullptr;  // (22,): the skin, the steps served, the drift's fit (thick::Fit)
    double* particle_box = nullptr;  // (N, 6)
    // a gather's scratch: the last look-up that met each triangle (T,), each particle's
    // first triangle (N,; -1: none), and which of each triangle's corners and edges it owns
    // (T,; bit k: corner k, bit 3 + k: edge k)
    index* tri_mark = nullptr;      // (T,)
    index* vertex_owner = nullptr;  // (N,)
    index* tri_owns = nullptr;      // (T,)
    // the positions the colliders left before the thickness contacts (N, 3), and the
    // inverse masses the stage sees (N,): 0 for the particles the colliders caught
    double* q_collided = nullptr;
    double* held_inv_mass = nullptr;
    double* q_solved = nullptr;  // (N, 3) the solver's positions, before any contact
    double* held = nullptr;      // (N, 8) thick::hold's moves, groups and their sums
};

/// Scratch of the vertex-major force pass.
struct LaneBuffers {
    double* rows = nullptr;       // (8 G, 8) x, y, z, vx, vy, vz, 0, 0 per particle
    double* lane_pnet = nullptr;  // (8 G,) P - P_ambient of each particle's body [Pa], 0 free
    const Parallel* parallel = nullptr;  // opt-in threads (null: serial)
    double* chunk_volume = nullptr;      // (chunks, B) each chunk's share of the volumes
    // The float32 force pass (set: the pass runs in float32; null: float64). Its rows hold
    // x - x_ref (the particle's body's first particle: body-local, so float32 keeps
    // 2^-24 of the body's size) and v; the ring tables are float copies of the model's.
    float* rows_f = nullptr;                    // (8 G, 8) x - x_ref, v, 0, 0 per particle
    const float* ring_rest_length_f = nullptr;  // (slots, 8) as Model.slots.ring_* [m]
    const float* ring_stiffness_f = nullptr;    // [N/m]
    const float* ring_damping_f = nullptr;      // [N s/m]
    const float* ring_face_f = nullptr;         // 1 where (j_{s-1}, j_s) is a face
    bool extra_slots = false;  // the model has springs off the rings, broken fans or membranes
};

/// Scratch for the explicit schemes, owned by softbody::ExplicitSolver.
struct ExplicitBuffers {
    LaneBuffers lanes;
    double* f = nullptr;      // (N, 3) force accumulator [N]
    double* q0 = nullptr;     // (N, 3) start-of-step positions
    double* v0 = nullptr;     // (N, 3) start-of-step velocities
    double* qs = nullptr;     // (N, 3) stage positions
    double* vs = nullptr;     // (N, 3) stage velocities
    double* acc_q = nullptr;  // (N, 3) RK4 sums
    double* acc_v = nullptr;  // (N, 3)
    BodyGas gas;
    ContactBuffers contact;
};

/// The implicit schemes' multigrid hierarchy (softbody.solvers.multigrid.Multigrid):
/// views of the arrays Python built (bindings/implicit.cpp checks every offset and index once), and
/// the V-cycle's scratch, owned by the solver. Level l has level_size[l] unknowns; its
/// matrix A_l is CSR at rows a_row_offset[l] of a_indptr and entries a_nz_offset[l] of
/// a_indices / a_data; P_l (level l to l + 1) likewise in p_*; its vectors sit at rows
/// vec_offset[l] of x, b, r.
/// The most terms a registry holds (terms/registry.hpp; kernels.cpp checks it).
constexpr int kMaxTerms = 16;

/// One registered term's off-diagonal blocks of the implicit system in the multigrid
/// smoother (a kStencil term, terms/term.hpp): each particle's entries as CSR sorted by the
/// neighbour j (Python builds them: softbody.solvers.multigrid.STENCILS), the term's own
/// map from its couplings to entries (springs: each entry's spring (E,); membranes: each
/// triangle's corner pair's entry (Tm, 3, 3), -1 on its diagonal), and each entry's
/// coefficients (E, the term's kStencilWidth), scratch its add_smoother_blocks fills for
/// the step and its add_entries reads.
struct Stencil {
    index count = 0;                  // E
    const index* ptr = nullptr;       // (N + 1,)
    const index* neighbor = nullptr;  // (E,)
    const index* map = nullptr;       // the term's
    double* coef = nullptr;           // (E, width)
};

struct MultigridView {
    index level_count = 0;     // L: sparse levels (prolongators)
    bool coarse_dense = false; // the coarsest level is solved by its Cholesky factor
    const index* level_size = nullptr;    // (L + 1,)
    const index* vec_offset = nullptr;    // (L + 2,)
    const index* a_row_offset = nullptr;  // (L + 1,)
    const index* a_nz_offset = nullptr;   // (L + 1,)
    const index* a_indptr = nullptr;
    const index* a_indices = nullptr;
    const double* a_data = nullptr;  // A_l at the current step (set_multigrid_step)
    const double* a_diag = nullptr;  // (sum n_l,) diagonal of each A_l
    const index* p_row_offset = nullptr;  // (max(L, 1),)
    const index* p_nz_offset = nullptr;
    const index* p_indptr = nullptr;
    const index* p_indices = nullptr;
    const double* p_data = nullptr;
    const double* coarse_cholesky = nullptr;  // (n_L, n_L) lower factor when coarse_dense
    // the finest level's off-diagonal blocks, each kStencil term's at its registry position
    Stencil stencils[kMaxTerms];
    // scratch
    double* block = nullptr;       // (N, 3, 3) diagonal blocks of the true matrix
    double* block_inv = nullptr;   // (N, 3, 3) their inverses
    double* x = nullptr;           // (sum n_l, 3) level solutions
    double* b = nullptr;           // (sum n_l, 3) level right-hand sides
    double* r = nullptr;           // (sum n_l, 3) level residuals
};

/// Scratch and history of the implicit schemes, owned by softbody::ImplicitSolver.
struct ImplicitBuffers {
    LaneBuffers lanes;
    double* f = nullptr;      // (N, 3) forces at the step's start [N]
    double* q0 = nullptr;     // (N, 3) start-of-step positions
    double* v0 = nullptr;     // (N, 3) start-of-step velocities
    double* qs = nullptr;     // (N, 3) y, the position change before dv; BDF2's contact check
    double* vs = nullptr;     // (N, 3) BDF2's contact check
    double* ky = nullptr;     // (N, 3) K y
    // each registered term's linearisation at the step's start (Linearization::scratch)
    double* linearization[kMaxTerms] = {};
    double* cg_diag = nullptr;   // (N,) Jacobi preconditioner [kg]
    double* cg_r = nullptr;      // (N, 3) residual
    double* cg_z = nullptr;      // (N, 3) preconditioned residual
    double* cg_p = nullptr;      // (N, 3) search direction
    double* cg_ap = nullptr;     // (N, 3) system matrix times p
    double* cg_x = nullptr;      // (N, 3) dv [m/s]; kept between steps (the warm start)
    double* q_prev = nullptr;    // (N, 3) BDF2: the previous step's start
    double* v_prev = nullptr;    // (N, 3)
    index* contacts_acted = nullptr;  // (1,) BDF2: the last step's contacts acted
    index* cg_stats = nullptr;        // (3,) steps, CG iterations in all, most in one
    BodyGas gas;
    ContactBuffers contact;
};

/// Projective dynamics' factored global matrix A = P^T L D L^T P (softbody.solvers.
/// factor.Projective; bindings/projective.cpp checks its structure once). perm[r] is the particle at
/// row r; inv_diag = 1 / diag(D). L (unit lower triangular) is stored by supernodes: node s
/// holds columns [node_col[s], node_col[s + 1]), its rows node_row[node_row_ptr[s] ..
/// node_row_ptr[s + 1]) (its own columns first, then those below), and its values a dense
/// row-major (rows, columns) block from node_value[node_value_ptr[s]].
struct Factor {
    index size = 0;        // N, 0 when no factor is set
    index node_count = 0;  // S
    double dt = 0.0;       // [s] the step the matrix was built for
    const index* perm = nullptr;            // (N,)
    const double* inv_diag = nullptr;       // (N,) [s^2/kg]
    const index* node_col = nullptr;        // (S + 1,)
    const index* node_row_ptr = nullptr;    // (S + 1,)
    const index* node_row = nullptr;        // (R,)
    const index* node_value_ptr = nullptr;  // (S + 1,)
    const double* node_value = nullptr;     // (V,)
};

/// Scratch for projective dynamics, owned by softbody::ProjectiveSolver.
struct ProjectiveBuffers {
    LaneBuffers lanes;
    double* f = nullptr;    // (N, 3) the non-spring forces at the iterate [N]
    double* q0 = nullptr;   // (N, 3) start-of-step positions
    double* v0 = nullptr;   // (N, 3) start-of-step velocities
    double* y = nullptr;    // (N, 3) inertial target x0 + dt v0
    double* rhs = nullptr;  // (N, 3) the global step's right-hand side, particle order
    double* x = nullptr;    // (N, 3) the triangular solves' vector, factor order
    BodyGas gas;
    ContactBuffers contact;
};

/// Doubles per membrane triangle in its linearisation (Linearization::own): two symmetric 6 x 6
/// blocks by their upper triangles (terms/membrane.hpp).
constexpr int kMembraneBlock = 42;

/// XPBD's scratch (solvers/substep.hpp) and the springs' colouring it sweeps in.
struct SubstepBuffers {
    LaneBuffers lanes;
    double* f = nullptr;       // (N, 3) the explicit forces at the substep's start [N]
    double* q0 = nullptr;      // (N, 3) start-of-step positions
    double* v0 = nullptr;      // (N, 3) start-of-step velocities
    double* q_prev = nullptr;  // (N, 3) start-of-substep positions
    // (N, kRow) the constraint pass's rows: the iterate x, y, z, the substep's start x, y,
    // z, two doubles of padding (ConstraintPass)
    double* rows = nullptr;
    double* spring_lambda = nullptr;      // (S,) [N s^2]
    double* attachment_lambda = nullptr;  // (A,) [N s^2]
    double* spring_coef = nullptr;        // (6, S) the springs' constants for the substep
    const index* spring_ends = nullptr;   // (2, S) the ends of spring_order's springs
    const index* spring_order = nullptr;  // (S,) the springs, colour by colour
    const index* colour_ptr = nullptr;    // (colours + 1,)
    index colours = 0;
    BodyGas gas;
    ContactBuffers contact;
};

/// The implicit solvers' linearisation at a point q (N, 3): what `prepare` writes and
/// `jacobian_product` / `add_smoother_blocks` / `add_jacobi_diagonal` read. Each
/// registered term keeps what it needs in its own scratch, its `linearization_size`
/// doubles in its layout (terms/term.hpp), at scratch[k] for the term at registry position
/// k; forms:: hands each term its own as `own` (null where the term has none: a term that
/// can compute its part at q as it goes, bending and membranes, then does).
struct Linearization {
    const double* q = nullptr;                // (N, 3) the point [m]
    const double* volume_gradient = nullptr;  // (N, 3) dV/dx [m^2] (the gas state's at q)
    double* const* scratch = nullptr;         // (kMaxTerms,) each term's scratch, or null
    double* own = nullptr;                    // the term's own (set by forms:: per term)
};

/// The multigrid smoother's diagonal blocks and one term's off-diagonal entries
/// (MultigridView's scratch), for step h [s].
struct SmootherBlocks {
    double h = 0.0;
    double* block = nullptr;  // (N, 3, 3) set to M, then each term adds its share
    Stencil entries;          // the term's own stencil (kStencil), its coef to fill; else empty
};

/// A registered term's name and traits (terms/term.hpp), for the bindings and Python.
struct TermTraits {
    const char* name = "";
    bool lane = false, projected = false, fused = false, energy = false, external = false,
         flow = false, bound = false, shared_rows = false, volume_mode = false;
    int stencil_width = 0;  // numbers per smoother entry of a kStencil term, else 0
};

/// A term's own part of the stability estimate (its `bound` form, terms/term.hpp): the
/// largest Gershgorin rows of its stiffness against the masses by part, [damped, undamped,
/// whole] [1/s^2] and its damping rate [1/s] (springs::BoundPart's order), which the
/// estimate adds to the other terms' (Weyl; the kSharedRows terms' take the largest of
/// theirs, one Gershgorin bound on their sum); of those, `mode` [1/s^2], the eigenvalue of
/// a kVolumeMode term's volume mode (the gas's rank-one P'(V) g g^T, included in parts 1
/// and 2); its damping per stiffness c / k [s], folded into [ratio_min, ratio_max]; and
/// pure_dampers, set where it has a damper without stiffness (c > 0, k = 0).
struct TermBound {
    double parts[4] = {0.0, 0.0, 0.0, 0.0};
    double mode = 0.0;
    double ratio_min = std::numeric_limits<double>::infinity();
    double ratio_max = -std::numeric_limits<double>::infinity();
    bool pure_dampers = false;
};

/// The stability estimate's four operators (softbody.stability.spectral_bounds), in
/// TermBound::parts' order: the damped stiffness (what the dampers act on), the undamped
/// stiffness, the whole stiffness, and the damping matrix. Each term's spectral_product
/// form (terms/term.hpp) says which of its stiffness goes into which.
enum class StiffnessPart : int { kDamped = 0, kUndamped = 1, kWhole = 2, kDamping = 3 };
constexpr int kStiffnessParts = 4;

/// What the terms' `bound` forms share (kernels.cpp: stiffness_bounds): scratch, the
/// Gershgorin row sums the kSharedRows terms fill first, and the state at which the
/// estimate took its linearisation, which softbody.stability's spectral part reuses.
struct BoundScratch {
    double* root_sum = nullptr;         // (N, 4) R_i by part, every add_row_sums form's
    double* rows = nullptr;             // (N, 2) scratch of one bound form
    double* body_pnet = nullptr;        // (B,) out: P - P_a at the largest scheduled gas [Pa]
    double* body_dpdv = nullptr;        // (B,) out: P'(V) [Pa/m^3]
    double* volume_gradient = nullptr;  // (N, 3) out: exact dV/dx [m^2], 0 off bodies
};

/// Outcome of a run of steps (softbody.solvers.Status).
/// OK; NONFINITE: a position or velocity became NaN or infinite; RUNAWAY: a particle moved
/// faster than the speed limit; BAD_VOLUME: a body volume became NaN, zero or negative;
/// SHRUNK / EXPLODED: a body volume fell below / grew past its limit; NEED_HASH: the
/// spatial hash needs more room; BAD_GAS: a body's gas amount or temperature became
/// negative or not finite (value: the amount [mol]); CROSSED: surface contacts with a thickness
/// found an edge through a triangle at a step's start (where: the edge's first particle,
/// value: the triangle); NEED_PAIRS: their pair list needs more room than it can grow to
/// (value: the pairs); STOPPED: RunParams::poll asked to stop (an interrupt), the
/// steps done are kept (enums.hpp lists them).
enum Status : int { SOFTBODY_ENUM_STATUS(SOFTBODY_ENUM_MEMBER) };

struct RunResult {
    int status = OK;
    index steps_done = 0;
    index where = -1;    // body or particle at fault
    double value = 0.0;  // the offending quantity
};

/// The implicit schemes' settings for one run.
struct ImplicitParams {
    bool bdf2 = false;          // BDF2, else backward Euler
    double tolerance = 1e-6;    // CG's relative residual
    index max_iterations = 200; // CG iterations per step at most
    bool history = false;       // the buffers hold the step before the state (BDF2)
};

/// The run's limits and its step.
struct RunParams {
    int scheme = Integrator::SYMPLECTIC_EULER;  // an explicit scheme (0-4)
    index iterations = 0;  // projective dynamics: local-global iterations per step
    index substeps = 1;    // XPBD: substeps per step (iterations: its passes per substep)
    double relaxation = 1.0;  // XPBD: over-relaxation of the passes after a substep's first
    index steps = 0;
    // the time of step k of this run [s]: t0 + (step0 + k) dt, t0 the time of the state's
    // clock origin and step0 the steps it took since (the bindings keep the origin across
    // runs of one step dt, so that n runs of one step keep the same times as one of n)
    double t0 = 0.0, dt = 0.0, step0 = 0.0;
    double time_at(index k) const { return t0 + (step0 + static_cast<double>(k)) * dt; }
    double max_speed = 1e4;
    double ratio_min = 1e-3, ratio_max = 1e3;
    // Called before every step with the steps done so far; nonzero stops the run with
    // STOPPED (the bindings: Python's signal handlers and a progress callback, so Ctrl-C
    // stops a long run between two steps). It rate-limits itself; null: never called.
    int (*poll)(void* context, index steps_done) = nullptr;
    void* poll_context = nullptr;
};

/// Whether the run's poll asks to stop before step `step_index` (the steps before it done):
/// every solver's step loop asks first thing in each step.
inline bool stop_requested(const RunParams& p, index step_index) {
    return p.poll != nullptr && p.poll(p.poll_context, step_index) != 0;
}

}  // namespace softbody
