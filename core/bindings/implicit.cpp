// softbody._core.ImplicitSolver (backward Euler, BDF2) and the multigrid hierarchy it
// preconditions with (core/solvers/implicit.hpp, multigrid.hpp), checked once.
#include "bindings/bindings.hpp"
#include "bindings/buffers.hpp"
#include "bindings/poll.hpp"
#include "threads.hpp"

namespace softbody::bindings {
namespace {

/// Checked views of a multigrid hierarchy (softbody.solvers.multigrid.Multigrid) for a
/// model, and the V-cycle's scratch: every offset, CSR row range and column checked once,
/// so that no kernel reads or writes outside an array.
class CheckedMultigrid {
public:
    CheckedMultigrid(const softbody::Model& m, nb::handle mg) {
        softbody::MultigridView& v = view;
        const Index n = m.particles.count;
        v.level_count = nb::cast<Index>(mg.attr("level_count"));
        const Index levels = v.level_count;
        if (levels < 0) fail("multigrid level_count must be >= 0");
        v.coarse_dense = nb::cast<Index>(mg.attr("coarse_dense")) != 0;
        v.level_size = i64(mg, "level_size", {levels + 1});
        v.vec_offset = i64(mg, "vec_offset", {levels + 2});
        if (v.level_size[0] != n)
            fail("multigrid level_size[0] must be the particle count " + std::to_string(n) +
                 ", got " + std::to_string(v.level_size[0]));
        if (v.vec_offset[0] != 0) fail("multigrid vec_offset[0] must be 0");
        for (Index l = 0; l <= levels; ++l) {
            if (v.level_size[l] < 0) fail("multigrid level_size must be >= 0");
            if (v.vec_offset[l + 1] != v.vec_offset[l] + v.level_size[l])
                fail("multigrid vec_offset must be the running sum of level_size");
        }
        total_ = v.vec_offset[levels + 1];
        v.a_row_offset = i64(mg, "a_row_offset", {levels + 1});
        v.a_nz_offset = i64(mg, "a_nz_offset", {levels + 1});
        const ConstI64 a_indptr = keep(attribute<ConstI64>(mg, "a_indptr", {-1}));
        const ConstI64 a_indices = keep(attribute<ConstI64>(mg, "a_indices", {-1}));
        v.a_indptr = a_indptr.data();
        v.a_indices = a_indices.data();
        const Index a_nnz = static_cast<Index>(a_indices.shape(0));
        v.a_data = f64(mg, "a_data", {a_nnz});
        v.a_diag = f64(mg, "a_diag", {total_});
        for (Index l = 0; l <= levels; ++l)
            check_csr(v.a_indptr, static_cast<Index>(a_indptr.shape(0)), v.a_row_offset[l],
                      v.a_nz_offset[l], v.a_indices, a_nnz, v.level_size[l], v.level_size[l],
                      "multigrid A level " + std::to_string(l));
        const Index p_levels = std::max<Index>(levels, 1);
        v.p_row_offset = i64(mg, "p_row_offset", {p_levels});
        v.p_nz_offset = i64(mg, "p_nz_offset", {p_levels});
        const ConstI64 p_indptr = keep(attribute<ConstI64>(mg, "p_indptr", {-1}));
        const ConstI64 p_indices = keep(attribute<ConstI64>(mg, "p_indices", {-1}));
        v.p_indptr = p_indptr.data();
        v.p_indices = p_indices.data();
        const Index p_nnz = static_cast<Index>(p_indices.shape(0));
        v.p_data = f64(mg, "p_data", {p_nnz});
        for (Index l = 0; l < levels; ++l)
            check_csr(v.p_indptr, static_cast<Index>(p_indptr.shape(0)), v.p_row_offset[l],
                      v.p_nz_offset[l], v.p_indices, p_nnz, v.level_size[l], v.level_size[l + 1],
                      "multigrid P level " + std::to_string(l));
        const Index coarse = v.level_size[levels];
        v.coarse_cholesky = v.coarse_dense ? f64(mg, "coarse_cholesky", {coarse, coarse}) : nullptr;
        const size_t n9 = static_cast<size_t>(9 * n), t3 = static_cast<size_t>(3 * total_);
        scratch_ = {std::vector<double>(n9), std::vector<double>(n9), std::vector<double>(t3),
                    std::vector<double>(t3), std::vector<double>(t3)};
        v.block = scratch_[0].data();
        v.block_inv = scratch_[1].data();
        v.x = scratch_[2].data();
        v.b = scratch_[3].data();
        v.r = scratch_[4].data();
        // every kStencil term's smoother entries (mg.stencils[name]: ptr, neighbor, map):
        // CSR over particles, neighbours in range, the map checked by the term
        const softbody::KernelTable& k = softbody::kernels();
        nb::dict stencils;
        if (!nb::try_cast(mg.attr("stencils"), stencils))
            fail("multigrid stencils must be a dict of term name -> stencil");
        coef_.resize(static_cast<size_t>(k.term_count));
        for (int t = 0; t < k.term_count; ++t) {
            const int width = k.terms[t].stencil_width;
            if (width == 0) continue;
            const std::string name = k.terms[t].name;
            const std::string what = "multigrid stencil " + name;
            if (!stencils.contains(name.c_str())) fail(what + " is missing");
            nb::handle st = stencils[name.c_str()];
            softbody::Stencil& s = v.stencils[t];
            s.ptr = i64(st, "ptr", {n + 1});
            const ConstI64 neighbor = keep(attribute<ConstI64>(st, "neighbor", {-1}));
            const ConstI64 map = keep(attribute<ConstI64>(st, "map", {-1}));
            s.count = static_cast<Index>(neighbor.shape(0));
            if (s.ptr[0] != 0 || s.ptr[n] != s.count)
                fail(what + " ptr must run from 0 to its entry count");
            for (Index i = 0; i < n; ++i)
                if (s.ptr[i] > s.ptr[i + 1]) fail(what + " ptr must not decrease");
            s.neighbor = neighbor.data();
            check_indices(s.neighbor, s.count, 0, n, what + " neighbor");
            s.map = map.data();
            if (const char* error = k.check_stencil(t, m, s, static_cast<Index>(map.shape(0))))
                fail(what + ": " + error);
            coef_[static_cast<size_t>(t)].assign(static_cast<size_t>(width * s.count), 0.0);
            s.coef = coef_[static_cast<size_t>(t)].data();
        }
    }

