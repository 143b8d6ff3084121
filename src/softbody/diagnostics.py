"""Per-body measurements and energies of a state, for plots, summaries and tests."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from softbody import _core
from softbody.core import core_model, terms
from softbody.gas import GAS_CONSTANT, GasLaw
from softbody.mesh import TriMesh
from softbody.reference import gas as ref_gas
from softbody.sim.control import Control, control_data
from softbody.sim.model import Model
from softbody.sim.state import State, kernel_input


def _control(model: Model, state: State, control: Control | None):
    """The kernel arrays of ``control``; without one, neutral inputs but for the gas values
    the state's last step applied (``state.body_gas_override``), so that a readback
    reports what a :class:`Control` set, not the model's value. Where neither prescribes
    a body's gas, its value is the state's: nRT = R n T at the state's amount and
    temperature (``state.body_gas_moles``, ``body_gas_temperature``; an adiabatic gas's
    taken to its reference volume along its isentrope). ``state`` is conformed."""
    state.conform(model)
    if control is not None:
        data = control.write(model, control_data(model))
    else:
        data = control_data(model)
        np.copyto(data.gas_override, state.body_gas_override)
    ranges = np.asarray(model.body_schedule_range)
    law = np.asarray(model.body_gas_law)
    fill = (
        ~np.isfinite(data.gas_override)
        & (law != GasLaw.FIXED_PRESSURE)
        & (ranges[:, 1] == ranges[:, 0])
        & (np.asarray(model.body_closed) == 1)
    )
    if fill.any():
        temperature = np.array(state.body_gas_temperature, dtype=np.float64)
        adiabatic = law == GasLaw.ADIABATIC
        if np.any(fill & adiabatic):
            volume = _core.eval_volumes(
                core_model(model), data, float(state.time), state.particle_q
            )[0]
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = (volume / model.body_gas_reference_volume) ** (model.body_gas_gamma - 1)
            temperature = np.where(adiabatic, temperature * ratio, temperature)
        value = GAS_CONSTANT * state.body_gas_moles * temperature
        data.gas_override[fill] = value[fill]
    return data


def _gas(model: Model, state: State, control: Control | None = None):
    """(volume (B,) [m^3], pressure (B,) [Pa], dV/dx (N, 3) [m^2]) of every body at
    ``state``, each body's volume by its own method."""
    state.conform(model)
    return _core.eval_volumes(
        core_model(model), _control(model, state, control), float(state.time), state.particle_q
    )


def active_terms(model: Model, control: Control | None = None) -> list[str]:
    """Names of the registered terms (:func:`softbody.core.terms`) that act in ``model``
    under ``control`` (default: the model's own), in registry order: a term acts when its
    data and the control give it something to do (``"attachments"`` only with
    attachments, ``"grab"`` only with a grabbed particle, the air on faces only with air
    of density > 0 and a body's coefficient > 0)."""
    data = control_data(model) if control is None else control.write(model, control_data(model))
    return [str(name) for name in _core.active_terms(core_model(model), data)]


def body_volume_by(model: Model, state: State, method: str) -> np.ndarray:
    """Volume of every body by one given method (``"exact"``, ``"bounding_box"``, ...)
    whatever method it simulates with [m^3], shape (B,): to compare the paper's bounding
    objects with the exact volume (Figure 5)."""
    from softbody.volume import VolumeMethod

    chosen = np.full(model.body_count, int(VolumeMethod.parse(method)), dtype=np.int64)
    samples = model.mc_samples
    mc_range = model.body_mc_range
    if chosen[0] == VolumeMethod.MONTE_CARLO and len(samples) == 0:
        samples = np.random.default_rng(0).random((4096, 2))
        mc_range = np.tile([0, 4096], (model.body_count, 1))
    state.conform(model)
    return _core.body_volumes(
        state.particle_q,
        model.tri_indices,
        model.body_particle_range,
        model.body_tri_range,
        kernel_input(chosen, np.int64),
        kernel_input(mc_range, np.int64),
        kernel_input(samples),
    )


def body_volume(model: Model, state: State) -> np.ndarray:
    """Volume of each body by its own volume method [m^3], shape (B,); NaN for open
    surfaces (cloth)."""
    v = _gas(model, state)[0]
    v[model.body_closed == 0] = np.nan
    return v


def body_pressure(model: Model, state: State, control: Control | None = None) -> np.ndarray:
    """Absolute gas pressure of each body at ``state.time`` [Pa], shape (B,).

    The gas values are ``control``'s where it sets them; without a control, those the
    state's last step applied (a :class:`Control`'s nRT or pressure, recorded in
    ``state.body_gas_override``), else the model's value or schedule.
    """
    return _gas(model, state, control)[1]


