"""A readable NumPy reference for every physics term of the compiled core.

One module per term, mirroring ``core/terms/``: :mod:`~softbody.reference.gravity`,
:mod:`~softbody.reference.springs` (mesh edges, bending and user springs: all rows of the
model's spring arrays), :mod:`~softbody.reference.attachments`,
:mod:`~softbody.reference.external` (``Control.particle_f`` and the grab spring),
:mod:`~softbody.reference.volume`, :mod:`~softbody.reference.gas` and
:mod:`~softbody.reference.drag`; :mod:`~softbody.reference.forces` sums them in the order
of ``core/solvers/explicit.hpp: eval_forces`` and :mod:`~softbody.reference.jacobians`
applies (alpha_m M + alpha_c C + alpha_k K) p as the implicit solvers do;
:mod:`~softbody.reference.steps` takes one backward Euler step (a dense Newton step) and
one projective-dynamics step (dense local-global iterations) on small meshes.

Written for reading, not for speed: plain vectorised NumPy (``np.add.at`` scatters), one
equation per function, no compiled code. Every function takes the model
(:class:`softbody.Model`), positions ``q`` (N, 3) [m], velocities ``qd`` (N, 3) [m/s] and,
where a term reads it, the control as the kernels see it (``ControlData``, from
:func:`control_arrays`). Stiffness K = df/dx and damping C = df/dv follow the core's sign:
both are negative semi-definite for a spring.
"""

from __future__ import annotations

from softbody.reference import (
    attachments,
    drag,
    external,
    forces,
    gas,
    gravity,
    jacobians,
    springs,
    steps,
    volume,
)
from softbody.reference._inputs import control_arrays

__all__ = [
    "attachments",
    "control_arrays",
    "drag",
    "external",
    "forces",
    "gas",
    "gravity",
    "jacobians",
    "springs",
    "steps",
    "volume",
]
