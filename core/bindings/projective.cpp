// softbody._core.ProjectiveSolver and the factor it solves with
// (core/solvers/projective.hpp), checked once.
#include "bindings/bindings.hpp"
#include "bindings/buffers.hpp"
#include "bindings/poll.hpp"
#include "threads.hpp"

namespace softbody::bindings {
namespace {

/// A Projective bundle's factor (softbody.solvers.factor.Projective), checked once
/// against a model of N particles: shapes, the supernodes' column, row and value ranges
/// nested and in bounds, each node's rows its own columns then rows below them, and perm a
/// permutation, so the triangular solves read and write only inside the arrays.
class CoreFactor {
public:
    CoreFactor(nb::handle d, Index n) : handle_(nb::borrow(d)) {
        softbody::Factor& a = factor_;
        const Index size = nb::cast<Index>(d.attr("size"));
        if (size != n)
            fail("the projective factor has size " + std::to_string(size) + " for a model of " +
                 std::to_string(n) + " particles");
        a.size = n;
        a.dt = nb::cast<double>(d.attr("dt"));
        if (!(std::isfinite(a.dt) && a.dt > 0.0)) fail("the projective factor's dt must be > 0");
        perm_ = attribute<ConstI64>(d, "perm", {n});
        inv_diag_ = attribute<ConstF64>(d, "inv_diag", {n});
        col_ = attribute<ConstI64>(d, "node_col", {-1});
        const Index count = static_cast<Index>(col_.shape(0)) - 1;
        if (count < 0) fail("node_col must hold at least one entry");
        row_ptr_ = attribute<ConstI64>(d, "node_row_ptr", {count + 1});
        rows_ = attribute<ConstI64>(d, "node_row", {-1});
        value_ptr_ = attribute<ConstI64>(d, "node_value_ptr", {count + 1});
        values_ = attribute<ConstF64>(d, "node_value", {-1});
        a.node_count = count;
        a.perm = perm_.data();
        a.inv_diag = inv_diag_.data();
        a.node_col = col_.data();
        a.node_row_ptr = row_ptr_.data();
        a.node_row = rows_.data();
        a.node_value_ptr = value_ptr_.data();
        a.node_value = values_.data();
        validate(static_cast<Index>(rows_.shape(0)), static_cast<Index>(values_.shape(0)));
    }

    const softbody::Factor& factor() const { return factor_; }
    nb::object handle() const { return handle_; }

private:
    void validate(Index row_count, Index value_count) {
        const softbody::Factor& a = factor_;
        const Index n = a.size;
        check_indices(a.perm, n, 0, n, "perm");
        std::vector<char> seen(static_cast<size_t>(n), 0);
        for (Index r = 0; r < n; ++r) {
            if (seen[static_cast<size_t>(a.perm[r])]) fail("perm is not a permutation");
            seen[static_cast<size_t>(a.perm[r])] = 1;
        }
        if (a.node_col[0] != 0 || a.node_col[a.node_count] != n)
            fail("node_col must run from 0 to " + std::to_string(n));
        if (a.node_row_ptr[0] != 0 || a.node_row_ptr[a.node_count] != row_count)
            fail("node_row_ptr must run from 0 to the length of node_row");
        if (a.node_value_ptr[0] != 0 || a.node_value_ptr[a.node_count] > value_count)
            fail("node_value_ptr must run from 0 to at most the length of node_value");
        for (Index s = 0; s < a.node_count; ++s) {
            const Index c0 = a.node_col[s], c1 = a.node_col[s + 1];
            const Index r0 = a.node_row_ptr[s], r1 = a.node_row_ptr[s + 1];
            const Index width = c1 - c0, height = r1 - r0;
            const std::string node = "supernode " + std::to_string(s);
            if (width < 1) fail("node_col must increase: " + node + " has no columns");
            if (height < width) fail(node + " has fewer rows than columns");
            // height <= len(node_row) and width <= N, arrays in memory: the product fits
            if (a.node_value_ptr[s] < 0 || a.node_value_ptr[s + 1] - a.node_value_ptr[s] != height * width)
                fail(node + "'s values are not a (rows, columns) block");
            for (Index p = 0; p < height; ++p) {
                const Index r = a.node_row[r0 + p];
                const bool ok = p < width ? r == c0 + p : r >= c1 && r < n;
                if (!ok) fail(node + "'s rows must be its columns, then rows below them in [" +
                              std::to_string(c1) + ", " + std::to_string(n) + ")");
            }
        }
    }

    nb::object handle_;  // keeps the Projective bundle (and so its arrays) alive
    softbody::Factor factor_;
    ConstI64 perm_, col_, row_ptr_, rows_, value_ptr_;
    ConstF64 inv_diag_, values_;
};

/// softbody._core.ProjectiveSolver: projective dynamics' time loop, its scratch, and the
/// factor it solves with (set for each step size by the caller, which builds it).
class ProjectiveSolver {
public:
    ProjectiveSolver(nb::object model, std::optional<Index> hash_capacity, int threads)
        : handle_(model),
          model_(nb::cast<const CoreModel&>(model)),
          buffers_(model_.model(), 6, checked_capacity(model_.model(), hash_capacity)),
          threads_(threads, model_.model().bodies.count) {
        threads_.attach(buffers_.lanes_view);
        buffers_.allow_growth();  // the surface contacts grow their hash inside a run
        w_.lanes = buffers_.lanes_view;
        w_.f = buffers_.row(0);
        w_.q0 = buffers_.row(1);
        w_.v0 = buffers_.row(2);
        w_.y = buffers_.row(3);
        w_.rhs = buffers_.row(4);
        w_.x = buffers_.row(5);
        w_.gas = buffers_.gas;
        w_.contact = buffers_.contact;
    }

