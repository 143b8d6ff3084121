"""Reading and writing mesh files through trimesh (OBJ, PLY, STL, OFF, GLB/GLTF)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from softbody import limits
from softbody.errors import MeshError
from softbody.mesh.tri_mesh import TriMesh
from softbody.mesh.validate import validate_mesh

#: File suffixes :func:`load_mesh` reads.
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")


def file_problem(path: str | os.PathLike) -> str | None:
    """Why ``path`` cannot be read as a file: ``"no such file"``, ``"is a directory, not
    a file"``, ``"not a regular file (a FIFO)"`` (or a socket, a device); None for a
    regular file (a link is followed). Nothing is opened, so a FIFO never blocks."""
    import stat

    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return "no such file"
    except OSError as exc:
        return f"cannot read it ({exc.strerror or exc})"
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "is a directory, not a file"
    kinds = {
        stat.S_ISFIFO: "a FIFO",
        stat.S_ISSOCK: "a socket",
        stat.S_ISCHR: "a character device",
        stat.S_ISBLK: "a block device",
    }
    kind = next((name for test, name in kinds.items() if test(mode)), "not a file")
    return f"not a regular file ({kind})"


def read_mesh(path: str | os.PathLike) -> TriMesh:
    """Read a triangle mesh file as stored, without validation or repair.

    Multi-object files (a GLB scene, an OBJ with several groups) are merged into one mesh
    with their transforms applied. Polygons are triangulated by trimesh.

    A file too large to parse within :func:`softbody.limits.memory_limit` is refused before
    it is read (``limits.BYTES_PER_FILE_BYTE`` bytes of memory per byte of file), and a
    parsed mesh too large to build and simulate is refused by its vertex and face counts,
    both with a :class:`~softbody.errors.SizeLimitError`. Every other problem (empty,
    unreadable, malformed, NaN coordinates, bad indices) is a :class:`MeshError` whose
    message starts with the file's path.
    """
    import trimesh

    p = Path(path)
    problem = file_problem(p)
    if problem is not None:
        raise MeshError(f"{p}: {problem}")
    if p.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(
            f"{p}: unsupported mesh format {p.suffix!r}; use one of {', '.join(MESH_SUFFIXES)}"
        )
    try:
        size = p.stat().st_size
    except OSError as exc:
        raise MeshError(f"{p}: could not read mesh ({exc.strerror or exc})") from exc
    if size == 0:
        raise MeshError(f"{p}: the file is empty")
    limits.check_file_size(str(p), size, factor=limits.BYTES_PER_FILE_BYTE)
    try:
        loaded = trimesh.load(str(p), force="mesh", process=False)
    except MemoryError:
        raise MeshError(
            f"{p}: ran out of memory reading a {limits.format_bytes(size)} file"
        ) from None
    except Exception as exc:  # trimesh raises many types for bad files
        reason = str(exc) or type(exc).__name__
        raise MeshError(f"{p}: could not read mesh ({reason})") from exc
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))))
    if faces.size == 0:
        raise MeshError(f"{p}: file holds no triangles")
    vertices = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))))
    limits.check_mesh_size(str(p), len(vertices), len(faces))
    try:
        return TriMesh(vertices, faces)
    except MeshError as exc:  # NaN coordinates, indices out of range: name the file
        raise MeshError(f"{p}: {exc}") from None


def load_mesh(path: str | os.PathLike, *, validate: bool = True) -> TriMesh:
    """Read a mesh file and make sure it can hold gas.

    With ``validate=True`` (default) the mesh goes through
    :func:`softbody.validate_mesh`: duplicate seam vertices are welded, an inward-wound
    mesh is flipped (with a warning), and an open, non-manifold or degenerate mesh raises
    :class:`MeshError` naming the problem and its count.
    """
    mesh = read_mesh(path)
    return validate_mesh(mesh, name=str(path)) if validate else mesh


def save_mesh(mesh: TriMesh, path: str | os.PathLike) -> Path:
    """Write ``mesh`` to ``path`` (format from the suffix), whole or not at all.

    The file is written to a temporary name beside the target and renamed into place,
    so a failed write never leaves a truncated file.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise ValueError(f"unsupported mesh format {p.suffix!r}; use one of {MESH_SUFFIXES}")
    data = mesh.to_trimesh().export(file_type=suffix[1:])
    if isinstance(data, str):
        data = data.encode()
    fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p
