"""``Simulator``: advance a State with one of the integrators."""

from __future__ import annotations

import functools
import operator
import threading
import warnings
from typing import Literal, Protocol

import numpy as np

from softbody.core import available_threads
from softbody.errors import SimulationError, StabilityWarning
from softbody.integrators import Integrator
from softbody.sim.control import Control, control_data
from softbody.sim.model import Model
from softbody.sim.progress import RunProgress
from softbody.sim.state import State
from softbody.solvers import RunLimits, Solver, Status, solver_class
from softbody.solvers.explicit import check_force_precision
from softbody.solvers.implicit import check_options as check_implicit_options
from softbody.solvers.projective import check_iterations as check_projective_iterations
from softbody.solvers.substep import DEFAULT_SUBSTEPS
from softbody.solvers.substep import check_count as check_xpbd_count
from softbody.solvers.substep import check_relaxation as check_xpbd_relaxation
from softbody.stability import stiffest_mode


class FrameRecorder(Protocol):
    """What :meth:`Simulator.advance` needs of ``record=``: ``softbody.Recorder`` (in the
    application layer, which the engine does not import) or any object with these two
    methods."""

    def frame_offsets(self, time: float, duration: float) -> np.ndarray:
        """Offsets [s] from ``time``, increasing, in [0, ``duration``], at which to
        capture, shape (K,)."""
        ...

    def capture(self, state: State, control: Control | None = None) -> None:
        """Keep ``state`` (advanced with ``control``) as a frame."""
        ...


#: With dt="auto": the fraction of the stability estimate used, and the largest step [s].
AUTO_SAFETY = 0.8
MAX_AUTO_DT = 1.0 / 60.0
#: With dt="auto": simulated seconds between re-estimates of the stable step.
AUTO_RECHECK = 0.25
#: Most steps one :meth:`Simulator.run` or :meth:`Simulator.advance` call takes. Counts
#: stay 64-bit integers in the compiled loop, and a call that long is a mistake: 1e12
#: steps of the smallest model take weeks.
MAX_STEPS = 10**12


def step_count(steps) -> int:
    """``steps`` as a Python int in [0, ``MAX_STEPS``]; a ``ValueError`` otherwise (a
    bool, a fraction, NaN, infinity, a negative or a too large count)."""
    if isinstance(steps, bool | np.bool_):
        raise ValueError(f"steps must be a non-negative integer, got {steps!r}")
    try:
        n = operator.index(steps)
    except TypeError:
        if isinstance(steps, float | np.floating) and float(steps).is_integer():
            n = int(steps)
        else:
            raise ValueError(f"steps must be a non-negative integer, got {steps!r}") from None
    if not 0 <= n <= MAX_STEPS:
        raise ValueError(f"steps must lie in [0, {MAX_STEPS:.0e}], got {steps!r}")
    return n


def _one_call_at_a_time(method):
    """``method`` of :class:`Simulator` under its lock, taken without waiting: a
    ``RuntimeError`` when another call holds it (the class's Threads)."""

    @functools.wraps(method)
    def call(self, *args, **kwargs):
        if not self._busy.acquire(blocking=False):
            raise RuntimeError(
                f"Simulator.{method.__name__}: this Simulator is already running a call in "
                "another thread, and its solver's buffers serve one call at a time: make "
                "one Simulator per thread (Simulator(model, integrator=sim.integrator, "
                "dt=..., **sim.options))"
            )
        try:
            return method(self, *args, **kwargs)
        finally:
            self._busy.release()

    return call


