"""Gas laws: what pressure the gas in a body has at a given volume, and its energy.

All quantities are SI: nRT in joules (J = Pa m^3), pressures in pascals, volumes in m^3.

============== =============================== ============================================
law            pressure P(V)                   potential energy E(V), with -dE/dV = P
============== =============================== ============================================
isothermal     P = nRT / V  (paper, eq. 5)     E = -nRT ln V
fixed_pressure P = P0  (a regulated supply)    E = -P0 V
adiabatic      P = nRT V_ref^(g-1) / V^g       E = nRT V_ref^(g-1) V^(1-g) / (g - 1)
============== =============================== ============================================

The adiabatic law keeps P V^gamma constant and is parameterised by nRT at a reference
volume V_ref (default: the body's rest volume), so P(V_ref) = nRT / V_ref as for the
isothermal law. An ambient pressure P_a outside the body adds P_a V to the energy and the
force uses P - P_a. The driving value (nRT, or P0 for fixed pressure) may follow a
piecewise-linear schedule in time or be overridden per step through ``Control``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

#: Molar gas constant R [J / (mol K)].
GAS_CONSTANT = 8.314462618

#: Molar mass of dry air [kg/mol].
AIR_MOLAR_MASS = 0.028965

#: The temperature a gas given by nRT alone is taken to have [K] (20 C).
ROOM_TEMPERATURE = 293.15


class GasLaw(IntEnum):
    """The equation of state of a body's gas."""

    ISOTHERMAL = 0
    FIXED_PRESSURE = 1
    ADIABATIC = 2


def _finite(name: str, value: float, *, minimum: float = 0.0, strict: bool = False) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if value < minimum or (strict and value == minimum):
        raise ValueError(f"{name} must be {'>' if strict else '>='} {minimum}, got {value!r}")
    return value


