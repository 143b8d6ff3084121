"""Per-step inputs: gas amount, external forces, kinematic targets."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from softbody.gas import GasLaw

if TYPE_CHECKING:
    from softbody.sim.model import Model


class ControlData(NamedTuple):
    """The control arrays the compiled kernels read."""

    gas_override: np.ndarray  # (B,) driving gas value, NaN = the model's value or schedule
    particle_f: np.ndarray  # (N, 3) external forces [N]
    attachment_anchor: np.ndarray  # (A, 3) anchor points [m]
    pin_target: np.ndarray  # (P, 3) pinned-particle targets at the end of the call [m]
    pin_active: bool  # whether pin_target is used
    collider_target: np.ndarray  # (C, 3) collider centre targets [m], NaN = prescribed motion
    grab_particle: int  # particle pulled by the grab spring, -1 for none
    grab_target: np.ndarray  # (3,) where the grab spring pulls it [m]
    grab_stiffness: float  # [N/m]
    grab_damping: float  # [N s/m]
    wind: np.ndarray  # (3,) air velocity [m/s] of this call
    vent_area: np.ndarray  # (V,) open area of each vent [m^2], NaN = the model's
    orifice_area: np.ndarray  # (O,) open area of each orifice [m^2], NaN = the model's
    inflator_mass_flow: np.ndarray  # (I,) [kg/s], NaN = the inflator's table


@dataclass(eq=False)
class Control:
    """Inputs for one call of ``Simulator.step`` (held constant over the call).

    Make one with ``model.control()`` and change what you need. NaN in a gas array means
    "use the model's value (or its schedule)".
    """

    body_gas_nrt: np.ndarray
    """nRT [J] of isothermal and adiabatic bodies, shape (B,); NaN keeps the model's."""
    body_gas_pressure: np.ndarray
    """Pressure P0 [Pa] of fixed-pressure bodies, shape (B,); NaN keeps the model's."""
    particle_f: np.ndarray
    """External force on each particle [N], shape (N, 3)."""
    attachment_anchor: np.ndarray
    """Anchor point of each attachment spring [m], shape (A, 3)."""
    pin_target: np.ndarray | None = None
    """Where each pinned particle (``model.pin_particle`` order) should be at the end of
    the call [m], shape (P, 3); it moves there at constant velocity. None leaves pins
    moving with their current velocity (at rest unless set)."""
    collider_target: np.ndarray | None = None
    """Where each collider's centre should be at the end of the call [m], shape (C, 3);
    it moves there in a straight line at constant velocity (a ball driven by the user).
    NaN rows (and None) follow the collider's prescribed motion."""
    grab_particle: int = -1
    """A particle pulled toward ``grab_target`` by a damped spring in every force
    evaluation (a mouse grab); -1 for none."""
    grab_target: np.ndarray | None = None
    """Where the grab spring pulls [m], shape (3,)."""
    grab_stiffness: float = 0.0
    """Grab spring stiffness [N/m]."""
    grab_damping: float = 0.0
    """Grab spring damping [N s/m] (on the particle's absolute velocity)."""
    wind: np.ndarray | None = None
    """Air velocity [m/s], shape (3,), for this call (a gust); None keeps the model's
    ``wind``."""
    vent_area: np.ndarray | None = None
    """Open area of each vent [m^2] for this call (a valve), shape (V,); NaN entries (and
    None) keep the vent's own area. A vent still opens only at its pressure or time."""
    orifice_area: np.ndarray | None = None
    """Open area of each orifice between two bodies [m^2], shape (O,); NaN (and None) keep
    the orifice's own; 0 closes it."""
    inflator_mass_flow: np.ndarray | None = None
    """Mass flow of each inflator [kg/s] for this call, shape (I,); NaN (and None) follow
    the inflator's table."""

    @classmethod
    def neutral(cls, model: Model) -> Control:
        """Inputs that change nothing about ``model``."""
        b = model.body_count
        return cls(
            body_gas_nrt=np.full(b, np.nan),
            body_gas_pressure=np.full(b, np.nan),
            particle_f=np.zeros((model.particle_count, 3)),
            attachment_anchor=model.attachment_anchor.copy(),
        )

    def write(self, model: Model, out: ControlData) -> ControlData:
        """Check this control against ``model`` and copy it into the kernel arrays ``out``."""
        b = model.body_count

        def arr(name, value, shape):
            a = np.asarray(value, dtype=np.float64)
            if a.shape != shape:
                raise ValueError(f"Control.{name} must have shape {shape}, got {a.shape}")
            return a

        nrt = arr("body_gas_nrt", self.body_gas_nrt, (b,))
        pressure = arr("body_gas_pressure", self.body_gas_pressure, (b,))
        fixed = model.body_gas_law == GasLaw.FIXED_PRESSURE
        for name, values, wrong in (
            ("body_gas_nrt", nrt, fixed),
            ("body_gas_pressure", pressure, ~fixed),
        ):
            if np.any(np.isinf(values)) or np.any(values < 0):
                raise ValueError(f"Control.{name} must be >= 0 and finite (NaN = unchanged)")
            if np.any(np.isfinite(values) & wrong):
                kind = "fixed-pressure" if name == "body_gas_nrt" else "isothermal/adiabatic"
                bodies = np.flatnonzero(np.isfinite(values) & wrong).tolist()
                raise ValueError(f"Control.{name} set for {kind} bodies {bodies}")
        np.copyto(out.gas_override, np.where(fixed, pressure, nrt))
        for name, value, target in (
            ("particle_f", self.particle_f, out.particle_f),
            ("attachment_anchor", self.attachment_anchor, out.attachment_anchor),
        ):
            a = arr(name, value, target.shape)
            if not np.all(np.isfinite(a)):
                raise ValueError(f"Control.{name} holds NaN or infinite values")
            np.copyto(target, a)
        active = self.pin_target is not None
        if active:
            a = arr("pin_target", self.pin_target, out.pin_target.shape)
            if not np.all(np.isfinite(a)):
                raise ValueError("Control.pin_target holds NaN or infinite values")
            np.copyto(out.pin_target, a)
        if self.collider_target is None:
            out.collider_target[:] = np.nan
        else:
            a = arr("collider_target", self.collider_target, out.collider_target.shape)
            if np.any(np.isinf(a)):
                raise ValueError("Control.collider_target holds infinite values")
            np.copyto(out.collider_target, a)
        grab = int(self.grab_particle)
        if grab >= model.particle_count or grab < -1:
            raise ValueError(f"Control.grab_particle must be -1 or a particle index, got {grab}")
        if grab >= 0:
            target = arr("grab_target", self.grab_target, (3,))
            if not np.all(np.isfinite(target)):
                raise ValueError("Control.grab_target must be finite")
            np.copyto(out.grab_target, target)
            for name in ("grab_stiffness", "grab_damping"):
                v = float(getattr(self, name))
                if not (np.isfinite(v) and v >= 0):
                    raise ValueError(f"Control.{name} must be finite and >= 0")
        if self.wind is None:
            np.copyto(out.wind, model.wind)
        else:
            wind = arr("wind", self.wind, (3,))
            if not np.all(np.isfinite(wind)):
                raise ValueError("Control.wind must be 3 finite numbers [m/s] (None = the model's)")
            np.copyto(out.wind, wind)
        for name, value, target in (
            ("vent_area", self.vent_area, out.vent_area),
            ("orifice_area", self.orifice_area, out.orifice_area),
            ("inflator_mass_flow", self.inflator_mass_flow, out.inflator_mass_flow),
        ):
            if value is None:
                target[:] = np.nan
                continue
            a = arr(name, value, target.shape)
            if np.any(np.isinf(a)) or np.any(a < 0):
                raise ValueError(f"Control.{name} must be >= 0 and finite (NaN = unchanged)")
            np.copyto(target, a)
        return out._replace(
            pin_active=active,
            grab_particle=grab,
            grab_stiffness=float(self.grab_stiffness),
            grab_damping=float(self.grab_damping),
        )


def control_data(model: Model) -> ControlData:
    """Fresh kernel control arrays for ``model`` holding neutral inputs."""
    return ControlData(
        gas_override=np.full(model.body_count, np.nan),
        particle_f=np.zeros((model.particle_count, 3)),
        attachment_anchor=model.attachment_anchor.copy(),
        pin_target=model.particle_q[model.pin_particle].copy(),
        pin_active=False,
        collider_target=np.full((model.collider_count, 3), np.nan),
        grab_particle=-1,
        grab_target=np.zeros(3),
        grab_stiffness=0.0,
        grab_damping=0.0,
        wind=np.array(model.wind, dtype=np.float64),
        vent_area=np.full(len(model.vent_body), np.nan),
        orifice_area=np.full(len(model.orifice_bodies), np.nan),
        inflator_mass_flow=np.full(len(model.inflator_body), np.nan),
    )
