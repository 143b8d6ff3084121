// The physics terms outside a time loop: forces, volumes, pressures, energies, Jacobian
// products, the stability estimate's bounds and its split products (SpectralOperator) at a
// state, and one contact pass (diagnostics, the stability estimate, tests).
#include "bindings/bindings.hpp"
#include "bindings/buffers.hpp"

namespace softbody::bindings {
namespace {

/// Forces, volumes, dV/dx and pressures at (q, qd, t): for diagnostics and tests.
nb::tuple eval_forces(const CoreModel& core, nb::handle control, double t, ConstF64 q,
                      ConstF64 qd) {
    const softbody::Model& m = core.model();
    check_shape(q, "q", {m.particles.count, 3});
    check_shape(qd, "qd", {m.particles.count, 3});
    CoreControl c(m, control);
    Buffers b(m, 1);
    {
        nb::gil_scoped_release release;
        softbody::kernels().eval_forces(m, c.view, t, q.data(), qd.data(), b.gas,
                                        b.lanes_view, b.row(0));
    }
    auto out = [](const double* data, std::vector<size_t> shape) {
        size_t count = 1;
        for (size_t s : shape) count *= s;
        double* copy = new double[count];
        std::copy(data, data + count, copy);
        nb::capsule owner(copy, [](void* p) noexcept { delete[] static_cast<double*>(p); });
        return nb::ndarray<nb::numpy, double>(copy, shape.size(), shape.data(), owner);
    };
    const size_t n = static_cast<size_t>(m.particles.count), nb_ = static_cast<size_t>(m.bodies.count);
    return nb::make_tuple(out(b.row(0), {n, 3}), out(b.gas.volume, {nb_}),
                          out(b.gas.pressure, {nb_}), out(b.gas.volume_gradient, {n, 3}));
}

/// Every body's volume by its own method at q, with dV/dx when asked.
nb::tuple eval_volumes(const CoreModel& core, nb::handle control, double t, ConstF64 q) {
    const softbody::Model& m = core.model();
    check_shape(q, "q", {m.particles.count, 3});
    CoreControl c(m, control);
    Buffers b(m, 0);
    {
        nb::gil_scoped_release release;
        softbody::kernels().eval_gas(m, c.view, t, q.data(), b.gas);
    }
    auto out = [](const double* data, std::vector<size_t> shape) {
        size_t count = 1;
        for (size_t s : shape) count *= s;
        double* copy = new double[count];
        std::copy(data, data + count, copy);
        nb::capsule owner(copy, [](void* p) noexcept { delete[] static_cast<double*>(p); });
        return nb::ndarray<nb::numpy, double>(copy, shape.size(), shape.data(), owner);
    };
    const size_t n = static_cast<size_t>(m.particles.count), nb_ = static_cast<size_t>(m.bodies.count);
    return nb::make_tuple(out(b.gas.volume, {nb_}), out(b.gas.pressure, {nb_}),
                          out(b.gas.volume_gradient, {n, 3}));
}

/// One pass of the soft-soft contacts on q, qd in place (for tests of the response);
/// returns the hash entries the surface contacts needed beyond hash_capacity, or 0.
Index soft_contacts(const CoreModel& core, F64 q, F64 qd, std::optional<Index> hash_capacity) {
    const softbody::Model& m = core.model();
    check_shape(q, "q", {m.particles.count, 3});
    check_shape(qd, "qd", {m.particles.count, 3});
    Buffers b(m, 0, checked_capacity(m, hash_capacity));
    nb::gil_scoped_release release;
    return softbody::kernels().soft_contacts(m, q.data(), qd.data(), b.contact);
}

/// The thickness contacts' candidate pairs nearer than `radius` [m] at q (N, 3), gathered
/// as the pair list's build gathers them (for tests of its broad and narrow phase): (kinds
/// (P,): 0 vertex-triangle, 1 edge-edge; particles (P, 4); distances (P,) [m] at q). With
/// q_end (N, 3), the candidates of a step from q to q_end as the contact stage's swept
/// gather finds them, its boxes grown by `radius`.
nb::tuple contact_pairs(const CoreModel& core, ConstF64 q, double radius,
                        std::optional<ConstF64> q_end, std::optional<ConstF64> q_later,
                        double slack) {
    const softbody::Model& m = core.model();
    check_shape(q, "q", {m.particles.count, 3});
    if (q_end) check_shape(*q_end, "q_end", {m.particles.count, 3});
    if (q_later && !q_end) fail("q_later needs q_end");
    if (q_later) check_shape(*q_later, "q_later", {m.particles.count, 3});
    if (!(slack >= 0.0) || !std::isfinite(slack))
        fail("slack must be finite and >= 0, got " + std::to_string(slack));
    if (m.soft_contacts.mode != SoftContactMode::SURFACE || !(m.soft_contacts.thickness > 0.0))
        fail("contact_pairs needs surface soft contacts with a thickness");
    if (!(radius > 0.0) || !std::isfinite(radius))
        fail("radius must be finite and > 0, got " + std::to_string(radius));
    std::vector<double> x(q.data(), q.data() + q.size());
    std::vector<double> end, later;
    if (q_end) end.assign(q_end->data(), q_end->data() + q_end->size());
    if (q_later) later.assign(q_later->data(), q_later->data() + q_later->size());
    Buffers b(m, 0, checked_capacity(m, std::nullopt));
    b.allow_growth();
    Index pairs = 0;
    {
        nb::gil_scoped_release release;
        pairs = softbody::kernels().contact_pairs(m, x.data(), radius,
                                                  q_end ? end.data() : nullptr, b.contact,
                                                  q_later ? later.data() : nullptr, slack);
    }
    if (pairs == -1)
        fail("an edge at particle " + std::to_string(b.contact.crossing[0]) +
             " passes through triangle " + std::to_string(b.contact.crossing[1]));
    if (pairs < 0) fail("the contact pairs do not fit their buffers");
    const size_t n = static_cast<size_t>(pairs);
    Index* kinds = new Index[n];
    Index* particles = new Index[4 * n];
    double* distances = new double[n];
    const Index* rows = b.contact.pairs->data;
    for (size_t p = 0; p < n; ++p) {
        const Index* row = rows + softbody::ContactBuffers::kPairSlots * p;
        kinds[p] = row[0];
        for (size_t k = 0; k < 4; ++k) particles[4 * p + k] = row[1 + k];
        std::memcpy(distances + p, row + 5, sizeof(double));
    }
    nb::capsule own_k(kinds, [](void* p) noexcept { delete[] static_cast<Index*>(p); });
    nb::capsule own_p(particles, [](void* p) noexcept { delete[] static_cast<Index*>(p); });
    nb::capsule own_d(distances, [](void* p) noexcept { delete[] static_cast<double*>(p); });
    const size_t shape_p[2] = {n, 4};
    return nb::make_tuple(nb::ndarray<nb::numpy, Index>(kinds, {n}, own_k),
                          nb::ndarray<nb::numpy, Index>(particles, 2, shape_p, own_p),
                          nb::ndarray<nb::numpy, double>(distances, {n}, own_d));
}

/// The thickness contacts' stage run over frames (F, N, 3): step k from frames[k] to
/// frames[k + 1] (the stage's bound and response act on a copy, the next step starts at
/// frames[k + 1] whatever they did), its pair list kept between the steps as a solver's
/// run keeps it (for tests of the list): after each step (counts (F - 1,): the list's
/// rows, -1 when the step dropped it; rows (sum of counts, 5): each listed pair's kind and
/// four particles; q_build (F - 1, N, 3): the positions the list was built at; skins
/// (F - 1,): its skin S [m], its radius 2 h + S).
nb::tuple contact_list(const CoreModel& core, ConstF64 frames) {
    const softbody::Model& m = core.model();
    if (m.soft_contacts.mode != SoftContactMode::SURFACE || !(m.soft_contacts.thickness > 0.0))
        fail("contact_list needs surface soft contacts with a thickness");
    if (frames.ndim() != 3 || frames.shape(0) < 2 ||
        static_cast<Index>(frames.shape(1)) != m.particles.count || frames.shape(2) != 3)
        fail("frames must have shape (F >= 2, " + std::to_string(m.particles.count) + ", 3)");
    const size_t n3 = static_cast<size_t>(3 * m.particles.count);
    const size_t steps = frames.shape(0) - 1;
    Buffers b(m, 0, checked_capacity(m, std::nullopt));
    b.allow_growth();
    std::vector<double> q(n3), qd(n3, 0.0);
    std::vector<Index> counts(steps), rows;
    std::vector<double> built(steps * n3), skins(steps);
    for (size_t k = 0; k < steps; ++k) {
        const double* q0 = frames.data() + k * n3;
        std::copy(q0 + n3, q0 + 2 * n3, q.begin());
        std::fill(qd.begin(), qd.end(), 0.0);
        Index status = 0;
        {
            nb::gil_scoped_release release;
            status = softbody::kernels().contact_stage(m, q0, q.data(), qd.data(), b.contact);
        }
        if (status == -1)
            fail("step " + std::to_string(k) + ": an edge at particle " +
                 std::to_string(b.contact.crossing[0]) + " passes through triangle " +
                 std::to_string(b.contact.crossing[1]));
        if (status != 0) fail("step " + std::to_string(k) + ": the pairs do not fit their buffers");
        counts[k] = b.contact.list[0];
        const Index* data = b.contact.pairs->data;
        for (Index p = 0; p < counts[k]; ++p)
            for (Index j = 0; j < 5; ++j)
                rows.push_back(data[softbody::ContactBuffers::kPairSlots * p + j]);
        std::copy(b.contact.q_build, b.contact.q_build + n3, built.begin() + k * n3);
        skins[k] = b.contact.list_skin[0];
    }
    auto* c = new std::vector<Index>(std::move(counts));
    auto* r = new std::vector<Index>(std::move(rows));
    auto* x = new std::vector<double>(std::move(built));
    auto* s = new std::vector<double>(std::move(skins));
    nb::capsule own_c(c, [](void* p) noexcept { delete static_cast<std::vector<Index>*>(p); });
    nb::capsule own_r(r, [](void* p) noexcept { delete static_cast<std::vector<Index>*>(p); });
    nb::capsule own_x(x, [](void* p) noexcept { delete static_cast<std::vector<double>*>(p); });
    nb::capsule own_s(s, [](void* p) noexcept { delete static_cast<std::vector<double>*>(p); });
    const size_t shape_r[2] = {r->size() / 5, 5};
    const size_t shape_x[3] = {steps, static_cast<size_t>(m.particles.count), 3};
    return nb::make_tuple(nb::ndarray<nb::numpy, Index>(c->data(), {steps}, own_c),
                          nb::ndarray<nb::numpy, Index>(r->data(), 2, shape_r, own_r),
                          nb::ndarray<nb::numpy, double>(x->data(), 3, shape_x, own_x),
                          nb::ndarray<nb::numpy, double>(s->data(), {steps}, own_s));
}

/// The registry position of the term called `name`.
int term_position(const std::string& name) {
    const softbody::KernelTable& k = softbody::kernels();
    for (int t = 0; t < k.term_count; ++t)
        if (name == k.terms[t].name) return t;
    fail("no registered term is called " + name);
    return -1;
}

/// Every registered term's linearisation scratch for a model: one buffer each, sized by
/// the term's linearization_size (terms/term.hpp), and the table of them (Linearization).
struct TermScratch {
    explicit TermScratch(const softbody::Model& m) {
        const softbody::KernelTable& k = softbody::kernels();
        for (int t = 0; t < k.term_count; ++t) {
            own[t].assign(static_cast<size_t>(k.linearization_size(t, m)), 0.0);
            table[t] = own[t].data();
        }
    }
    std::vector<double> own[softbody::kMaxTerms];
    double* table[softbody::kMaxTerms] = {};
};

/// The implicit schemes' matrix-free product at q and time t, every term's linearisation
/// by its own prepare form there, or (a term named in `linearization`) the caller's, in the
/// term's layout; terms named in leave_out left out.
void apply_jacobians(const CoreModel& core, nb::handle control, ConstF64 q, ConstF64 p,
                     double alpha_m, double alpha_c, double alpha_k, F64 out, double t,
                     nb::dict linearization, std::optional<ConstF64> volume_gradient,
                     std::vector<std::string> leave_out) {
    const softbody::Model& m = core.model();
    const Index n = m.particles.count;
    check_shape(q, "q", {n, 3});
    check_shape(p, "p", {n, 3});
    check_shape(out, "out", {n, 3});
    if (volume_gradient) check_shape(*volume_gradient, "volume_gradient", {n, 3});
    CoreControl c(m, control);
    const softbody::KernelTable& k = softbody::kernels();
    unsigned skip = 0;
    for (const std::string& name : leave_out) skip |= 1u << term_position(name);
    std::vector<std::pair<int, ConstF64>> given;
    for (auto [key, value] : linearization) {
        std::string name;
        if (!nb::try_cast(key, name)) fail("linearization's keys must be term names");
        const int term = term_position(name);
        const std::string what = "linearization[" + name + "]";
        ConstF64 a;
        if (!nb::try_cast(value, a, false)) fail(what + " must be a C-contiguous float64 array");
        check_shape(a, what, {k.linearization_size(term, m)});
        given.emplace_back(term, a);
    }
    Buffers b(m, 0);
    TermScratch scratch(m);
    softbody::Linearization l;
    l.q = q.data();
    l.volume_gradient = b.gas.volume_gradient;
    l.scratch = scratch.table;
    nb::gil_scoped_release release;
    k.prepare(m, c.view, t, b.gas, l);
    for (const auto& [term, a] : given) std::copy(a.data(), a.data() + a.size(), scratch.table[term]);
    if (volume_gradient) l.volume_gradient = volume_gradient->data();
    k.apply_jacobians(m, c.view, l, p.data(), alpha_m, alpha_c, alpha_k, skip, out.data());
}

/// softbody._core.SpectralOperator: the stability estimate's four operators at one state
/// (StiffnessPart), each term's linearisation prepared once for every product.
class SpectralOperator {
public:
    SpectralOperator(nb::object model, nb::object control, ConstF64 q, ConstF64 body_pnet,
                     ConstF64 body_dpdv, ConstF64 volume_gradient)
        : handle_(model),
          model_(nb::cast<const CoreModel&>(model)),
          control_(model_.model(), control),
          buffers_(model_.model(), 0),
          scratch_(model_.model()) {
        const softbody::Model& m = model_.model();
        const Index n = m.particles.count, bodies = m.bodies.count;
        check_shape(q, "q", {n, 3});
        check_shape(body_pnet, "body_pnet", {bodies});
        check_shape(body_dpdv, "body_dpdv", {bodies});
        check_shape(volume_gradient, "volume_gradient", {n, 3});
        q_.assign(q.data(), q.data() + 3 * n);
        pnet_.assign(body_pnet.data(), body_pnet.data() + bodies);
        dpdv_.assign(body_dpdv.data(), body_dpdv.data() + bodies);
        gradient_.assign(volume_gradient.data(), volume_gradient.data() + 3 * n);
        softbody::BoundScratch w;
        w.body_pnet = pnet_.data();
        w.body_dpdv = dpdv_.data();
        w.volume_gradient = gradient_.data();
        l_.q = q_.data();
        l_.volume_gradient = gradient_.data();
        l_.scratch = scratch_.table;
        nb::gil_scoped_release release;
        softbody::kernels().prepare_spectral(m, control_.view, buffers_.gas, w, l_);
    }