@dataclass(frozen=True)
class Gas:
    """The gas inside one body. Build it with one of the class methods.

    Attributes
    ----------
    law : GasLaw
    value : float
        The driving quantity: nRT [J] for isothermal and adiabatic gas, the pressure P0 [Pa]
        for fixed pressure.
    gamma : float
        Heat capacity ratio for the adiabatic law (1.4 for air).
    reference_volume : float or None
        Adiabatic only: the volume [m^3] at which P = nRT / V; None means the rest volume.
    ambient_pressure : float
        Pressure outside the body [Pa]; the force uses P - ambient.
    schedule : tuple of (time [s], value) pairs or None
        Piecewise-linear ``value`` over time, held constant before the first and after the
        last point (inflate, deflate, heat). Overrides ``value`` when given.
    temperature : float
        Temperature of the gas at the body's initial positions [K]; with nRT it fixes the
        amount n [mol] that ``State.body_gas_moles`` starts from.
    molar_mass : float
        Molar mass of the gas [kg/mol] (air: 0.028965): what turns a mass flow through a
        vent, an orifice or an inflator into moles.
    ambient_temperature : float
        Temperature of the air outside [K]: what flows in through vents and leaks when the
        outside pressure is higher.
    """

    law: GasLaw
    value: float
    gamma: float = 1.4
    reference_volume: float | None = None
    ambient_pressure: float = 0.0
    schedule: tuple[tuple[float, float], ...] | None = None
    temperature: float = ROOM_TEMPERATURE
    molar_mass: float = AIR_MOLAR_MASS
    ambient_temperature: float = ROOM_TEMPERATURE

    def __post_init__(self):
        object.__setattr__(self, "law", GasLaw(self.law))
        label = "pressure" if self.law == GasLaw.FIXED_PRESSURE else "nRT"
        object.__setattr__(self, "value", _finite(f"gas {label}", self.value))
        object.__setattr__(
            self, "gamma", _finite("gas gamma", self.gamma, minimum=1.0, strict=True)
        )
        if self.reference_volume is not None:
            object.__setattr__(
                self,
                "reference_volume",
                _finite("gas reference_volume", self.reference_volume, strict=True),
            )
        object.__setattr__(
            self, "ambient_pressure", _finite("gas ambient_pressure", self.ambient_pressure)
        )
        for name in ("temperature", "molar_mass", "ambient_temperature"):
            value = _finite(f"gas {name}", getattr(self, name), strict=True)
            object.__setattr__(self, name, value)
        if self.schedule is not None:
            pts = np.asarray(self.schedule, dtype=np.float64)
            if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) == 0:
                raise ValueError("gas schedule must be a non-empty list of (time, value) pairs")
            if not np.all(np.isfinite(pts)):
                raise ValueError("gas schedule holds NaN or infinite numbers")
            if np.any(np.diff(pts[:, 0]) <= 0):
                raise ValueError("gas schedule times must increase strictly")
            if np.any(pts[:, 1] < 0):
                raise ValueError(f"gas schedule {label} values must be >= 0")
            object.__setattr__(self, "schedule", tuple(map(tuple, pts.tolist())))

    @classmethod
    def isothermal(
        cls,
        nrt: float,
        *,
        ambient_pressure: float = 0.0,
        schedule: Sequence[tuple[float, float]] | None = None,
    ) -> Gas:
        """Closed gas at constant temperature: P = nRT / V (the paper's model). nRT in J."""
        return cls(GasLaw.ISOTHERMAL, nrt, ambient_pressure=ambient_pressure, schedule=schedule)

    @classmethod
    def ideal(
        cls,
        moles: float,
        temperature: float,
        *,
        molar_mass: float = AIR_MOLAR_MASS,
        gamma: float = 1.4,
        process: str = "isothermal",
        ambient_pressure: float = 0.0,
        ambient_temperature: float = ROOM_TEMPERATURE,
    ) -> Gas:
        """An ideal gas of ``moles`` [mol] at ``temperature`` [K] (at the body's initial
        positions): P = n R T / V, with the amount and temperature in ``State`` so that
        vents, orifices, inflators and leaks change them.

        ``process="isothermal"`` keeps T (heat exchange with the surroundings is fast);
        ``"adiabatic"`` exchanges no heat: P V^gamma is constant while no gas flows, and
        the first law of the open system, d(n c_v T) = enthalpy in - enthalpy out - P dV,
        sets T when it does. ``molar_mass`` [kg/mol] and ``gamma`` (c_p / c_v) name the
        species (air: 0.028965, 1.4); ``ambient_temperature`` [K] is the outside air's.
        """
        n = _finite("gas moles", moles)
        temp = _finite("gas temperature", temperature, strict=True)
        if process not in ("isothermal", "adiabatic"):
            raise ValueError(f"gas process must be 'isothermal' or 'adiabatic', got {process!r}")
        law = GasLaw.ISOTHERMAL if process == "isothermal" else GasLaw.ADIABATIC
        return cls(
            law,
            n * GAS_CONSTANT * temp,
            gamma=gamma,
            ambient_pressure=ambient_pressure,
            temperature=temp,
            molar_mass=molar_mass,
            ambient_temperature=ambient_temperature,
        )

    @classmethod
    def fixed_pressure(
        cls,
        pressure: float,
        *,
        ambient_pressure: float = 0.0,
        schedule: Sequence[tuple[float, float]] | None = None,
    ) -> Gas:
        """Gas held at pressure P0 [Pa] whatever the volume (a body on a regulator)."""
        return cls(
            GasLaw.FIXED_PRESSURE, pressure, ambient_pressure=ambient_pressure, schedule=schedule
        )

    @classmethod
    def adiabatic(
        cls,
        nrt: float,
        *,
        gamma: float = 1.4,
        reference_volume: float | None = None,
        ambient_pressure: float = 0.0,
        schedule: Sequence[tuple[float, float]] | None = None,
    ) -> Gas:
        """Gas compressed without heat exchange: P V^gamma constant, P(V_ref) = nRT / V_ref."""
        return cls(
            GasLaw.ADIABATIC,
            nrt,
            gamma=gamma,
            reference_volume=reference_volume,
            ambient_pressure=ambient_pressure,
            schedule=schedule,
        )