    softbody::MultigridView view;

private:
    // Rows [r0, r0 + rows] of indptr within it, non-decreasing, their entries (offset z0)
    // within the column array, and every column in [0, cols).
    static void check_csr(const Index* indptr, Index indptr_size, Index r0, Index z0,
                          const Index* cols, Index nnz, Index rows, Index col_count,
                          const std::string& name) {
        if (r0 < 0 || r0 + rows + 1 > indptr_size || z0 < 0)
            fail(name + ": row or entry offset outside its arrays");
        for (Index i = 0; i < rows; ++i)
            if (indptr[r0 + i] > indptr[r0 + i + 1]) fail(name + ": indptr decreases");
        const Index first = indptr[r0], last = indptr[r0 + rows];
        if (first < 0 || z0 + last > nnz) fail(name + ": entries outside its arrays");
        check_indices(cols + z0 + first, last - first, 0, col_count, name + " columns");
    }
    template <typename Array>
    Array keep(Array a) {
        if constexpr (std::is_same_v<Array, ConstI64>)
            keep_i_.push_back(a);
        else
            keep_f_.push_back(a);
        return a;
    }
    const Index* i64(nb::handle mg, const char* name, std::vector<Index> shape) {
        return keep(attribute<ConstI64>(mg, name, shape)).data();
    }
    const double* f64(nb::handle mg, const char* name, std::vector<Index> shape) {
        return keep(attribute<ConstF64>(mg, name, shape)).data();
    }