def body_gas_value(model: Model, state: State, control: Control | None = None) -> np.ndarray:
    """Driving gas value of each body at ``state.time``: nRT [J], or P0 [Pa] for fixed
    pressure, shape (B,): the control's override where finite (without a control, the
    one the state's last step applied), else the body's piecewise-linear schedule (held
    before the first and after the last point), else the model's value."""
    state.conform(model)
    return ref_gas.driving_values(model, _control(model, state, control), float(state.time))


def body_mesh(model: Model, state: State, body: int) -> TriMesh:
    """Body ``body``'s surface at ``state``, deformed, as a :class:`~softbody.TriMesh`.

    Its vertices (V, 3) [m] are the body's particles in order (vertex k is particle
    ``model.body_particle_range[body][0] + k``: the mesh given to
    :meth:`~softbody.ModelBuilder.add_soft_body` after validation, which may weld
    duplicate vertices) and its faces (F, 3) the body's triangles, outward-wound, as
    indices into them. ``mesh.to_trimesh()`` gives a :class:`trimesh.Trimesh`;
    :func:`softbody.save_mesh` writes it to a file.
    """
    if isinstance(body, bool) or not isinstance(body, int | np.integer):
        raise TypeError(f"body must be an integer body index, got {body!r}")
    if not 0 <= body < model.body_count:
        raise ValueError(f"body must lie in [0, {model.body_count - 1}], got {body}")
    state.conform(model)
    p0, p1 = (int(i) for i in model.body_particle_range[body])
    t0, t1 = (int(i) for i in model.body_tri_range[body])
    return TriMesh(state.particle_q[p0:p1], model.tri_indices[t0:t1] - p0)


@dataclass(frozen=True)
class GasFlows:
    """The gas flowing into and out of each body at one state, by the laws of its vents,
    orifices, inflators and leaks (``core/terms/flows.hpp``; the step limiter, which acts
    only within a step too long for a flow, left out). Shapes (B,)."""

    inflow: np.ndarray
    """Molar flow into each body [mol/s]."""
    outflow: np.ndarray
    """Molar flow out of each body [mol/s]."""
    inflow_temperature: np.ndarray
    """Mean temperature of the gas flowing in [K] (NaN where none flows in)."""
    mass_inflow: np.ndarray
    """Mass flow into each body [kg/s] (its gas's molar mass times ``inflow``)."""
    mass_outflow: np.ndarray
    """Mass flow out of each body [kg/s]."""

    @property
    def net(self) -> np.ndarray:
        """dn/dt [mol/s] of each body's gas: inflow - outflow."""
        return self.inflow - self.outflow


def body_gas_flows(model: Model, state: State, control: Control | None = None) -> GasFlows:
    """The gas flows of every body at ``state`` (its positions, gas amounts, temperatures
    and vent latches) under ``control`` (valve areas, inflator flows; default: none).
    An orifice's flow appears as the outflow of its high-pressure body and the inflow of
    the other."""
    state.conform(model)
    if control is not None:
        data = control.write(model, control_data(model))
    else:  # the state's gas drives every body the last step did not prescribe
        data = control_data(model)
        np.copyto(data.gas_override, state.body_gas_override)
    inflow, inflow_t, outflow = _core.eval_flows(
        core_model(model), data, float(state.time), state.particle_q, state.body_gas_moles,
        state.body_gas_temperature, state.vent_open,
    )  # fmt: skip
    molar_mass = np.asarray(model.body_gas_molar_mass)
    with np.errstate(divide="ignore", invalid="ignore"):
        temperature = np.where(inflow > 0, inflow_t / inflow, np.nan)
    return GasFlows(
        inflow=inflow,
        outflow=outflow,
        inflow_temperature=temperature,
        mass_inflow=inflow * molar_mass,
        mass_outflow=outflow * molar_mass,
    )


def gas_state_bodies(model: Model) -> np.ndarray:
    """Which bodies hold a gas whose amount [mol] and temperature [K] are state (a closed
    body with an isothermal or adiabatic gas, not a fixed pressure), shape (B,) bool."""
    law = np.asarray(model.body_gas_law)
    return (np.asarray(model.body_closed) == 1) & (law != GasLaw.FIXED_PRESSURE)


def has_gas_flows(model: Model) -> bool:
    """Whether a term that moves gas acts in ``model`` (a vent, an orifice, an inflator or
    a leak: the registered terms with the ``flow`` trait, :func:`softbody.core.terms`)."""
    flows = {t["name"] for t in terms() if t["flow"]}
    return any(name in flows for name in active_terms(model))


