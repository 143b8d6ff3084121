"""A readable NumPy reference for every physics term of the compiled core.

One module per term, mirroring ``core/terms/`` (each module's ``TERMS`` maps the names it
serves in the core's registry to their force), with :mod:`~softbody.reference.volume`
for the volumes; :mod:`~softbody.reference.forces` sums every registered term in the
registry's order and :mod:`~softbody.reference.jacobians`
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

import importlib
import pkgutil

from softbody.reference._inputs import control_arrays

# every module of the package (one per term, and the compositions)
_MODULES = sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))
for _name in _MODULES:
    globals()[_name] = importlib.import_module(f"softbody.reference.{_name}")

__all__ = ["control_arrays", *_MODULES]