    Index total_ = 0;
    std::vector<std::vector<double>> scratch_;
    std::vector<std::vector<double>> coef_;  // each stencil's coefficients, by term
    std::vector<ConstF64> keep_f_;
    std::vector<ConstI64> keep_i_;
};

/// softbody._core.ImplicitSolver: backward Euler and BDF2, their time loop, scratch and
/// history (BDF2's previous step, CG's last dv and its statistics).
class ImplicitSolver {
public:
    ImplicitSolver(nb::object model, nb::object multigrid, std::optional<Index> hash_capacity,
                   int threads)
        : handle_(model),
          model_(nb::cast<const CoreModel&>(model)),
          buffers_(model_.model(), 13, checked_capacity(model_.model(), hash_capacity)),
          threads_(threads, model_.model().bodies.count) {
        const softbody::Model& m = model_.model();
        threads_.attach(buffers_.lanes_view);
        buffers_.allow_growth();  // the surface contacts grow their hash inside a run
        if (!multigrid.is_none()) multigrid_.emplace(m, multigrid);
        mg_handle_ = multigrid;
        double** rows[] = {&w_.f, &w_.q0, &w_.v0, &w_.qs, &w_.vs, &w_.ky, &w_.cg_r,
                           &w_.cg_z, &w_.cg_p, &w_.cg_ap, &w_.cg_x, &w_.q_prev, &w_.v_prev};
        for (int k = 0; k < 13; ++k) *rows[k] = buffers_.row(k);
        // each registered term's linearisation at the step's start, as large as it asks
        const softbody::KernelTable& k = softbody::kernels();
        linearization_.resize(static_cast<size_t>(k.term_count));
        for (int t = 0; t < k.term_count; ++t) {
            std::vector<double>& own = linearization_[static_cast<size_t>(t)];
            own.assign(static_cast<size_t>(k.linearization_size(t, m)), 0.0);
            w_.linearization[t] = own.empty() ? nullptr : own.data();
        }
        diag_.assign(static_cast<size_t>(m.particles.count), 0.0);
        w_.cg_diag = diag_.data();
        w_.contacts_acted = &flags_[0];
        w_.cg_stats = &flags_[1];
        w_.gas = buffers_.gas;
        w_.lanes = buffers_.lanes_view;
        w_.contact = buffers_.contact;
    }

    std::tuple<int, Index, Index, double> simulate(
        bool bdf2, Index steps, double dt, nb::handle control, nb::handle state,
        nb::handle limits, double tolerance, Index max_iterations, bool history,
        nb::handle progress, nb::handle previous_q, nb::handle previous_qd,
        bool contacts_acted) {
        const softbody::Model& m = model_.model();
        if (!(std::isfinite(tolerance) && tolerance > 0.0 && tolerance < 1.0))
            fail("tolerance must lie in (0, 1)");
        if (max_iterations < 1) fail("max_iterations must be >= 1");
        CheckedRun run = checked_run(m, steps, dt, state, limits);
        CoreControl c(m, control);
        attach_gas(w_.gas, run);
        softbody::ImplicitParams ip;
        ip.bdf2 = bdf2;
        ip.tolerance = tolerance;
        ip.max_iterations = max_iterations;
        ip.history = history;
        // BDF2's history: the step before the state's, in the caller's arrays (the State's
        // own, softbody.sim.state.StepHistory), written there as the run steps; without
        // them, this solver's scratch
        const Index n = m.particles.count;
        F64 prev_q, prev_qd;
        if (previous_q.is_none() != previous_qd.is_none())
            fail("previous_q and previous_qd must be given together");
        if (!previous_q.is_none()) {
            prev_q = writable(previous_q, "previous_q", {n, 3});
            prev_qd = writable(previous_qd, "previous_qd", {n, 3});
            w_.q_prev = prev_q.data();
            w_.v_prev = prev_qd.data();
        } else {
            if (history) fail("a run with history needs previous_q and previous_qd");
            w_.q_prev = buffers_.row(11);
            w_.v_prev = buffers_.row(12);
        }
        flags_[0] = history && contacts_acted ? 1 : 0;
        const softbody::MultigridView* mg = multigrid_ ? &multigrid_->view : nullptr;
        RunPoll poll(run.params, progress);
        softbody::RunResult r;
        {
            nb::gil_scoped_release release;
            r = softbody::kernels().simulate_implicit(m, c.view, run.params, ip, run.state, w_,
                                                      mg);
        }
        poll.finish(state, run.params, r);
        return {r.status, r.steps_done, r.where, r.value};
    }