def body_area(model: Model, state: State) -> np.ndarray:
    """Surface area of each body [m^2], shape (B,)."""
    x = state.particle_q[model.tri_indices]
    areas = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)
    return np.array([areas[t0:t1].sum() for t0, t1 in model.body_tri_range])


def body_centroid(model: Model, state: State) -> np.ndarray:
    """Centroid of the region each body encloses [m], shape (B, 3).

    Exact for the polyhedron: the volume-weighted mean of the tetrahedra
    (c, a, b, d) over faces, with c the vertex centroid.
    """
    q = state.particle_q
    out = np.zeros((model.body_count, 3))
    for b, (t0, t1) in enumerate(model.body_tri_range):
        tri = model.tri_indices[t0:t1]
        p0, p1 = model.body_particle_range[b]
        c = q[p0:p1].mean(axis=0)
        a, bb, d = q[tri[:, 0]] - c, q[tri[:, 1]] - c, q[tri[:, 2]] - c
        vol = np.einsum("ij,ij->i", a, np.cross(bb, d)) / 6.0
        out[b] = c + (vol[:, None] * (a + bb + d) / 4.0).sum(axis=0) / vol.sum()
    return out


def body_center_of_mass(model: Model, state: State) -> np.ndarray:
    """Mass-weighted mean position of each body's particles [m], shape (B, 3)."""
    q, m = state.particle_q, model.particle_mass
    return np.array(
        [
            (m[p0:p1, None] * q[p0:p1]).sum(axis=0) / m[p0:p1].sum()
            for p0, p1 in model.body_particle_range
        ]
    ).reshape(-1, 3)


@dataclass(frozen=True)
class Energies:
    """Energies of a state [J]. Totals cover the whole model (free particles included);
    ``body_*`` arrays (B,) split them by body.

    ``terms`` holds every registered term's energy (``softbody.core.terms()``, those with
    one), ``body_terms`` its split by body. ``gravitational`` is the weight's, ``gas`` the
    gas law's potential (``softbody.gas``), evaluated at each body's volume by its own
    method (0 for open surfaces, whose wind pressure does uncounted work), and ``spring``
    every other term's elastic energy (springs, attachments, and any term added since),
    work done from outside the model (the grab spring) left out. With the exact volume the
    pressure force is minus its gradient, so kinetic + gravitational + spring + gas is
    conserved without damping and with constant nRT; with a bounding volume that sum is not
    conserved (the paper's approximation).
    """

    kinetic: float
    gravitational: float
    spring: float
    gas: float
    body_kinetic: np.ndarray
    body_gravitational: np.ndarray
    body_spring: np.ndarray
    body_gas: np.ndarray
    terms: dict[str, float]
    body_terms: dict[str, np.ndarray]

    @property
    def total(self) -> float:
        """kinetic + gravitational + spring + gas [J]."""
        return self.kinetic + self.gravitational + self.spring + self.gas


def energies(model: Model, state: State, control: Control | None = None) -> Energies:
    """Kinetic energy and every registered term's energy at ``state``.

    ``control`` supplies gas overrides and attachment anchors when they differ from the
    model's; without one, the gas values are those the state's last step applied
    (``state.body_gas_override``) and the anchors the model's. Each term's energy comes
    from its own file of the compiled core (``core/terms/``; ``softbody.reference`` holds
    the same formulas in NumPy). Dissipative and given forces (air on faces, the control's
    forces) have none; the grab spring's is reported in ``terms`` but left out of the
    total (the user's hand does work).
    """
    state.conform(model)
    q, qd = state.particle_q, state.particle_qd
    m = model.particle_mass
    bodies = model.body_count
    pb = model.particle_body

    kin = 0.5 * m * np.einsum("ij,ij->i", qd, qd)
    # each body's gas energy at its volume by its own method; an open surface (cloth)
    # holds no gas: the work of its wind pressure is not counted
    values = _core.eval_energies(
        core_model(model), _control(model, state, control), float(state.time), q
    )
    internal = [t["name"] for t in terms() if t["energy"] and not t["external"]]
    elastic = [name for name in internal if name not in ("gravity", "gas")]
    return Energies(
        kinetic=float(kin.sum()),
        gravitational=values["gravity"][0],
        spring=float(sum(values[name][0] for name in elastic)),
        gas=values["gas"][0],
        body_kinetic=np.bincount(pb[pb >= 0], weights=kin[pb >= 0], minlength=bodies),
        body_gravitational=values["gravity"][1],
        body_spring=sum((values[name][1] for name in elastic), np.zeros(bodies)),
        body_gas=values["gas"][1],
        terms={name: float(v[0]) for name, v in values.items() if name != "volume"},
        body_terms={name: v[1] for name, v in values.items() if name != "volume"},
    )
