"""The closed sets held as integers in the model and the run parameters are named once, in
``core/enums.hpp``; the compiled core exports them (``softbody._core.enums()``).

Reference: each Python IntEnum of the same name (the one users and the builders write)
holds exactly the core's members with the same values, so that a value written in
Python means the same thing in C++; a member added on one side only fails here.
"""

from __future__ import annotations

import pytest

from softbody import _core
from softbody.collision import ColliderKind, SoftContactMode
from softbody.collision.colliders import MotionKind
from softbody.gas import GasLaw
from softbody.integrators import Integrator
from softbody.membrane import MembraneMaterial
from softbody.solvers.base import Status
from softbody.volume import VolumeMethod

PYTHON = {
    "Integrator": Integrator,
    "GasLaw": GasLaw,
    "VolumeMethod": VolumeMethod,
    "ColliderKind": ColliderKind,
    "MotionKind": MotionKind,
    "SoftContactMode": SoftContactMode,
    "MembraneMaterial": MembraneMaterial,
    "Status": Status,
}


def test_every_core_set_has_its_python_enum():
    """The core exports exactly the sets named here."""
    assert set(_core.enums()) == set(PYTHON)


@pytest.mark.parametrize("name", sorted(PYTHON))
def test_python_enum_equals_the_core_set(name):
    """Same member names, same values."""
    assert {m.name: int(m.value) for m in PYTHON[name]} == _core.enums()[name]