    /// z (N, 3) = P^-1 r: the preconditioner for step h [s] with its blocks at q (N, 3) at
    /// time t [s] (the multigrid hierarchy's values must be set for h); with contacts, the
    /// thickness contacts' pairs near at q in it too (gathered in buffers of its own, so
    /// the solver's pair list is left as it was). For tests.
    nb::ndarray<nb::numpy, double> apply_preconditioner(nb::handle control, double t, double h,
                                                        ConstF64 q, ConstF64 r, bool contacts) {
        const softbody::Model& m = model_.model();
        check_shape(q, "q", {m.particles.count, 3});
        check_shape(r, "r", {m.particles.count, 3});
        if (!(std::isfinite(h) && h > 0.0)) fail("h must be finite and > 0");
        CoreControl c(m, control);
        const size_t n3 = static_cast<size_t>(3 * m.particles.count);
        std::copy(q.data(), q.data() + n3, w_.q0);
        std::optional<Buffers> own;
        if (contacts) {
            if (m.soft_contacts.mode != softbody::SoftContactMode::SURFACE ||
                !(m.soft_contacts.thickness > 0.0))
                fail("contacts needs surface soft contacts with a thickness");
            own.emplace(m, 0, checked_capacity(m, std::nullopt));
            own->allow_growth();
        }
        double* z = new double[n3 > 0 ? n3 : 1];
        nb::capsule owner(z, [](void* p) noexcept { delete[] static_cast<double*>(p); });
        {
            nb::gil_scoped_release release;
            softbody::kernels().apply_preconditioner(m, c.view, t, h, w_,
                                                     multigrid_ ? &multigrid_->view : nullptr,
                                                     r.data(), z, own ? &own->contact : nullptr);
        }
        size_t shape[2] = {static_cast<size_t>(m.particles.count), 3};
        return nb::ndarray<nb::numpy, double>(z, 2, shape, owner);
    }

