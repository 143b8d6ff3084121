"""Time integrators: explicit Euler, Midpoint (RK2), RK4, symplectic Euler, velocity Verlet,
implicit (backward) Euler and BDF2, projective dynamics (backward Euler by
local-global iterations), and XPBD with small steps (substeps of one constraint pass)."""

from __future__ import annotations

from enum import IntEnum

import numpy as np


class Integrator(IntEnum):
    """Time-stepping schemes; ``order`` and ``force_evaluations`` describe each."""

    EULER = 0
    MIDPOINT = 1
    RK4 = 2
    SYMPLECTIC_EULER = 3
    VELOCITY_VERLET = 4
    IMPLICIT_EULER = 5
    BDF2 = 6
    PROJECTIVE = 7
    XPBD = 8

    @property
    def order(self) -> int:
        """Global order of accuracy for smooth problems."""
        return {0: 1, 1: 2, 2: 4, 3: 1, 4: 2, 5: 1, 6: 2, 7: 1, 8: 1}[int(self)]

    @property
    def force_evaluations(self) -> int:
        """Force evaluations per step (the implicit schemes add their CG iterations;
        projective dynamics evaluates the non-spring forces once per iteration, XPBD the
        unconstrained forces once per substep)."""
        return {0: 1, 1: 2, 2: 4, 3: 1, 4: 2, 5: 1, 6: 1, 7: 1, 8: 1}[int(self)]

    @property
    def implicit(self) -> bool:
        """True for schemes that solve a linear system each step (unconditionally stable)."""
        return self in (Integrator.IMPLICIT_EULER, Integrator.BDF2)

    @property
    def explicit(self) -> bool:
        """True for the explicit schemes, whose stable step the springs limit (the
        spectral stability estimate is worth its Lanczos runs only for them)."""
        return int(self) <= int(Integrator.VELOCITY_VERLET)

    @property
    def symplectic(self) -> bool:
        """True for schemes that conserve a modified energy (no secular drift)."""
        return self in (Integrator.SYMPLECTIC_EULER, Integrator.VELOCITY_VERLET)

    @classmethod
    def parse(cls, value: str | int | Integrator) -> Integrator:
        """Accept an enum, its int value or its lowercase name (``"rk4"``, ``"midpoint"``)."""
        if isinstance(value, cls):
            return value
        if isinstance(value, str):
            key = value.strip().lower().replace("-", "_")
            aliases = {
                "rk2": "midpoint",
                "verlet": "velocity_verlet",
                "semi_implicit_euler": "symplectic_euler",
                "explicit_euler": "euler",
                "implicit": "implicit_euler",
                "backward_euler": "implicit_euler",
                "implicit_bdf2": "bdf2",
                "pd": "projective",
                "projective_dynamics": "projective",
                "substep": "xpbd",
            }
            key = aliases.get(key, key)
            for member in cls:
                if member.name.lower() == key:
                    return member
        elif isinstance(value, int | np.integer) and int(value) in {m.value for m in cls}:
            return cls(int(value))
        names = ", ".join(m.name.lower() for m in cls)
        raise ValueError(f"unknown integrator {value!r}; choose one of: {names}")


__all__ = ["Integrator"]
