// softbody._core.SubstepSolver: XPBD with small steps (core/solvers/substep.hpp), with the
// springs' colouring it sweeps in, checked once.
#include "bindings/bindings.hpp"
#include "bindings/buffers.hpp"
#include "bindings/poll.hpp"
#include "threads.hpp"

#include <cstdint>

namespace softbody::bindings {
namespace {

/// softbody._core.SubstepSolver: XPBD's time loop, its scratch and the springs' colouring.
class SubstepSolver {
public:
    SubstepSolver(nb::object model, ConstI64 spring_order, ConstI64 colour_ptr,
                  std::optional<Index> hash_capacity, int threads)
        : handle_(model),
          model_(nb::cast<const CoreModel&>(model)),
          buffers_(model_.model(), 4, checked_capacity(model_.model(), hash_capacity)),
          threads_(threads, model_.model().bodies.count) {
        const softbody::Model& m = model_.model();
        set_colouring(m, spring_order, colour_ptr);
        threads_.attach(buffers_.lanes_view);
        buffers_.allow_growth();  // the surface contacts grow their hash inside a run
        spring_lambda_.assign(static_cast<size_t>(std::max<Index>(m.springs.count, 1)), 0.0);
        spring_coef_.assign(static_cast<size_t>(6 * std::max<Index>(m.springs.count, 1)), 0.0);
        attachment_lambda_.assign(static_cast<size_t>(std::max<Index>(m.attachments.count, 1)),
                                  0.0);
        w_.lanes = buffers_.lanes_view;
        w_.f = buffers_.row(0);
        w_.q0 = buffers_.row(1);
        w_.v0 = buffers_.row(2);
        w_.q_prev = buffers_.row(3);
        w_.rows = aligned_rows(m.particles.count);
        w_.spring_lambda = spring_lambda_.data();
        w_.attachment_lambda = attachment_lambda_.data();
        w_.spring_coef = spring_coef_.data();
        w_.spring_ends = ends_.data();
        w_.spring_order = order_.data();
        w_.colour_ptr = colour_ptr_.data();
        w_.colours = static_cast<Index>(colour_ptr_.size()) - 1;
        w_.gas = buffers_.gas;
        w_.contact = buffers_.contact;
    }

    std::tuple<int, Index, Index, double> simulate(Index steps, double dt, Index substeps,
                                                   Index iterations, double relaxation,
                                                   nb::handle control,
                                                   nb::handle state, nb::handle limits,
                                                   nb::handle progress) {
        const softbody::Model& m = model_.model();
        if (substeps < 1) fail("substeps must be >= 1");
        if (iterations < 1) fail("iterations must be >= 1");
        if (!(relaxation > 0.0 && relaxation < 2.0)) fail("relaxation must lie in (0, 2)");
        CheckedRun run = checked_run(m, steps, dt, state, limits);
        run.params.scheme = Integrator::XPBD;
        run.params.substeps = substeps;
        run.params.iterations = iterations;
        run.params.relaxation = relaxation;
        CoreControl c(m, control);
        attach_gas(w_.gas, run);
        RunPoll poll(run.params, progress);
        softbody::RunResult r;
        {
            nb::gil_scoped_release release;
            r = softbody::kernels().simulate_substep(m, c.view, run.params, run.state, w_);
        }
        poll.finish(state, run.params, r);
        return {r.status, r.steps_done, r.where, r.value};
    }

