"""What changes every step: positions, velocities, time."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def kernel_array(a) -> np.ndarray:
    """``a`` as the compiled kernels take every state array: float64, C-contiguous,
    aligned and writable (a copy only when ``a`` is not already all of these).

    The core writes the state in place and refuses any other kind of array with a
    ValueError; every array that crosses into it goes through here (or
    :meth:`State.conform`), so a user's read-only, float32 or strided arrays are
    converted instead.
    """
    return np.require(a, dtype=np.float64, requirements=["C", "A", "W"])


def _kernel_ready(a, shape: tuple) -> bool:
    """Whether ``a`` is already what :func:`kernel_array` makes, with this shape."""
    if type(a) is not np.ndarray or a.dtype != np.float64 or a.shape != shape:
        return False
    flags = a.flags
    return flags.c_contiguous and flags.writeable and flags.aligned


def kernel_input(a, dtype=np.float64) -> np.ndarray:
    """``a`` as the compiled kernels take a model's arrays: C-contiguous, aligned and
    read-only (a read-only view; a copy only when the layout or ``dtype`` differs), for
    a call from Python that passes arrays the compiled loop takes from a ``Model``."""
    view = np.require(a, dtype=dtype, requirements=["C", "A"]).view()
    view.flags.writeable = False
    return view


@dataclass(eq=False)
class StepHistory:
    """A multistep scheme's memory of the step before a state's (BDF2: that step's start),
    which the state carries (:attr:`State.history`) so that any solver of that scheme can
    go on from it. It belongs to the state while the state's ``step_count`` and
    :attr:`State.version` are the ones recorded here and the step is ``dt``; otherwise the
    scheme starts over (BDF2: a backward Euler step)."""

    dt: float
    """The step [s] it was taken with."""
    step_count: int
    """The state's step count it belongs to."""
    version: int
    """The state's :attr:`State.version` it belongs to."""
    particle_q: np.ndarray
    """Positions at the previous step's start [m], shape (N, 3) (the core writes them)."""
    particle_qd: np.ndarray
    """Velocities at the previous step's start [m/s], shape (N, 3)."""
    contacts_acted: bool = False
    """Whether contacts moved a particle in the last step (BDF2 then steps as backward
    Euler: it would read a projection as motion)."""

    def belongs_to(self, state: State, dt: float) -> bool:
        """Whether this is ``state``'s history for a step of ``dt`` [s]: no write the
        state saw since (its version), no step taken by another scheme, the same dt."""
        return (
            self.dt == dt
            and self.step_count == state.step_count
            and self.version == state.version
            and self.particle_q.shape == state.particle_q.shape
        )

    def copy(self) -> StepHistory:
        """An independent copy."""
        return StepHistory(self.dt, self.step_count, self.version, self.particle_q.copy(),
                           self.particle_qd.copy(), self.contacts_acted)  # fmt: skip


# assignments that change what a state is, which end a multistep scheme's history
_TRACKED = frozenset({"particle_q", "particle_qd"})


@dataclass(eq=False)
class State:
    """Positions and velocities of all particles at one instant.

    Volumes, pressures and energies are derived from it by
    :func:`softbody.body_volume`, :func:`softbody.body_pressure` and :func:`softbody.energies`.
    ``Simulator.step`` advances a state in place.

    A state carries the history a multistep scheme keeps (:attr:`history`: BDF2's previous
    step), valid while nothing else writes the state. Assigning ``particle_q`` or
    ``particle_qd`` is seen (it bumps :attr:`version`, and the next BDF2 step is backward
    Euler); an edit in place (``state.particle_q[i] = ...``) is not, since no array is
    compared: call :meth:`mark_edited` after one, or BDF2 reads the edit as motion.
    """

    particle_q: np.ndarray
    """Particle positions [m], shape (N, 3), float64, C-contiguous."""
    particle_qd: np.ndarray
    """Particle velocities [m/s], shape (N, 3), float64, C-contiguous."""
    time: float = 0.0
    """Simulated time [s]. A run goes on from the clock origin of the run before it (its
    step k at origin + (steps since the origin + k) dt, as one longer run would time it) while
    the time is the one that run left and the step the same; set by hand, or with another
    step, the time starts a new origin. So n runs of one step time their steps as one run of
    n steps does, to the bit."""
    step_count: int = 0
    """Number of steps taken since the state was made."""
    collider_q: np.ndarray | None = None
    """Centre of each rigid collider [m], shape (C, 3)."""
    collider_rotation: np.ndarray | None = None
    """Orientation of each rigid collider, shape (C, 3, 3)."""
    collider_impulse: np.ndarray | None = None
    """Impulse each collider received from particles during the last ``Simulator.run``
    call [N s], shape (C, 3)."""
    body_gas_override: np.ndarray | None = None
    """The gas value the last step's :class:`Control` set for each body (nRT [J], or P0
    [Pa] for fixed pressure), shape (B,); NaN where the model's value or schedule applied
    (and before any step). :func:`softbody.body_pressure`, :func:`softbody.body_gas_value`
    and :func:`softbody.energies` read it when given no control, so they report what was
    applied. None until the state meets its model (``model.state()`` fills it)."""
    body_gas_moles: np.ndarray | None = None
    """Amount of gas in each body [mol], shape (B,): what the gas law's nRT comes from
    (``Gas.ideal``), changed by vents, orifices, inflators and leaks; for a body whose gas
    is prescribed (a fixed pressure, a schedule, a :class:`Control` value) the amount that
    value means at the body's temperature. 0 for an open surface. None until the state
    meets its model (the model's initial amounts)."""
    body_gas_temperature: np.ndarray | None = None
    """Temperature of each body's gas [K], shape (B,): constant for an isothermal gas; for
    an adiabatic gas it follows its volume (P V^gamma constant) and the enthalpy the flows
    bring and take. A state's gas is what its amount and temperature say: positions set by
    hand leave the temperature as it was; set this to None to put each adiabatic gas back
    on its isentrope at the state's positions (which is what a state that never had one
    gets when it meets its model: the model's temperature at the initial volume)."""
    vent_open: np.ndarray | None = None
    """1.0 for each vent that has opened (at its opening pressure or time; it stays open),
    else 0.0, shape (V,). None until the state meets its model (all closed)."""
    history: StepHistory | None = field(default=None, repr=False)
    """A multistep scheme's history (:class:`StepHistory`; BDF2 writes it), or None: the
    next BDF2 step is backward Euler. :meth:`copy` copies it."""

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)
        if name in _TRACKED:
            object.__setattr__(self, "_version", self.__dict__.get("_version", 0) + 1)

    @property
    def version(self) -> int:
        """A counter of the writes this state sees: assigning ``particle_q`` or
        ``particle_qd``, and :meth:`mark_edited`. A solver's history records it and holds
        only while it is unchanged."""
        return self.__dict__.get("_version", 0)

    def mark_edited(self) -> None:
        """Say that an array was edited in place (which no assignment shows): bumps
        :attr:`version`, so the next BDF2 step starts over with backward Euler."""
        object.__setattr__(self, "_version", self.version + 1)

    def __post_init__(self):
        if self.collider_q is None:
            self.collider_q = np.zeros((0, 3))
        if self.collider_rotation is None:
            self.collider_rotation = np.zeros((len(self.collider_q), 3, 3)) + np.eye(3)
        if self.collider_impulse is None:
            self.collider_impulse = np.zeros((len(self.collider_q), 3))
        self.collider_q = kernel_array(self.collider_q)
        self.collider_rotation = kernel_array(self.collider_rotation)
        self.collider_impulse = kernel_array(self.collider_impulse)
        self.particle_q = kernel_array(self.particle_q)
        self.particle_qd = kernel_array(self.particle_qd)
        for name in ("body_gas_override", "body_gas_moles", "body_gas_temperature", "vent_open"):
            if getattr(self, name) is not None:
                setattr(self, name, kernel_array(getattr(self, name)))
        if self.particle_q.ndim != 2 or self.particle_q.shape[1] != 3:
            raise ValueError(f"particle_q must have shape (N, 3), got {self.particle_q.shape}")
        if self.particle_qd.shape != self.particle_q.shape:
            raise ValueError(
                f"particle_qd shape {self.particle_qd.shape} differs from particle_q "
                f"shape {self.particle_q.shape}"
            )

    def conform(self, model) -> None:
        """Check this state's array shapes against ``model`` and make every array
        float64, C-contiguous and writable (:func:`kernel_array`), replacing an attribute
        a user set to some other kind of array. Raises ``ValueError`` naming the array."""
        n, c = model.particle_count, model.collider_count
        if self.body_gas_override is None:
            self.body_gas_override = np.full(model.body_count, np.nan)
        if self.body_gas_moles is None:
            self.body_gas_moles = model.initial_gas_moles()
        if self.body_gas_temperature is None:
            self.body_gas_temperature = model.gas_temperature_at(self.particle_q)
        if self.vent_open is None:
            self.vent_open = np.zeros(len(model.vent_body))
        for name, shape in (
            ("particle_q", (n, 3)),
            ("particle_qd", (n, 3)),
            ("collider_q", (c, 3)),
            ("collider_rotation", (c, 3, 3)),
            ("collider_impulse", (c, 3)),
            ("body_gas_override", (model.body_count,)),
            ("body_gas_moles", (model.body_count,)),
            ("body_gas_temperature", (model.body_count,)),
            ("vent_open", (len(model.vent_body),)),
        ):
            value = getattr(self, name)
            if _kernel_ready(value, shape):
                continue  # the usual case, in a few flag reads (this runs every run call)
            try:
                array = kernel_array(value)
            except (TypeError, ValueError):
                raise ValueError(f"state.{name} must be an array of numbers") from None
            if array.shape != shape:
                raise ValueError(
                    f"state.{name} has shape {array.shape}, the model needs {shape}"
                )
            setattr(self, name, array)

    def copy(self) -> State:
        """An independent copy, its history with it (a solver goes on from the copy as
        from this state)."""
        out = State(
            self.particle_q.copy(),
            self.particle_qd.copy(),
            self.time,
            self.step_count,
            self.collider_q.copy(),
            self.collider_rotation.copy(),
            self.collider_impulse.copy(),
            None if self.body_gas_override is None else self.body_gas_override.copy(),
            None if self.body_gas_moles is None else self.body_gas_moles.copy(),
            None if self.body_gas_temperature is None else self.body_gas_temperature.copy(),
            None if self.vent_open is None else self.vent_open.copy(),
            None if self.history is None else self.history.copy(),
        )
        object.__setattr__(out, "_version", self.version)
        if "_clock" in self.__dict__:  # the runs' clock origin (see time)
            object.__setattr__(out, "_clock", self.__dict__["_clock"])
        return out

    def __repr__(self) -> str:
        return (
            f"State(particle_count={len(self.particle_q)}, time={self.time:.6g}, "
            f"step_count={self.step_count}, collider_count={len(self.collider_q)})"
        )