    void apply(int part, ConstF64 p, F64 out) const {
        const softbody::Model& m = model_.model();
        if (part < 0 || part >= softbody::kStiffnessParts)
            fail("part must be 0 (damped), 1 (undamped), 2 (whole) or 3 (damping)");
        check_shape(p, "p", {m.particles.count, 3});
        check_shape(out, "out", {m.particles.count, 3});
        nb::gil_scoped_release release;
        softbody::kernels().spectral_product(m, control_.view, l_,
                                             static_cast<softbody::StiffnessPart>(part),
                                             p.data(), out.data());
    }

private:
    nb::object handle_;  // keeps the CoreModel (and so the model's arrays) alive
    const CoreModel& model_;
    CoreControl control_;  // holds the control's arrays
    Buffers buffers_;
    TermScratch scratch_;
    std::vector<double> q_, pnet_, dpdv_, gradient_;
    softbody::Linearization l_;
};

/// Volumes of bodies given by plain arrays (before a Model exists, or by another method).
nb::ndarray<nb::numpy, double> body_volumes(ConstF64 q, ConstI64 tri_indices,
                                            ConstI64 body_particle_range, ConstI64 body_tri_range,
                                            ConstI64 body_volume_method, ConstI64 body_mc_range,
                                            ConstF64 mc_samples) {
    softbody::Model m;
    check_shape(q, "q", {-1, 3});
    check_shape(tri_indices, "tri_indices", {-1, 3});
    check_shape(body_particle_range, "body_particle_range", {-1, 2});
    m.particles.count = static_cast<Index>(q.shape(0));
    m.triangles.count = static_cast<Index>(tri_indices.shape(0));
    m.bodies.count = static_cast<Index>(body_particle_range.shape(0));
    check_shape(body_tri_range, "body_tri_range", {m.bodies.count, 2});
    check_shape(body_volume_method, "body_volume_method", {m.bodies.count});
    check_shape(body_mc_range, "body_mc_range", {m.bodies.count, 2});
    check_shape(mc_samples, "mc_samples", {-1, 2});
    m.volumes.mc_count = static_cast<Index>(mc_samples.shape(0));
    m.triangles.indices = tri_indices.data();
    m.bodies.particle_range = body_particle_range.data();
    m.bodies.tri_range = body_tri_range.data();
    m.volumes.method = body_volume_method.data();
    m.volumes.mc_range = body_mc_range.data();
    m.volumes.mc_samples = mc_samples.data();
    check_indices(m.triangles.indices, 3 * m.triangles.count, 0, m.particles.count, "tri_indices");
    check_ranges(m.bodies.particle_range, m.bodies.count, m.particles.count, "body_particle_range");
    check_ranges(m.bodies.tri_range, m.bodies.count, m.triangles.count, "body_tri_range");
    check_ranges(m.volumes.mc_range, m.bodies.count, m.volumes.mc_count, "body_mc_range");
    check_indices(m.volumes.method, m.bodies.count, 0, VolumeMethod::kCount, "body_volume_method");
    for (Index b = 0; b < m.bodies.count; ++b)
        if (m.bodies.tri_range[2 * b + 1] > m.bodies.tri_range[2 * b] &&
            m.bodies.particle_range[2 * b + 1] == m.bodies.particle_range[2 * b])
            fail("body " + std::to_string(b) + " has triangles but no particles");
    const size_t count = static_cast<size_t>(m.bodies.count);
    double* volume = new double[count > 0 ? count : 1];
    nb::capsule owner(volume, [](void* p) noexcept { delete[] static_cast<double*>(p); });
    std::vector<double> lo(3 * count), hi(3 * count);
    softbody::BodyGas gas;
    gas.volume = volume;
    gas.lo = lo.data();
    gas.hi = hi.data();
    {
        nb::gil_scoped_release release;
        softbody::kernels().eval_volumes(m, q.data(), gas);
    }
    size_t shape[1] = {count};
    return nb::ndarray<nb::numpy, double>(volume, 1, shape, owner);
}


/// A copy of data (count,) as a NumPy array.
nb::ndarray<nb::numpy, double> copy_array(const double* data, size_t count) {
    return to_numpy(std::vector<double>(data, data + count));
}

/// The molar flows at a state: (inflow (B,), inflow times its temperature (B,), outflow
/// (B,)) [mol/s, mol K/s, mol/s], by the flow terms' laws without the step limiter.
nb::tuple eval_flows(const CoreModel& core, nb::handle control, double t, ConstF64 q,
                     ConstF64 moles, ConstF64 temperature, ConstF64 vent_open) {
    const softbody::Model& m = core.model();
    check_shape(q, "q", {m.particles.count, 3});
    check_shape(moles, "moles", {m.bodies.count});
    check_shape(temperature, "temperature", {m.bodies.count});
    check_shape(vent_open, "vent_open", {m.vents.count});
    CoreControl c(m, control);
    Buffers b(m, 0);
    {
        nb::gil_scoped_release release;
        softbody::kernels().eval_flows(m, c.view, t, q.data(), moles.data(), temperature.data(),
                                       vent_open.data(), b.gas);
    }
    const size_t count = static_cast<size_t>(m.bodies.count);
    return nb::make_tuple(copy_array(b.gas.flow_in, count), copy_array(b.gas.flow_in_t, count),
                          copy_array(b.gas.flow_out, count));
}

/// Each registered term's energy at (q, t): per term with an energy its total and each
/// body's share.
nb::dict eval_energies(const CoreModel& core, nb::handle control, double t, ConstF64 q) {
    const softbody::Model& m = core.model();
    check_shape(q, "q", {m.particles.count, 3});
    CoreControl c(m, control);
    const softbody::KernelTable& k = softbody::kernels();
    const size_t nb_ = static_cast<size_t>(m.bodies.count);
    std::vector<double> per_body(static_cast<size_t>(k.term_count) * nb_, 0.0), volume(nb_),
        lo(3 * nb_), hi(3 * nb_);
    softbody::TermEnergies e;
    e.body = per_body.data();
    softbody::BodyGas gas;
    gas.volume = volume.data();
    gas.lo = lo.data();
    gas.hi = hi.data();
    {
        nb::gil_scoped_release release;
        k.eval_energies(m, c.view, t, q.data(), gas, e);
    }
    nb::dict out;
    for (int term = 0; term < k.term_count; ++term)
        if (k.terms[term].energy)
            out[k.terms[term].name] =
                nb::make_tuple(e.total[term], copy_array(e.body + term * nb_, nb_));
    out["volume"] = copy_array(volume.data(), nb_);
    return out;
}

/// The closed sets (enums.hpp): {Python IntEnum name: {member: value}}.
nb::dict enums() {
    nb::dict out;
#define SOFTBODY_ENUM_ITEM(name, value) members[#name] = static_cast<Index>(value);
#define SOFTBODY_ENUM_SET(cpp, python, list) \
    {                                        \
        nb::dict members;                    \
        list(SOFTBODY_ENUM_ITEM)             \
        out[python] = members;               \
    }
    SOFTBODY_ENUMS(SOFTBODY_ENUM_SET)
    SOFTBODY_ENUM_SET(Status, "Status", SOFTBODY_ENUM_STATUS)
#undef SOFTBODY_ENUM_SET
#undef SOFTBODY_ENUM_ITEM
    return out;
}

/// The names of the registered terms that act with this model and control.
nb::list active_terms(const CoreModel& core, nb::handle control) {
    const softbody::Model& m = core.model();
    CoreControl c(m, control);
    const softbody::KernelTable& k = softbody::kernels();
    const unsigned mask = k.active_terms(m, c.view);
    nb::list out;
    for (int t = 0; t < k.term_count; ++t)
        if (mask & (1u << t)) out.append(nb::str(k.terms[t].name));
    return out;
}

/// The registered terms in registry order (the order of their sums): each a dict of its
/// name and traits.
nb::list term_table() {
    const softbody::KernelTable& k = softbody::kernels();
    nb::list out;
    for (int t = 0; t < k.term_count; ++t) {
        const softbody::TermTraits& traits = k.terms[t];
        nb::dict d;
        d["name"] = traits.name;
        d["lane"] = traits.lane;
        d["projected"] = traits.projected;
        d["fused"] = traits.fused;
        d["energy"] = traits.energy;
        d["external"] = traits.external;
        d["flow"] = traits.flow;
        d["bound"] = traits.bound;
        d["shared_rows"] = traits.shared_rows;
        d["volume_mode"] = traits.volume_mode;
        d["stencil_width"] = traits.stencil_width;
        out.append(d);
    }
    return out;
}

/// The stability estimate's Gershgorin pieces at q, each term's, and the gas's state there.
nb::dict stiffness_bounds(const CoreModel& core, nb::handle control, ConstF64 q) {
    const softbody::Model& m = core.model();
    check_shape(q, "q", {m.particles.count, 3});
    CoreControl c(m, control);
    const size_t n = static_cast<size_t>(m.particles.count), nb_ = static_cast<size_t>(m.bodies.count);
    std::vector<double> root_sum(4 * n), rows(2 * n), pnet(nb_), dpdv(nb_), gradient(3 * n);
    softbody::BoundScratch w;
    w.root_sum = root_sum.data();
    w.rows = rows.data();
    w.body_pnet = pnet.data();
    w.body_dpdv = dpdv.data();
    w.volume_gradient = gradient.data();
    softbody::StiffnessBounds b;
    {
        nb::gil_scoped_release release;
        b = softbody::kernels().stiffness_bounds(m, c.view, q.data(), w);
    }
    auto parts = [](const double* v) { return nb::make_tuple(v[0], v[1], v[2], v[3]); };
    nb::dict out;
    // every term with a bound form (TermTraits::bound), by name; the traits that say how
    // they combine (shared rows; a volume mode, its eigenvalue apart)
    const softbody::KernelTable& k = softbody::kernels();
    nb::dict terms, modes;
    nb::list shared;
    for (int t = 0; t < k.term_count; ++t) {
        const softbody::TermTraits& traits = k.terms[t];
        if (!traits.bound) continue;
        terms[traits.name] = parts(b.terms[t].parts);
        if (traits.shared_rows) shared.append(nb::str(traits.name));
        if (traits.volume_mode) modes[traits.name] = b.terms[t].mode;
    }
    out["terms"] = terms;
    out["shared_rows"] = shared;
    out["volume_modes"] = modes;
    out["damping_ratio"] = nb::make_tuple(b.ratio_min, b.ratio_max);
    out["pure_dampers"] = b.pure_dampers;
    out["body_pnet"] = to_numpy(std::move(pnet));
    out["body_dpdv"] = to_numpy(std::move(dpdv));
    size_t shape[2] = {n, 3};
    auto* owned = new std::vector<double>(std::move(gradient));
    nb::capsule owner(owned, [](void* p) noexcept { delete static_cast<std::vector<double>*>(p); });
    out["volume_gradient"] = nb::ndarray<nb::numpy, double>(owned->data(), 2, shape, owner);
    return out;
}

}  // namespace

void bind_terms(nb::module_& mod) {
    mod.def("eval_energies", &eval_energies, nb::arg("model"), nb::arg("control"), nb::arg("t"),
            nb::arg("q").noconvert(),
            "Energies [J] of the registered terms that have one at q (N, 3), time t [s]: a "
            "dict of term name -> (total, per body (B,)), and 'volume' (B,) [m^3], each "
            "body's by its method (the gas's).");
    mod.def("enums", &enums,
            "The core's closed sets: {IntEnum name: {member name: value}} (core/enums.hpp).");
    mod.def("active_terms", &active_terms, nb::arg("model"), nb::arg("control"),
            "Names of the registered terms that act with this model and control.");
    mod.def("term_table", &term_table,
            "The registered physics terms in the order their forces are summed: a list of "
            "dicts of 'name' and the traits 'lane' (a vertex-major form), 'projected' "
            "(projective dynamics' local step), 'fused' (the fused symplectic pass), "
            "'energy' (has one), 'external' (its energy is work from outside the model), "
            "'flow' (it moves gas), 'bound' (its own part of the stability estimate), "
            "'shared_rows' (its Gershgorin rows are shared with the other such terms: "
            "their bound is the largest of theirs), 'volume_mode' (its bound holds a body's "
            "volume mode, reported apart), 'stencil_width' (numbers per entry of its blocks "
            "between particles in the multigrid smoother; 0: none).");
    mod.def("stiffness_bounds", &stiffness_bounds, nb::arg("model"), nb::arg("control"),
            nb::arg("q").noconvert(),
            "The stability estimate's Gershgorin pieces at q (N, 3): a dict of 'terms' "
            "(each term with a bound form, in registry order: name -> (damped, transverse, "
            "whole [1/s^2], damping [1/s])), 'shared_rows' (the names whose rows are shared: "
            "their sum is bounded by the largest of theirs), 'volume_modes' (each "
            "volume-mode term's name -> its volume mode's eigenvalue [1/s^2], included in its "
            "parts), 'damping_ratio' (min, max c / k [s]), "
            "'pure_dampers', and the gas at its largest scheduled value: 'body_pnet' (B,) "
            "[Pa], 'body_dpdv' (B,) [Pa/m^3], 'volume_gradient' (N, 3) [m^2].");
    mod.def("eval_forces", &eval_forces, nb::arg("model"), nb::arg("control"), nb::arg("t"),
            nb::arg("q").noconvert(), nb::arg("qd").noconvert(),
            "(f (N, 3) [N], volume (B,) [m^3], pressure (B,) [Pa], dV/dx (N, 3) [m^2]).");
    mod.def("apply_jacobians", &apply_jacobians, nb::arg("model"), nb::arg("control"),
            nb::arg("q").noconvert(), nb::arg("p").noconvert(), nb::arg("alpha_m"),
            nb::arg("alpha_c"), nb::arg("alpha_k"), nb::arg("out").noconvert(),
            nb::arg("t") = 0.0, nb::arg("linearization") = nb::dict(),
            nb::arg("volume_gradient").noconvert() = nb::none(),
            nb::arg("leave_out") = std::vector<std::string>(),
            "out (N, 3) = alpha_m M p + alpha_c C p + alpha_k K p (C = df/dv, K = df/dx) for "
            "p (N, 3), linearised at q (N, 3) and time t [s] as the implicit schemes do at a "
            "step's start: each registered term's own prepare form, except the terms named "
            "in linearization (name -> that term's linearisation, flat, in its layout: "
            "core/terms/*.hpp linearization_size) and dV/dx where volume_gradient (N, 3) "
            "[m^2] is given; the terms named in leave_out add nothing.");
    nb::class_<SpectralOperator>(mod, "SpectralOperator",
                                 "The stability estimate's split of the terms' Jacobians at "
                                 "one state, linearised once for its products.")
        .def(nb::init<nb::object, nb::object, ConstF64, ConstF64, ConstF64, ConstF64>(),
             nb::arg("model"), nb::arg("control"), nb::arg("q").noconvert(),
             nb::arg("body_pnet").noconvert(), nb::arg("body_dpdv").noconvert(),
             nb::arg("volume_gradient").noconvert(),
             "At positions q (N, 3) [m], with the estimate's state (stiffness_bounds'): "
             "body_pnet (B,) [Pa], body_dpdv (B,) [Pa/m^3], volume_gradient (N, 3) [m^2].")
        .def("apply", &SpectralOperator::apply, nb::arg("part"), nb::arg("p").noconvert(),
             nb::arg("out").noconvert(),
             "out (N, 3) = the part's K p [N] (part 0 damped, 1 undamped, 2 whole stiffness; "
             "3: C p, the damping) for p (N, 3), summed over the registered terms: each "
             "says which of its stiffness goes where (core/terms/term.hpp: "
             "spectral_product).");
    mod.def("soft_contacts", &soft_contacts, nb::arg("model"), nb::arg("q").noconvert(),
            nb::arg("qd").noconvert(), nb::arg("hash_capacity") = nb::none(),
            "One pass of the model's soft-soft contacts on q, qd (N, 3) in place; returns "
            "the hash entries the surface contacts needed when they did not fit, else 0.");
    mod.def("contact_list", &contact_list, nb::arg("model"), nb::arg("frames").noconvert(),
            "The thickness contacts' stage run over frames (F, N, 3), its pair list kept "
            "between steps: (counts (F - 1,): the list's rows after each step, -1 none; rows "
            "(sum of counts, 5): kind and four particles; q_build (F - 1, N, 3); skins "
            "(F - 1,) [m]).");
    mod.def("contact_pairs", &contact_pairs, nb::arg("model"), nb::arg("q").noconvert(),
            nb::arg("radius"), nb::arg("q_end").noconvert() = nb::none(),
            nb::arg("q_later").noconvert() = nb::none(), nb::arg("slack") = 0.0,
            "The thickness contacts' candidate pairs nearer than radius [m] at q (N, 3), "
            "gathered as the pair list's build gathers them: (kinds (P,): 0 vertex-triangle, "
            "1 edge-edge; particles (P, 4); distances (P,) [m]). With q_end (N, 3): the "
            "candidates of a step from q to q_end as the contact stage's swept gather finds "
            "them, its boxes grown by radius; with q_later (N, 3) too, that gather made with "
            "slack [m], then a later pass's pairs to q_later from its rows (the same "
            "translation). Raises ValueError where an edge passes through a triangle at q.");
    mod.def("body_volumes", &body_volumes, nb::arg("q").noconvert(),
            nb::arg("tri_indices").noconvert(), nb::arg("body_particle_range").noconvert(),
            nb::arg("body_tri_range").noconvert(), nb::arg("body_volume_method").noconvert(),
            nb::arg("body_mc_range").noconvert(), nb::arg("mc_samples").noconvert(),
            "Volume (B,) [m^3] of each body by its method, from plain arrays.");
    mod.def("eval_flows", &eval_flows, nb::arg("model"), nb::arg("control"), nb::arg("t"),
            nb::arg("q").noconvert(), nb::arg("moles").noconvert(),
            nb::arg("temperature").noconvert(), nb::arg("vent_open").noconvert(),
            "(inflow, inflow times its temperature, outflow) (B,) each [mol/s, mol K/s, "
            "mol/s]: every flow term's molar flows at a state, without the step limiter.");
    mod.def("eval_volumes", &eval_volumes, nb::arg("model"), nb::arg("control"), nb::arg("t"),
            nb::arg("q").noconvert(),
            "(volume (B,) [m^3], pressure (B,) [Pa], dV/dx (N, 3) [m^2]) at time t [s].");
}

}  // namespace softbody::bindings
