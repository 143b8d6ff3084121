"""The compiled engine core (``softbody._core``, C++17): which instruction set it uses,
and the views of a :class:`Model` its solvers step.

The kernels are compiled when the package is installed, once for each instruction set the
build knows (AVX-512, AVX2 and a scalar path on x86-64; the scalar path elsewhere); the
best one the CPU runs is chosen at import. ``SOFTBODY_SIMD=scalar|avx2|avx512`` (or
:func:`use_simd`) forces one, to compare them: every path gives the same results to
round-off.
"""

from __future__ import annotations

import functools
import os
import warnings
import weakref

from softbody import _core

__all__ = ["available_threads", "simd_path", "simd_paths", "terms", "use_simd"]

_MODELS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def simd_paths() -> list[str]:
    """The instruction sets this build has and this CPU runs, best last
    (``["scalar", "avx2", "avx512"]`` on a recent x86-64)."""
    return list(_core.simd_paths())


def simd_path() -> str:
    """The instruction set the kernels use now."""
    return str(_core.simd_path())


def use_simd(name: str) -> None:
    """Run the kernels with instruction set ``name`` (``"scalar"``, ``"avx2"``,
    ``"avx512"``, or ``"auto"`` for the best available); a ``ValueError`` names the
    available ones when this build or CPU lacks it."""
    key = str(name).strip().lower()
    if not _core.select_simd(key):
        raise ValueError(
            f"instruction set {name!r} is not available here; choose one of: "
            + ", ".join([*simd_paths(), "auto"])
        )


def terms() -> list[dict]:
    """The physics terms registered in the core (``core/terms/registry.hpp``), in the order
    their forces, Jacobian products and energies are summed: one dict each with its
    ``name`` and traits, ``lane`` (the vertex-major pass gives its force), ``projected``
    (projective dynamics solves it by its projection), ``fused`` (the fused symplectic
    Euler pass covers it), ``energy`` (it has one), ``external`` (its energy is work
    done from outside the model, such as the grab spring's), ``flow`` (it moves gas
    between bodies and the air: vents, orifices, inflators, leaks) and ``bound`` (its own
    part of the stability estimate, ``softbody.stability``)."""
    return [dict(t) for t in _term_table()]


@functools.cache
def _term_table() -> tuple:
    """The registry as the core reports it (fixed for a build: read once)."""
    return tuple(_core.term_table())


def available_threads() -> int:
    """CPU cores this process may run on: the most ``threads`` a Simulator takes."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def core_model(model):
    """The compiled core's checked view of ``model`` (built once per model)."""
    view = _MODELS.get(model)
    if view is None:
        view = _MODELS[model] = _core.Model(model)
    return view


def _from_environment() -> None:
    name = os.environ.get("SOFTBODY_SIMD", "").strip().lower()
    if name and name != "auto":
        try:
            use_simd(name)
        except ValueError as error:
            warnings.warn(f"SOFTBODY_SIMD: {error}; using {simd_path()}", stacklevel=3)


_from_environment()
