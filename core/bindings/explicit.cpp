// softbody._core.ExplicitSolver: the explicit schemes (core/solvers/explicit.hpp).
#include "bindings/bindings.hpp"
#include "bindings/buffers.hpp"
#include "bindings/poll.hpp"
#include "threads.hpp"

namespace softbody::bindings {
namespace {

/// softbody._core.ExplicitSolver: the explicit schemes' time loop and its scratch.
class ExplicitSolver {
public:
    ExplicitSolver(nb::object model, std::optional<Index> hash_capacity, int threads,
                   bool float32)
        : handle_(model),
          model_(nb::cast<const CoreModel&>(model)),
          buffers_(model_.model(), 7, checked_capacity(model_.model(), hash_capacity)),
          threads_(threads, model_.model().bodies.count) {
        threads_.attach(buffers_.lanes_view);
        buffers_.allow_growth();  // the surface contacts grow their hash inside a run
        w_.f = buffers_.row(0);
        w_.q0 = buffers_.row(1);
        w_.v0 = buffers_.row(2);
        w_.qs = buffers_.row(3);
        w_.vs = buffers_.row(4);
        w_.acc_q = buffers_.row(5);
        w_.acc_v = buffers_.row(6);
        w_.gas = buffers_.gas;
        w_.lanes = buffers_.lanes_view;
        w_.contact = buffers_.contact;
        if (float32) use_float32();
    }

    std::tuple<int, Index, Index, double> simulate(int scheme, Index steps, double dt,
                                                   nb::handle control, nb::handle state,
                                                   nb::handle limits, nb::handle progress) {
        const softbody::Model& m = model_.model();
        if (scheme < Integrator::EULER || scheme > Integrator::VELOCITY_VERLET)
            fail("scheme must be an explicit Integrator (0-4)");
        CheckedRun run = checked_run(m, steps, dt, state, limits);
        run.params.scheme = scheme;
        CoreControl c(m, control);
        attach_gas(w_.gas, run);
        RunPoll poll(run.params, progress);
        softbody::RunResult r;
        {
            nb::gil_scoped_release release;
            r = softbody::kernels().simulate_explicit(m, c.view, run.params, run.state, w_);
        }
        poll.finish(state, run.params, r);
        return {r.status, r.steps_done, r.where, r.value};
    }

    Index hash_capacity() const { return buffers_.hash_capacity(); }
    bool float32() const { return w_.lanes.rows_f != nullptr; }
    int threads() const { return threads_.count(); }

private:
    /// The float32 force pass: its rows and float copies of the model's ring tables.
    void use_float32() {
        const softbody::Model& m = model_.model();
        const size_t lanes = static_cast<size_t>(8 * m.slots.group_count);
        const size_t slots = static_cast<size_t>(8 * m.slots.ring_start[m.slots.group_count]);
        rows_f_.assign(8 * lanes, 0.0f);  // padding rows stay zero
        auto copy = [slots](const double* from, std::vector<float>& to) {
            to.resize(slots);
            for (size_t k = 0; k < slots; ++k) to[k] = static_cast<float>(from[k]);
            return to.data();
        };
        softbody::LaneBuffers& l = w_.lanes;
        l.rows_f = rows_f_.data();
        l.ring_rest_length_f = copy(m.slots.ring_rest_length, rest_f_);
        l.ring_stiffness_f = copy(m.slots.ring_stiffness, stiffness_f_);
        l.ring_damping_f = copy(m.slots.ring_damping, damping_f_);
        l.ring_face_f = copy(m.slots.ring_face, face_f_);
        const index g = m.slots.group_count;
        // the membranes' lane form, too, reads the float64 rows
        l.extra_slots = m.slots.spring_start[g] > 0 || m.slots.face_start[g] > 0 ||
                        m.membranes.count > 0;
    }

    nb::object handle_;  // keeps the CoreModel (and so the model's arrays) alive
    const CoreModel& model_;
    Buffers buffers_;
    SolverThreads threads_;
    softbody::ExplicitBuffers w_;
    std::vector<float> rows_f_, rest_f_, stiffness_f_, damping_f_, face_f_;
};

}  // namespace

void bind_explicit(nb::module_& mod) {
    nb::class_<ExplicitSolver>(mod, "ExplicitSolver",
                               "The explicit schemes' time loop with its scratch buffers.")
        .def(nb::init<nb::object, std::optional<Index>, int, bool>(), nb::arg("model"),
             nb::arg("hash_capacity") = nb::none(), nb::arg("threads") = 1,
             nb::arg("float32") = false,
             "hash_capacity: entries of the surface contacts' spatial hash at first (default 8 "
             "per triangle); a run that needs more grows it, and returns NEED_HASH with the "
             "count needed only beyond 512 per triangle (a blow-up). "
             "threads: > 1 runs the force pass on that many threads, deterministically. "
             "float32: the ring's springs and faces in float32 (positions, velocities and "
             "the integration stay float64).")
        .def_prop_ro("threads", &ExplicitSolver::threads, "Threads of the force pass.")
        .def_prop_ro("float32", &ExplicitSolver::float32,
                     "Whether the force pass runs its springs and faces in float32.")
        .def_prop_ro("hash_capacity", &ExplicitSolver::hash_capacity,
                     "Entries the surface contacts' spatial hash holds (0 without them).")
        .def("simulate", &ExplicitSolver::simulate, nb::arg("scheme"), nb::arg("steps"),
             nb::arg("dt"), nb::arg("control"), nb::arg("state"), nb::arg("limits"),
             nb::arg("progress") = nb::none(),
             "Advance a softbody.State in place from its time (limits: a RunLimits); returns "
             "(status, steps_done, index, value). " RUN_POLL_DOC);
}

}  // namespace softbody::bindings