    Index colours() const { return w_.colours; }
    Index hash_capacity() const { return buffers_.hash_capacity(); }
    int threads() const { return threads_.count(); }

private:
    /// The colouring checked: spring_order a permutation of the S springs, colour_ptr
    /// rising from 0 to S, and no particle twice in one colour (so that a colour's
    /// constraints may run in any order or at once).
    void set_colouring(const softbody::Model& m, ConstI64 spring_order, ConstI64 colour_ptr) {
        const Index s = m.springs.count;
        check_shape(spring_order, "spring_order", {s});
        check_shape(colour_ptr, "colour_ptr", {-1});
        const Index colours = static_cast<Index>(colour_ptr.shape(0)) - 1;
        if (colours < 0) fail("colour_ptr must hold at least one entry");
        const Index* order = spring_order.data();
        const Index* ptr = colour_ptr.data();
        check_indices(order, s, 0, std::max<Index>(s, 1), "spring_order");
        if (ptr[0] != 0 || ptr[colours] != s)
            fail("colour_ptr must run from 0 to the springs' count " + std::to_string(s));
        std::vector<char> seen(static_cast<size_t>(s), 0);
        for (Index r = 0; r < s; ++r) {
            if (seen[static_cast<size_t>(order[r])]) fail("spring_order is not a permutation");
            seen[static_cast<size_t>(order[r])] = 1;
        }
        std::vector<Index> stamp(static_cast<size_t>(m.particles.count), -1);
        for (Index c = 0; c < colours; ++c) {
            if (ptr[c + 1] < ptr[c]) fail("colour_ptr must not decrease");
            for (Index r = ptr[c]; r < ptr[c + 1]; ++r) {
                const Index sp = order[r];
                for (int end = 0; end < 2; ++end) {
                    const Index i = m.springs.indices[2 * sp + end];
                    if (stamp[static_cast<size_t>(i)] == c)
                        fail("colour " + std::to_string(c) + " holds two springs at particle " +
                             std::to_string(i));
                    stamp[static_cast<size_t>(i)] = c;
                }
            }
        }
        order_.assign(order, order + s);
        colour_ptr_.assign(ptr, ptr + colours + 1);
        ends_.assign(static_cast<size_t>(std::max<Index>(2 * s, 1)), 0);
        for (Index r = 0; r < s; ++r) {
            ends_[static_cast<size_t>(r)] = m.springs.indices[2 * order[r]];
            ends_[static_cast<size_t>(s + r)] = m.springs.indices[2 * order[r] + 1];
        }
    }

    /// The constraint pass's rows (N, kRow), zeroed, each on a 64-byte line of its own.
    double* aligned_rows(Index n) {
        constexpr size_t line = 64 / sizeof(double);
        rows_.assign(static_cast<size_t>(8 * std::max<Index>(n, 1)) + line, 0.0);
        const size_t misaligned = (reinterpret_cast<std::uintptr_t>(rows_.data()) % 64) / 8;
        return rows_.data() + (misaligned == 0 ? 0 : line - misaligned);
    }

    nb::object handle_;  // keeps the CoreModel (and so the model's arrays) alive
    const CoreModel& model_;
    Buffers buffers_;
    SolverThreads threads_;
    softbody::SubstepBuffers w_;
    std::vector<Index> order_, colour_ptr_, ends_;
    std::vector<double> spring_lambda_, attachment_lambda_, spring_coef_, rows_;
};

}  // namespace

void bind_substep(nb::module_& mod) {
    nb::class_<SubstepSolver>(mod, "SubstepSolver",
                              "XPBD with small steps: its time loop, scratch buffers and the "
                              "springs' colouring.")
        .def(nb::init<nb::object, ConstI64, ConstI64, std::optional<Index>, int>(),
             nb::arg("model"), nb::arg("spring_order").noconvert(),
             nb::arg("colour_ptr").noconvert(), nb::arg("hash_capacity") = nb::none(),
             nb::arg("threads") = 1,
             "spring_order (S,) int64: the springs colour by colour; colour_ptr (colours + 1,) "
             "int64: colour c is spring_order[colour_ptr[c]:colour_ptr[c + 1]], no two of its "
             "springs sharing a particle (checked). hash_capacity, threads: as for "
             "ExplicitSolver (threads run the explicit forces' pass).")
        .def_prop_ro("threads", &SubstepSolver::threads, "Threads of the force pass.")
        .def_prop_ro("colours", &SubstepSolver::colours, "Colours of the springs' colouring.")
        .def_prop_ro("hash_capacity", &SubstepSolver::hash_capacity,
                     "Entries the surface contacts' spatial hash holds (0 without them).")
        .def("simulate", &SubstepSolver::simulate, nb::arg("steps"), nb::arg("dt"),
             nb::arg("substeps"), nb::arg("iterations"), nb::arg("relaxation"), nb::arg("control"),
             nb::arg("state"),
             nb::arg("limits"), nb::arg("progress") = nb::none(),
             "Advance a softbody.State in place from its time by steps steps of dt, each of "
             "substeps substeps with iterations constraint passes, those after the first "
             "over-relaxed by relaxation in (0, 2) (limits: a RunLimits); "
             "returns (status, steps_done, index, value). " RUN_POLL_DOC);
}

}  // namespace softbody::bindings