    /// Whether the last run's last step's contacts acted (BDF2 then takes its next step as
    /// backward Euler): part of the history a caller keeps.
    bool contacts_acted() const { return flags_[0] != 0; }
    /// (steps, CG iterations in all, most in one step) since the last clear_stats.
    std::tuple<Index, Index, Index> cg_stats() const { return {flags_[1], flags_[2], flags_[3]}; }
    void clear_stats() { flags_[1] = flags_[2] = flags_[3] = 0; }
    Index hash_capacity() const { return buffers_.hash_capacity(); }
    bool uses_multigrid() const { return multigrid_.has_value(); }
    int threads() const { return threads_.count(); }

private:
    nb::object handle_;  // keeps the CoreModel (and so the model's arrays) alive
    const CoreModel& model_;
    nb::object mg_handle_;  // keeps the hierarchy's arrays alive
    std::optional<CheckedMultigrid> multigrid_;
    Buffers buffers_;
    SolverThreads threads_;
    std::vector<std::vector<double>> linearization_;  // each term's, by registry position
    std::vector<double> diag_;
    Index flags_[4] = {0, 0, 0, 0};  // contacts acted, then the CG statistics
    softbody::ImplicitBuffers w_;
};

/// One V-cycle z = V(r) of a hierarchy for r (N, 3): for tests of the preconditioner.
nb::ndarray<nb::numpy, double> apply_multigrid(const CoreModel& core, nb::handle mg, ConstF64 r) {
    const softbody::Model& m = core.model();
    check_shape(r, "r", {m.particles.count, 3});
    CheckedMultigrid checked(m, mg);
    const size_t n3 = static_cast<size_t>(3 * m.particles.count);
    double* z = new double[n3 > 0 ? n3 : 1];
    nb::capsule owner(z, [](void* p) noexcept { delete[] static_cast<double*>(p); });
    {
        nb::gil_scoped_release release;
        softbody::kernels().apply_multigrid(checked.view, r.data(), z);
    }
    size_t shape[2] = {static_cast<size_t>(m.particles.count), 3};
    return nb::ndarray<nb::numpy, double>(z, 2, shape, owner);
}

}  // namespace

void bind_implicit(nb::module_& mod) {
    nb::class_<ImplicitSolver>(mod, "ImplicitSolver",
                               "Backward Euler and BDF2 with their scratch, BDF2's previous "
                               "step and CG's statistics.")
        .def(nb::init<nb::object, nb::object, std::optional<Index>, int>(), nb::arg("model"),
             nb::arg("multigrid").none() = nb::none(), nb::arg("hash_capacity") = nb::none(),
             nb::arg("threads") = 1,
             "multigrid: a softbody.solvers.multigrid.Multigrid for this model (checked "
             "once; its values are read at each step, so set_multigrid_step on it takes "
             "effect), or None for the Jacobi preconditioner. threads: as for ExplicitSolver "
             "(threads run the force pass at each step's start).")
        .def_prop_ro("threads", &ImplicitSolver::threads, "Threads of the force pass.")
        .def_prop_ro("hash_capacity", &ImplicitSolver::hash_capacity)
        .def_prop_ro("uses_multigrid", &ImplicitSolver::uses_multigrid)
        .def_prop_ro("cg_stats", &ImplicitSolver::cg_stats,
                     "(implicit steps, CG iterations in all, most in one step) since the last "
                     "clear_stats().")
        .def("clear_stats", &ImplicitSolver::clear_stats)
        .def_prop_ro("contacts_acted", &ImplicitSolver::contacts_acted,
                     "Whether the last run's last step's contacts acted (BDF2's history).")
        .def("apply_preconditioner", &ImplicitSolver::apply_preconditioner,
             nb::arg("control"), nb::arg("t"), nb::arg("h"), nb::arg("q").noconvert(),
             nb::arg("r").noconvert(), nb::arg("contacts") = false,
             "z (N, 3) = P^-1 r, the solve's preconditioner for step h with its blocks at q "
             "(N, 3); its hierarchy's values must be set for h. contacts: the thickness "
             "contacts' pairs near at q in it too.")
        .def("simulate", &ImplicitSolver::simulate, nb::arg("bdf2"), nb::arg("steps"),
             nb::arg("dt"), nb::arg("control"), nb::arg("state"), nb::arg("limits"),
             nb::arg("tolerance"), nb::arg("max_iterations"), nb::arg("history"),
             nb::arg("progress") = nb::none(), nb::arg("previous_q") = nb::none(),
             nb::arg("previous_qd") = nb::none(), nb::arg("contacts_acted") = false,
             "Advance a softbody.State in place by backward Euler (or BDF2) from its time "
             "(limits: a RunLimits). previous_q, previous_qd (N, 3): BDF2's history, the "
             "start of the step before the state's, read when history is true (with "
             "contacts_acted: that step's contacts acted) and written as the run steps (the "
             "start of its last step). Returns (status, steps_done, index, value). "
             RUN_POLL_DOC);
    mod.def("apply_multigrid", &apply_multigrid, nb::arg("model"), nb::arg("multigrid"),
            nb::arg("r").noconvert(), "z (N, 3) = one V-cycle of the hierarchy for r (N, 3).");
}

}  // namespace softbody::bindings
