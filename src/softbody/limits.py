"""Size guards: refuse a job whose memory would not fit, before allocating any of it.

A scene key such as ``subdivisions = 1000`` or a 2 GB mesh file must end in a one-line
error that names the key, the memory it would take and the limit, not in a MemoryError
traceback or the kernel's out-of-memory killer. Every guard compares an *estimate*
made from sizes alone (vertex counts, sample counts, file sizes) with
:func:`memory_limit`.

The limit is half of this machine's physical memory (or of its container's memory limit,
when it runs in one with a smaller limit), or the ``SOFTBODY_MEMORY_LIMIT``
environment variable (bytes, or a number with a ``K``, ``M``, ``G`` or ``T`` suffix,
powers of 1024), for a user who knows their machine better.
"""

from __future__ import annotations

import os

import numpy as np

from softbody.errors import SizeLimitError

#: Fraction of physical memory a single job may plan to use.
MEMORY_FRACTION = 0.5
#: Model, simulator and one step's buffers, per particle [bytes]: 2.1 kB measured
#: (tracemalloc, 2,562 to 163,842 vertices, implicit Euler and velocity Verlet alike;
#: ``benchmarks/ball_drop.py``) with headroom for the renderer and the diagnostics.
BYTES_PER_PARTICLE = 3072
#: Bytes per face a mesh takes while it is built and validated (faces, edges, half-edge
#: sorts, adjacency), beyond the per-particle figure.
BYTES_PER_FACE = 512
#: Monte Carlo volume sample lines [bytes each]: two float64 in the builder's list, the
#: Model's concatenated copy and the transient one while concatenating (3 x 16 bytes).
BYTES_PER_MC_SAMPLE = 48
#: Reading a mesh file with trimesh: memory per byte of file. Measured (peak RSS growth
#: of ``trimesh.load(..., process=False)`` in a fresh process, icospheres of 10,242 to
#: 655,362 vertices, 0.4 to 98 MB files, trimesh 5.2): ASCII PLY 17.4-18.1, binary PLY
#: 10.6-11.7, binary STL 9.0-9.5, text OBJ 7.1-10.1, ASCII STL 6.7 (tracemalloc peaks
#: agree within 15%). The worst format, rounded up; a smaller file is refused late, by
#: the vertex and face counts, if its mesh would not fit.
BYTES_PER_FILE_BYTE = 20
#: Largest scene file read [bytes]: a scene is a page of TOML; 64 MB allows very long
#: inline index lists and refuses a file that is not a scene.
MAX_SCENE_FILE_BYTES = 64 * 1024**2

_SUFFIXES = {"": 1, "K": 1024, "M": 1024**2, "G": 1024**3, "T": 1024**4}


def physical_memory() -> int:
    """This machine's physical memory [bytes] (0 when the system does not say)."""
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return 0


#: Files that hold a container's memory limit (cgroup v2, then v1), read by
#: :func:`available_memory`.
CGROUP_LIMIT_FILES = (
    "/sys/fs/cgroup/memory.max",
    "/sys/fs/cgroup/memory/memory.limit_in_bytes",
)


def available_memory() -> int:
    """Physical memory [bytes], or a container's (cgroup) memory limit when that is
    smaller: a job in a 2 GB container on a 24 GB host has 2 GB (0 when unknown)."""
    total = physical_memory()
    for name in CGROUP_LIMIT_FILES:
        try:
            with open(name) as f:  # closed at once: no ResourceWarning in a sweep's rows
                text = f.read().strip()
        except OSError:
            continue
        # v2 writes "max" when there is no limit; v1 a huge number, which min() passes over
        if text.isdigit() and int(text) > 0:
            total = min(total, int(text)) if total > 0 else int(text)
        break
    return total


def memory_limit() -> int:
    """Most memory [bytes] one job may plan to use: ``SOFTBODY_MEMORY_LIMIT`` if set,
    else ``MEMORY_FRACTION`` of :func:`available_memory` (8 GiB when that is unknown)."""
    text = os.environ.get("SOFTBODY_MEMORY_LIMIT", "").strip()
    if text:
        unit = text[-1].upper() if text[-1].isalpha() else ""
        number = text[:-1] if unit else text
        try:
            value = float(number) * _SUFFIXES[unit]
        except (KeyError, ValueError):
            value = -1.0
        if not value > 0 or value == float("inf"):
            raise SizeLimitError(
                f"SOFTBODY_MEMORY_LIMIT must be a positive number of bytes (e.g. 8G), got {text!r}"
            )
        return int(value)
    total = available_memory()
    return int(MEMORY_FRACTION * total) if total > 0 else 8 * 1024**3


def format_bytes(n: float) -> str:
    """``1.5e9`` -> ``'1.4 GiB'``: a size for a message."""
    n = float(n)
    if not np.isfinite(n):
        return "more than any machine has"
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.3g} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


def format_count(n: float) -> str:
    """``40962`` -> ``'40,962'``; past a trillion, ``'1e+300'``."""
    n = float(n)
    return f"{n:,.0f}" if abs(n) < 1e12 else f"{n:.3g}"


def check_memory(key: str, estimate: float, what: str) -> None:
    """Raise :class:`SizeLimitError` when ``estimate`` [bytes] exceeds :func:`memory_limit`.

    ``key`` names what the user set (a scene key such as ``bodies.0.mesh.subdivisions``
    or an argument name), ``what`` the size it implies (``"10,485,762 vertices"``); the
    message gives both, the estimate and the limit.
    """
    limit = memory_limit()
    if not estimate <= limit:  # also refuses NaN
        source = (
            "SOFTBODY_MEMORY_LIMIT"
            if os.environ.get("SOFTBODY_MEMORY_LIMIT", "").strip()
            else "half of this machine's or container's memory; set SOFTBODY_MEMORY_LIMIT "
            "to change it"
        )
        raise SizeLimitError(
            f"{key}: {what} would need about {format_bytes(estimate)} of memory, over the "
            f"limit of {format_bytes(limit)} ({source})"
        )


def check_mesh_size(key: str, vertex_count: float, face_count: float) -> None:
    """Guard a mesh of ``vertex_count`` vertices and ``face_count`` triangles before it is
    made: what it costs to build, validate and simulate (``BYTES_PER_PARTICLE``,
    ``BYTES_PER_FACE``)."""
    estimate = BYTES_PER_PARTICLE * float(vertex_count) + BYTES_PER_FACE * float(face_count)
    check_memory(key, estimate, f"a mesh of {format_count(vertex_count)} vertices")


def check_file_size(key: str, size: int, *, factor: float, maximum: int | None = None) -> None:
    """Guard reading a file of ``size`` bytes that takes ``factor`` bytes of memory per
    byte to parse, and, when given, refuse one larger than ``maximum`` bytes."""
    if maximum is not None and size > maximum:
        raise SizeLimitError(
            f"{key}: the file is {format_bytes(size)}, larger than the "
            f"{format_bytes(maximum)} such a file can reasonably be"
        )
    check_memory(key, factor * size, f"reading a {format_bytes(size)} file")