    /// Checked first: a refused factor leaves the one set before.
    void set_factor(nb::handle factor) {
        CoreFactor checked(factor, model_.model().particles.count);
        factor_.reset();
        factor_.emplace(std::move(checked));
    }

    nb::object factor() const { return factor_ ? factor_->handle() : nb::none(); }

    std::tuple<int, Index, Index, double> simulate(Index steps, double dt, Index iterations,
                                                   nb::handle control, nb::handle state,
                                                   nb::handle limits, nb::handle progress) {
        const softbody::Model& m = model_.model();
        if (iterations < 1) fail("iterations must be >= 1");
        if (!factor_) fail("no projective factor set (set_factor)");
        if (factor_->factor().dt != dt)
            fail("the projective factor was built for dt = " + std::to_string(factor_->factor().dt) +
                 " s, not " + std::to_string(dt) + " s");
        CheckedRun run = checked_run(m, steps, dt, state, limits);
        run.params.iterations = iterations;
        CoreControl c(m, control);
        attach_gas(w_.gas, run);
        RunPoll poll(run.params, progress);
        softbody::RunResult r;
        {
            nb::gil_scoped_release release;
            r = softbody::kernels().simulate_projective(m, c.view, run.params, run.state,
                                                        factor_->factor(), w_);
        }
        poll.finish(state, run.params, r);
        return {r.status, r.steps_done, r.where, r.value};
    }

    Index hash_capacity() const { return buffers_.hash_capacity(); }
    int threads() const { return threads_.count(); }

private:
    nb::object handle_;  // keeps the CoreModel (and so the model's arrays) alive
    const CoreModel& model_;
    Buffers buffers_;
    SolverThreads threads_;
    softbody::ProjectiveBuffers w_;
    std::optional<CoreFactor> factor_;
};

/// x (N, 3) = A^-1 b by a projective factor's two triangular solves: for tests of the
/// factor.
nb::ndarray<nb::numpy, double> solve_factor(const CoreModel& core, nb::handle factor,
                                            ConstF64 b) {
    const softbody::Model& m = core.model();
    check_shape(b, "b", {m.particles.count, 3});
    CoreFactor checked(factor, m.particles.count);
    const size_t n3 = static_cast<size_t>(3 * m.particles.count);
    std::vector<double> scratch(n3 > 0 ? n3 : 1);
    double* x = new double[n3 > 0 ? n3 : 1];
    nb::capsule owner(x, [](void* p) noexcept { delete[] static_cast<double*>(p); });
    {
        nb::gil_scoped_release release;
        softbody::kernels().projective_solve(checked.factor(), b.data(), scratch.data(), x);
    }
    size_t shape[2] = {static_cast<size_t>(m.particles.count), 3};
    return nb::ndarray<nb::numpy, double>(x, 2, shape, owner);
}

}  // namespace

void bind_projective(nb::module_& mod) {
    nb::class_<ProjectiveSolver>(mod, "ProjectiveSolver",
                                 "Projective dynamics' time loop with its scratch buffers and "
                                 "the factored matrix it solves with.")
        .def(nb::init<nb::object, std::optional<Index>, int>(), nb::arg("model"),
             nb::arg("hash_capacity") = nb::none(), nb::arg("threads") = 1,
             "hash_capacity, threads: as for ExplicitSolver (threads run the pass that "
             "measures the volumes and dV/dx).")
        .def_prop_ro("threads", &ProjectiveSolver::threads, "Threads of the force pass.")
        .def("set_factor", &ProjectiveSolver::set_factor, nb::arg("factor"),
             "Solve with this Projective factor (softbody.solvers.factor.build_projective for "
             "the model and the step); checked once here and kept alive.")
        .def_prop_ro("factor", &ProjectiveSolver::factor, "The factor set, or None.")
        .def_prop_ro("hash_capacity", &ProjectiveSolver::hash_capacity,
                     "Entries the surface contacts' spatial hash holds (0 without them).")
        .def("simulate", &ProjectiveSolver::simulate, nb::arg("steps"), nb::arg("dt"),
             nb::arg("iterations"), nb::arg("control"), nb::arg("state"), nb::arg("limits"),
             nb::arg("progress") = nb::none(),
             "Advance a softbody.State in place from its time by steps steps of dt (the "
             "factor's), iterations local-global iterations each (limits: a RunLimits); "
             "returns (status, steps_done, index, value). " RUN_POLL_DOC);
    mod.def("solve_factor", &solve_factor, nb::arg("model"), nb::arg("factor"),
            nb::arg("b").noconvert(),
            "x (N, 3) = A^-1 b by a projective factor's two triangular solves.");
}

}  // namespace softbody::bindings
