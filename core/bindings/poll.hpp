// What a solver's run does between its steps for Python: runs Python's signal handlers (so
// Ctrl-C, a SIGTERM handler or a Jupyter interrupt stops a long run between two steps),
// reports progress, and at the end writes the run's clock (time, step count) back to the
// state before any Python code runs, so that the state is consistent however the call ends.
#pragma once

#include <chrono>

#include "bindings/arrays.hpp"

namespace softbody::bindings {

/// A run's RunParams::poll. The loop calls it before every step; it reads the clock every
/// `stride` calls (the stride adapts so that the reads come about every millisecond, so a
/// call costs a decrement whatever a step costs), and every kCheckInterval of wall time it
/// takes the GIL to run Python's signal handlers (on the main thread, the only one where
/// Python runs them) and to call `progress(steps_done)`. An exception from either stops the
/// run (STOPPED); finish() raises it once the state's clock is written.
class RunPoll {
public:
    // Taking the GIL waits up to Python's switch interval (5 ms) while another thread runs
    // Python code: every 50 ms keeps that below 10% of the run, and a stop within 0.1 s.
    static constexpr std::chrono::milliseconds kCheckInterval{50};

    RunPoll(softbody::RunParams& p, nb::handle progress) : progress_(progress) {
        signals_ = PyThread_get_thread_ident() == main_thread();
        if (!signals_ && progress_.is_none()) return;
        last_read_ = Clock::now();
        next_check_ = last_read_ + kCheckInterval;
        p.poll = &RunPoll::poll;
        p.poll_context = this;
    }
    ~RunPoll() {  // the binding's scope holds the GIL
        Py_XDECREF(type_);
        Py_XDECREF(value_);
        Py_XDECREF(traceback_);
    }
    RunPoll(const RunPoll&) = delete;
    RunPoll& operator=(const RunPoll&) = delete;

    /// With the GIL, after the run: clock.time = p.time_at(steps_done),
    /// clock.step_count += steps_done and clock._clock = (p.t0, the step count at p.t0,
    /// p.dt), the origin the next run goes on from (checked_run's clock_from; clock None:
    /// nothing); then the exception that stopped the run, if any, is raised.
    void finish(nb::handle clock, const softbody::RunParams& p, const softbody::RunResult& r) {
        if (!clock.is_none()) {
            const nb::object count = clock.attr("step_count");
            clock.attr("time") = nb::float_(p.time_at(r.steps_done));
            clock.attr("step_count") = count + nb::int_(r.steps_done);
            const nb::object origin_count = count - nb::int_(static_cast<long long>(p.step0));
            clock.attr("_clock") = nb::make_tuple(p.t0, origin_count, p.dt);
        }
        if (type_ != nullptr) {
            PyErr_Restore(type_, value_, traceback_);
            type_ = value_ = traceback_ = nullptr;
            throw nb::python_error();
        }
        if (r.status == softbody::STOPPED) fail("the run stopped with no exception to raise");
    }

private:
    using Clock = std::chrono::steady_clock;
    static constexpr index kMostStride = index(1) << 20;

    static int poll(void* context, index steps_done) {
        RunPoll& self = *static_cast<RunPoll*>(context);
        if (--self.countdown_ > 0) return 0;
        const Clock::time_point now = Clock::now();
        const Clock::duration since = now - self.last_read_;
        if (since < std::chrono::microseconds(500) && self.stride_ < kMostStride)
            self.stride_ *= 2;
        else if (since > std::chrono::milliseconds(2) && self.stride_ > 1)
            self.stride_ /= 2;
        self.countdown_ = self.stride_;
        self.last_read_ = now;
        if (now < self.next_check_) return 0;
        self.next_check_ = now + kCheckInterval;
        PyGILState_STATE gil = PyGILState_Ensure();
        bool stop = self.signals_ && PyErr_CheckSignals() != 0;
        if (!stop && !self.progress_.is_none()) {
            PyObject* done = PyLong_FromLongLong(static_cast<long long>(steps_done));
            PyObject* out = done ? PyObject_CallOneArg(self.progress_.ptr(), done) : nullptr;
            Py_XDECREF(done);
            stop = out == nullptr;
            Py_XDECREF(out);
        }
        if (stop) PyErr_Fetch(&self.type_, &self.value_, &self.traceback_);
        PyGILState_Release(gil);
        return stop ? 1 : 0;
    }

    /// The ident of Python's main thread (looked up once, with the GIL).
    static unsigned long main_thread() {
        static const unsigned long ident = nb::cast<unsigned long>(
            nb::module_::import_("threading").attr("main_thread")().attr("ident"));
        return ident;
    }

    nb::handle progress_;  // borrowed from the call's arguments
    bool signals_ = false;
    index stride_ = 1, countdown_ = 1;
    Clock::time_point last_read_, next_check_;
    PyObject *type_ = nullptr, *value_ = nullptr, *traceback_ = nullptr;
};

}  // namespace softbody::bindings

/// The docstring of the solvers' simulate() arguments clock and progress.
#define RUN_POLL_DOC                                                                          \
    "The state's time [s] and step_count advance by the steps done before the call "        \
    "returns or raises. progress: called with the steps done every 50 ms or so. "          \
    "Python's signal handlers run between steps (on the main thread): an exception from "    \
    "one (KeyboardInterrupt) or from progress stops the run and is raised."