class Simulator:
    """Steps a :class:`Model`'s states forward in time.

    Parameters
    ----------
    model : Model
    integrator : str
        ``"velocity_verlet"`` (default: second order, and stable without growth on the
        undamped pressure and spring vibrations below its stable step), ``"midpoint"``
        (the paper's choice, which slowly amplifies undamped vibration at any dt),
        ``"euler"``, ``"rk4"``, ``"symplectic_euler"``, or the implicit ``"implicit_euler"``
        (backward Euler) and ``"bdf2"`` (second order, far less numerical damping; it uses
        the previous step, so its first step on a state, after dt changes, after the
        state was changed outside :meth:`run`, or after contacts acted, is a backward
        Euler step), both stable at any dt; or ``"projective"`` (projective dynamics:
        backward Euler by ``projective_iterations`` local-global iterations on a matrix
        factored once per dt; springs stable at any dt, pressure explicit, so
        :attr:`stable_dt` is 1 / omega_gas; fast at large meshes, and the fewer the
        iterations the softer and more damped the slow motion); or ``"xpbd"`` (XPBD with
        small steps: ``xpbd_substeps`` substeps per step, each the explicit forces, then
        ``xpbd_iterations`` passes of the springs' and attachments' compliant constraints;
        the springs stable at any dt, the pressure explicit per substep, so
        :attr:`stable_dt` is ``xpbd_substeps`` / omega_gas; keeps a dropped ball's bounce
        at 1/60 s, converging to the springs' true dynamics as the substeps grow).
    dt : float or "auto"
        Time step [s], > 0. A :class:`StabilityWarning` is issued when it exceeds
        :attr:`stable_dt`. ``"auto"`` (default) picks it from the stability estimate (and
        :meth:`advance` re-picks it from the current state).
    max_speed : float
        A particle faster than this [m/s] means the run blew up (runaway energy).
    volume_limits : (float, float)
        A body whose volume leaves [low, high] times its rest volume blew up.
    implicit_tolerance : float
        ``implicit_euler`` and ``bdf2``: relative residual at which its conjugate-gradient solve
        stops, in (0, 1).
    implicit_max_iterations : int
        ``implicit_euler`` and ``bdf2``: most CG iterations per step (a step that reaches it keeps
        the last iterate; :attr:`solver_iterations` tells).
    threads : int
        Threads for the force pass, >= 1 and at most the cores this process may use
        (``softbody.core.available_threads()``). Default 1: serial. Every solver runs the
        compiled core's force pass (springs, dV/dx and the volumes; for projective dynamics
        dV/dx and the volumes) on that many threads, each on a fixed run of particles, and
        adds the chunks' volume sums in a fixed order; the implicit solve and projective
        dynamics' triangular solves stay serial. Results agree with the serial ones to
        round-off and are the same in every run. Opt-in because a thread that loses its
        core to another process stalls the whole step, and because handing the pass to
        the threads costs more than it saves on small meshes: measured on a 2-core
        machine (``benchmarks/pressure_scaling.py``), symplectic Euler on 2 threads ran
        0.03x as fast as on one at 162 particles, 0.4x at 2,562, and no faster at 10,242
        and 40,962.
    implicit_preconditioner : str
        ``implicit_euler`` and ``bdf2``: ``"multigrid"`` (default; one algebraic-multigrid V-cycle
        of the spring Laplacian, built once, so the iteration count barely grows with mesh
        size) or ``"jacobi"`` (the diagonal; iterations grow like omega_max dt).
    projective_iterations : int
        ``projective``: local-global iterations per step, >= 1 (default 2); each costs a
        pass over the springs and the non-spring forces and two triangular solves. More
        converge to backward Euler (``softbody.solvers.factor``).
    xpbd_substeps : int
        ``xpbd``: substeps per step, >= 1 (default ``softbody.solvers.substep.DEFAULT_SUBSTEPS``,
        the fewest that keep the 2,562-vertex ball drop's bounce at 1/60 s); the error
        falls like dt / xpbd_substeps.
    xpbd_iterations : int
        ``xpbd``: constraint passes per substep, >= 1 (default 1: more substeps beat more
        iterations, Macklin et al. 2019).
    xpbd_relaxation : float
        ``xpbd``: the over-relaxation factor omega, in (0, 2), of every constraint pass
        after a substep's first (default 1.0: plain Gauss-Seidel). 1.9 with 4 passes
        keeps the 10,242-vertex ball drop's bounce with an eighth of the substeps one plain
        pass needs (docs/guide/integrators.md); a lone constraint stays exact at any omega.
    force_precision : str
        The explicit schemes: ``"float64"`` (default) or ``"float32"``, the precision of
        the force pass's mesh springs, dV/dx and volume shares. Positions, velocities,
        the integration, the pressure and every sum stay float64; float32 perturbs the
        forces as if each position moved by 2^-24 of its body's size (60 nm on a 1 m
        ball); a step runs 1.2-2.2x as fast with AVX2 or AVX-512 (0.4-0.75x on the scalar
        path). ``benchmarks/float32.py`` measures its drift against float64 (user guide:
        "Choosing an integrator"). Another integrator with ``"float32"`` is a
        ``ValueError``.

    A step that blows up raises :class:`SimulationError` naming the body or particle, the
    step and the time; the state is left at the last good step.

    **Interrupting.** Ctrl-C, a Jupyter interrupt, or any Python signal handler that
    raises (the ``softbody`` command line turns SIGTERM into one) stops a long
    :meth:`run` or :meth:`advance` within 50 ms and one step: the compiled loop runs
    Python's signal handlers between steps every 50 ms, and the exception
    (``KeyboardInterrupt``) is raised with the state at the last whole step: positions,
    velocities, ``time`` and ``step_count`` all describe it (as after a blow-up).
    Without a handler SIGTERM ends the process at once (Python's default). Signal handlers
    run on the main thread only, so a run on another thread finishes its call.

    **Threads.** A Simulator steps one state at a time: its solver's scratch buffers,
    step and caches serve one call. A call while another thread's call on the same
    Simulator is running raises ``RuntimeError``; make one Simulator per thread (each its
    own state; ``Simulator(model, integrator=sim.integrator, dt=..., **sim.options)``).
    Models, and states not shared, can be used from any number of threads at once.

    Every registered term (``softbody.core.terms()``) is stepped by every integrator. A term
    with no Jacobian product (the air on faces) enters ``implicit_euler`` and ``bdf2``
    explicitly, its force at the step's start (stable while dt < 2 m / (dF/dv): v_t / g
    for a body falling through air at its terminal speed v_t), and projective dynamics
    takes every term without a projection, like the pressure, as a force at each iterate.
    """

    def __init__(
        self,
        model: Model,
        *,
        integrator: str | Integrator = "velocity_verlet",
        dt: float | Literal["auto"] = "auto",
        max_speed: float = 1.0e4,
        volume_limits: tuple[float, float] = (1.0e-3, 1.0e3),
        implicit_tolerance: float = 1.0e-6,
        implicit_max_iterations: int = 200,
        implicit_preconditioner: str = "multigrid",
        threads: int = 1,
        projective_iterations: int = 2,
        force_precision: str = "float64",
        xpbd_substeps: int = DEFAULT_SUBSTEPS,
        xpbd_iterations: int = 1,
        xpbd_relaxation: float = 1.0,
    ):
        if not isinstance(model, Model):
            raise TypeError(f"model must be a softbody.Model, got {type(model).__name__}")
        self.model = model
        # held by each run/advance/step call: a second thread's call is refused (see Threads)
        self._busy = threading.Lock()
        self.integrator = Integrator.parse(integrator)
        self.auto_dt = isinstance(dt, str) and dt == "auto"
        self._auto_limit: float | None = None
        self._auto_time = 0.0
        if self.auto_dt:
            dt = MAX_AUTO_DT
        try:
            dt = float(dt)
        except (TypeError, ValueError):
            raise ValueError(f"dt must be a number of seconds or 'auto', got {dt!r}") from None
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0 seconds, got {dt!r}")
        self.dt = dt
        if not (np.isfinite(max_speed) and max_speed > 0):
            raise ValueError(f"max_speed must be finite and > 0, got {max_speed!r}")
        self.max_speed = float(max_speed)
        lo, hi = (float(x) for x in volume_limits)
        if not (0 < lo < 1 < hi):
            raise ValueError(f"volume_limits must satisfy 0 < low < 1 < high, got {volume_limits}")
        self.volume_limits = (lo, hi)
        # every method's options are checked, whichever this simulator uses, so a typo
        # fails the same way for every integrator
        (self.implicit_tolerance, self.implicit_max_iterations,
         self.implicit_preconditioner) = check_implicit_options(
            implicit_tolerance, implicit_max_iterations, implicit_preconditioner
        )  # fmt: skip
        self.projective_iterations = check_projective_iterations(projective_iterations)
        self.xpbd_substeps = check_xpbd_count("xpbd_substeps", xpbd_substeps)
        self.xpbd_iterations = check_xpbd_count("xpbd_iterations", xpbd_iterations)
        self.xpbd_relaxation = check_xpbd_relaxation(xpbd_relaxation)
        self.force_precision = check_force_precision(force_precision)
        if self.force_precision != "float64" and not self.integrator.explicit:
            raise ValueError(
                f"force_precision={self.force_precision!r} is for the explicit schemes; "
                f"{self.integrator.name.lower()} runs its force pass in float64"
            )
        available = available_threads()
        if (
            isinstance(threads, bool)
            or not isinstance(threads, int | np.integer)
            or not 1 <= threads <= available
        ):
            raise ValueError(
                f"threads must be an integer from 1 to {available} (the cores this process "
                f"may use), got {threads!r}"
            )
        self.threads = int(threads)
        cls = solver_class(self.integrator)
        own = {k: v for k, v in self.options.items() if k in cls.option_names}
        #: The solver that steps this simulator's states (softbody.solvers).
        self.solver: Solver = cls(model, self.integrator, threads=self.threads, **own)
        # implicit schemes have no step limit: the Gershgorin bounds describe the model
        # without the Lanczos runs (seconds at 100k particles)
        self.stiffest_mode = stiffest_mode(model, spectral=self.integrator.explicit)
        self.stable_dt = self.solver.stable_step(self.stiffest_mode)
        self._neutral = control_data(model)
        self._control = control_data(model)
        if self.auto_dt:
            self.dt = min(MAX_AUTO_DT, AUTO_SAFETY * self.stable_dt)
        elif dt > self.stable_dt:
            warnings.warn(self.stability_note(), StabilityWarning, stacklevel=2)

    def __repr__(self) -> str:
        dt = f"{self.dt:.4g}" + (" (auto)" if self.auto_dt else "")
        return (
            f"Simulator(integrator={self.integrator.name.lower()!r}, dt={dt}, "
            f"stable_dt={self.stable_dt:.4g}, particle_count={self.model.particle_count}, "
            f"body_count={self.model.body_count}, threads={self.threads})"
        )

    @property
    def options(self) -> dict:
        """The keyword options this simulator was built with, other than the model,
        integrator and dt: ``Simulator(model, integrator=..., dt=..., **sim.options)``
        builds one that solves, checks and threads the same way (the viewer does this when
        the integrator or the model changes)."""
        return {
            "max_speed": self.max_speed,
            "volume_limits": self.volume_limits,
            "implicit_tolerance": self.implicit_tolerance,
            "implicit_max_iterations": self.implicit_max_iterations,
            "implicit_preconditioner": self.implicit_preconditioner,
            "projective_iterations": self.projective_iterations,
            "force_precision": self.force_precision,
            "xpbd_substeps": self.xpbd_substeps,
            "xpbd_iterations": self.xpbd_iterations,
            "xpbd_relaxation": self.xpbd_relaxation,
            "threads": self.threads,
        }

    @property
    def solver_iterations(self) -> tuple[float, int]:
        """``implicit_euler``, ``bdf2``: (mean, most) CG iterations per step over the
        last :meth:`run` call; (0, 0) for explicit integrators."""
        return self.solver.iterations

    def stability_note(self) -> str:
        """One line comparing ``dt`` with the stability estimate, with advice."""
        mode = self.stiffest_mode
        name = self.integrator.name.lower()
        if self.integrator == Integrator.PROJECTIVE:
            return (
                f"dt = {self.dt:.3g} s exceeds the stable estimate {self.stable_dt:.3g} s for "
                f"projective (gas volume mode {mode.omega_gas:.3g} rad/s; projective dynamics "
                "takes the pressure explicitly); reduce dt or the gas's pressure, or add mass"
            )
        if self.integrator == Integrator.XPBD:
            return (
                f"dt = {self.dt:.3g} s exceeds the stable estimate {self.stable_dt:.3g} s for "
                f"xpbd at {self.xpbd_substeps} substeps (gas volume mode "
                f"{mode.omega_gas:.3g} rad/s"
                + "".join(f", {name} {w:.3g} rad/s" for name, w in mode.omega_terms.items())
                + ", explicit within each substep); raise xpbd_substeps, reduce dt or the gas's "
                "pressure, or add mass"
            )
        text = (
            f"dt = {self.dt:.3g} s exceeds the stable estimate {self.stable_dt:.3g} s for "
            f"{name} (stiffest mode {mode.omega:.3g} rad/s, damping ratio {mode.zeta:.2g})"
        )
        weak = mode.zeta < 1e-3 or mode.omega_undamped > 0
        if self.integrator in (Integrator.EULER, Integrator.MIDPOINT) and weak:
            text += (
                "; euler and midpoint amplify undamped vibration (pressure, stretched "
                "springs) at any dt: use rk4, symplectic_euler or velocity_verlet"
            )
        else:
            text += "; reduce dt, stiffness or pressure, or add mass"
        return text

    @_one_call_at_a_time
    def advance(
        self,
        state: State,
        duration: float,
        control: Control | None = None,
        *,
        record: FrameRecorder | None = None,
        progress: bool | None = None,
    ) -> State:
        """Advance ``state`` by ``duration`` [s] in equal substeps.

        With ``dt="auto"`` the substep is chosen from the stability estimate at the
        current positions (``AUTO_SAFETY`` times the largest stable step, at most
        ``MAX_AUTO_DT``; 1/60 s for implicit Euler), re-estimated every ``AUTO_RECHECK``
        simulated seconds, so the run stays stable as the gas and shape change;
        otherwise the substeps are no longer than ``dt``. The state
        ends exactly ``duration`` later.

        ``record``: a :class:`softbody.Recorder` (or any object with its
        ``frame_offsets(time, duration)`` and ``capture(state, control)`` methods) that
        captures the state at its frame times within the call: every 1 / fps seconds,
        the start included when it is the recording's first frame. The call advances from
        frame to frame (each stretch in equal substeps, as above) and ends exactly
        ``duration`` later; if a step blows up, the frames before it are kept.

        ``progress``: a progress bar (tqdm; a widget in a notebook) on stderr. None
        (default) shows one when the call, judged after 0.5 s, will take longer than 2 s,
        and only where it can be seen (stderr is a terminal, or a Jupyter kernel); True
        always, False never. The bar does not change the steps taken.
        """
        duration = float(duration)
        if not (np.isfinite(duration) and duration >= 0):
            raise ValueError(f"duration must be finite and >= 0 seconds, got {duration!r}")
        if record is not None:
            return self._advance_recorded(state, duration, control, record, progress)
        return self._advance(state, duration, control, progress)

    def _advance(
        self, state: State, duration: float, control: Control | None, progress: bool | None
    ) -> State:
        """:meth:`advance`'s steps, in the caller's hold of the lock."""
        if duration == 0:
            return state
        state.conform(self.model)
        limit = self.dt
        if self.auto_dt:
            # re-estimate from the current shape and gas now and then (it costs Lanczos
            # runs on the Jacobians); between estimates keep the last substep limit
            if self._auto_limit is None or abs(state.time - self._auto_time) >= AUTO_RECHECK:
                mode = stiffest_mode(
                    self.model, state.particle_q, spectral=self.integrator.explicit
                )
                self._auto_limit = min(
                    MAX_AUTO_DT,
                    AUTO_SAFETY * self.solver.stable_step(mode),
                )
                self._auto_time = state.time
            limit = self._auto_limit
        substeps = max(1, np.ceil(duration / limit - 1e-9))
        if substeps > MAX_STEPS:
            raise ValueError(
                f"advancing {duration:.6g} s in steps of at most {limit:.3g} s takes "
                f"{substeps:.3g} steps, over the limit of {MAX_STEPS:.0e} per call"
            )
        substeps = int(substeps)
        saved, self.dt = self.dt, duration / substeps
        try:
            self._run(state, substeps, control, progress)
        finally:
            if not self.auto_dt:
                self.dt = saved
        return state

    def _advance_recorded(
        self,
        state: State,
        duration: float,
        control: Control | None,
        record: FrameRecorder,
        progress: bool | None,
    ) -> State:
        """:meth:`advance` in stretches between ``record``'s frame times, capturing at each."""
        for name in ("frame_offsets", "capture"):
            if not callable(getattr(record, name, None)):
                raise TypeError(
                    "record must be a softbody.Recorder (an object with frame_offsets(time, "
                    f"duration) and capture(state, control)), got {type(record).__name__}"
                )
        state.conform(self.model)
        offsets = np.asarray(record.frame_offsets(float(state.time), duration), dtype=float)
        if offsets.ndim != 1 or not (
            np.all(np.isfinite(offsets))
            and np.all(offsets >= 0)
            and np.all(offsets <= duration)
            and np.all(np.diff(offsets) >= 0)
        ):
            raise ValueError(
                "record.frame_offsets must return increasing offsets within [0, duration]"
            )
        done = 0.0
        for offset in offsets:
            if offset > done:
                self._advance(state, offset - done, control, progress)
                done = float(offset)
            record.capture(state, control)
        if duration > done:
            self._advance(state, duration - done, control, progress)
        return state

    @_one_call_at_a_time
    def step(self, state: State, control: Control | None = None) -> State:
        """Advance ``state`` by one step of ``dt`` in place; returns it."""
        return self._run(state, 1, control, False)

    @_one_call_at_a_time
    def run(
        self,
        state: State,
        steps: int,
        control: Control | None = None,
        *,
        progress: bool | None = None,
    ) -> State:
        """Advance ``state`` in place by ``steps`` steps with the same ``control``.

        One compiled call does all the steps, so this is the fast path for long runs.
        ``progress`` as in :meth:`advance`.
        """
        return self._run(state, steps, control, progress)

    def _run(self, state: State, steps, control: Control | None, progress) -> State:
        model = self.model
        steps = step_count(steps)
        state.conform(model)
        if steps == 0:
            return state
        data = self._neutral if control is None else control.write(model, self._control)
        limits = RunLimits(self.max_speed, *self.volume_limits)
        bar = RunProgress.start(steps, state.time, self.dt, progress)
        state.collider_impulse[:] = 0.0
        solver = self.solver
        first = state.step_count
        solver.begin_run()
        remaining = steps
        try:
            while remaining:
                # the core advances state.time and state.step_count with the arrays
                result = solver.simulate(
                    state, remaining, self.dt, data, limits,
                    None if bar is None else bar.callback(steps - remaining),
                )  # fmt: skip
                remaining -= result.steps_done
                if result.status != Status.OK:
                    raise self._blow_up(result.status, state.step_count, state.time,
                                        result.where, result.value)  # fmt: skip
        finally:
            solver.end_run()
            if state.step_count != first:  # what the last step applied, for the readbacks
                np.copyto(state.body_gas_override, data.gas_override)
            if bar is not None:
                bar.close(state.step_count - first)
        return state

    def _blow_up(self, status, step, time, index, value) -> SimulationError:
        model = self.model
        where = f"at step {step} (t = {time:.6g} s)"
        if status in (Status.NONFINITE, Status.RUNAWAY):
            body = int(model.particle_body[index])
            who = f"body {body}" if body >= 0 else "free particle"
            what = (
                "position or velocity became NaN or infinite"
                if status == Status.NONFINITE
                else f"speed {value:.3g} m/s exceeds max_speed {self.max_speed:.3g} m/s "
                "(runaway kinetic energy)"
            )
            msg = f"{who} blew up {where}: particle {index} {what}"
            particle = int(index)
        elif status == Status.CROSSED:
            # value: the triangle, or -1 - the triangle where a collider pushed the edge
            # through it in this step (core/collision/thick_system.hpp), or below -T a mesh
            # collider's crossing
            particle, tri = int(index), int(value)
            body = int(model.particle_body[particle])
            when = (
                "at the step's start (an initial self-intersection, or a collider pushed one "
                "sheet through another)"
                if tri >= 0
                else "after a collider pushed it there in this step (the state is left at "
                "the step's start)"
            )
            tri = tri if tri >= 0 else -1 - tri
            if tri >= model.tri_count:
                # a mesh collider's edge contacts left it: code 2 (k S + x) + kind, S the larger
                # of the particle and triangle counts (core/collision/mesh.hpp, crossing_code)
                code = tri - model.tri_count
                span = max(model.particle_count, model.tri_count)
                collider, x = divmod(code // 2, span)
                what = (
                    f"the triangle {x} (particles {', '.join(map(str, model.tri_indices[x]))})"
                    if code % 2
                    else f"the edge from particle {particle} to particle {x}"
                )
                msg = (
                    f"body {body} crossed mesh collider {collider} {where}: {what} passes "
                    "through it, or passed through it within the step, and its edge contacts "
                    "could not hold it back (pushed to their limit, or every particle there "
                    "pinned; the state is left at the step's start)"
                )
            else:
                msg = (
                    f"body {body} crossed a surface {where}: the edge at particle {particle} "
                    f"passes through triangle {tri} (body {int(model.tri_body[tri])}) {when}"
                )
        elif status == Status.NEED_HASH:
            # the core grows the contacts' hash itself up to 512 entries per triangle
            body, particle = -1, -1
            msg = (
                f"surface contacts blew up {where}: the triangles span {value:.3g} grid cells, "
                f"over 512 per triangle ({model.tri_count} triangles); a triangle has "
                "stretched far past its rest size"
            )
        elif status == Status.NEED_PAIRS:
            # the core grows the thickness contacts' pair list itself up to 4096 per triangle
            body, particle = -1, -1
            msg = (
                f"surface contacts blew up {where}: the contact pair list needs {value:.0f} "
                f"pairs, over 4096 per triangle ({model.tri_count} triangles); sheets are "
                "packed far closer than the thickness, or a triangle has stretched far past "
                "its rest size"
            )
        else:
            body, particle = int(index), -1
            lo, hi = self.volume_limits
            what = {
                Status.BAD_GAS: f"gas amount became {value:.3g} mol (negative or not finite; "
                "a flow too fast for the step)",
                Status.BAD_VOLUME: f"volume became {value:.3g} m^3 (collapsed or inverted)",
                Status.SHRUNK: f"volume fell to {value:.3g} of its rest volume (limit {lo:g})",
                Status.EXPLODED: f"volume grew to {value:.3g} times its rest volume (limit {hi:g})",
            }[status]
            msg = f"body {body} blew up {where}: {what}"
        if self.dt > self.stable_dt:
            msg += "; " + self.stability_note()
        return SimulationError(msg, step=step, time=time, body=body, particle=particle)
