"""USD export: the bodies as time-sampled meshes and the colliders as shapes, a cache that
Blender, Houdini and Maya import. Needs the optional ``usd`` extra (usd-core).

Layout of the stage (Y up, one unit is one metre, ``timeCodesPerSecond`` = frames per
simulated second, frame k at time code ``start_frame + k``)::

    /softbody                    Xform, the default prim
        /<body name>             Mesh: one per body, its triangles, and per time code
                                 points [m], normals (per vertex, unit, outward),
                                 velocities [m/s] and extent [m]
        /colliders
            /ground_<c>          Mesh: a square of side ``ground_size`` in the plane
            /box_<c>             Cube of size 2 scaled by the half-extents (a solid box)
            /container_<c>       the same for a box that holds the bodies, 15% opaque
            /sphere_<c>          Sphere of the collider's radius
            /mesh_<c>            Mesh: a mesh collider's triangles in its local frame

Colliders are placed by ``xformOp:translate`` (the collider's centre) and
``xformOp:orient`` (its rotation, a quaternion); a collider that moves has them sampled at
every time code, a still one holds one value.

**The input mesh's vertices.** A body's mesh was welded when it was added (duplicate seam
vertices merged, see :func:`softbody.validate_mesh`), so its points can be fewer than the
vertices of the file it came from. Two integer primvars map the points back:

``primvars:softbody:sourceVertex`` (vertex interpolation)
    for each point, the index of the input mesh's vertex whose position it starts at (the
    first of the vertices welded into it);
``primvars:softbody:sourceCornerVertex`` (faceVarying interpolation)
    for each corner of each triangle (in ``faceVertexIndices`` order), the input mesh's
    vertex at that corner; seam duplicates stay apart here, so input UVs ``uv`` (one per
    input vertex) become the face-varying primvar ``uv[sourceCornerVertex]``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from softbody.collision.colliders import ColliderKind
from softbody.collision.mesh_collider import collider_mesh
from softbody.sim.model import Model

#: Opacity of a container box (the bodies are seen through it).
CONTAINER_OPACITY = 0.15
#: Colour of every collider (linear RGB).
COLLIDER_COLOR = (0.6, 0.6, 0.62)


def vertex_normals(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit per-vertex normals (V, 3) of ``points`` (V, 3) [m] with triangles ``faces``
    (F, 3): the area-weighted sum of the triangles' right-hand normals at each vertex
    (outward for an outward-wound body); zero at a vertex no triangle with area uses."""
    a, b, c = (points[faces[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)  # twice the area times the unit normal
    corner = faces.reshape(-1)
    normal = np.stack(
        [np.bincount(corner, np.repeat(face[:, d], 3), minlength=len(points)) for d in range(3)],
        axis=1,
    )
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    return np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)


def check_start_frame(start_frame: float) -> float:
    """``start_frame`` as a float; ValueError unless it is a finite number (a time code)
    of at most 1e15 in size."""
    if isinstance(start_frame, bool) or not isinstance(
        start_frame, int | float | np.integer | np.floating
    ):
        raise ValueError(f"start_frame must be a number (a time code), got {start_frame!r}")
    start = float(start_frame)
    if not (math.isfinite(start) and abs(start) <= 1e15):
        raise ValueError(f"start_frame must be a finite time code, got {start_frame!r}")
    return start


def _prim_name(text: str, fallback: str) -> str:
    name = "".join(ch if ch.isalnum() else "_" for ch in text) or fallback
    return f"b_{name}" if name[0].isdigit() else name


def _quaternions(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) as (w, x, y, z) of rotation matrices (..., 3, 3)."""
    from scipy.spatial.transform import Rotation

    shape = rotation.shape[:-2]
    xyzw = Rotation.from_matrix(rotation.reshape(-1, 3, 3)).as_quat()
    return np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1).reshape(*shape, 4)


def write_usd(
    path: Path,
    model: Model,
    frames: np.ndarray,
    fps: float,
    names: list[str],
    *,
    velocities: np.ndarray | None = None,
    collider_q: np.ndarray | None = None,
    collider_rotation: np.ndarray | None = None,
    start_frame: float = 0.0,
    ground_size: float = 8.0,
) -> None:
    """Write ``frames`` (F, N, 3) [m] of particle positions, ``fps`` frames per second, to
    ``path`` (.usd, .usda or .usdc); the layout is in this module's docstring.

    ``velocities`` (F, N, 3) [m/s]: the particles' velocities at each frame (none written
    when None). ``collider_q`` (F, C, 3) [m] and ``collider_rotation`` (F, C, 3, 3): the
    colliders' poses at each frame (the model's, still, when None). ``start_frame``: the
    time code of the first frame (a film's 1001, say). ``ground_size`` [m]: the side of
    the square drawn for each ground plane. ValueError for a non-finite ``start_frame``
    or arrays of the wrong shape.
    """
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, Vt
    except ImportError as exc:
        raise RuntimeError("USD export needs usd-core: pip install 'softbody[usd]'") from exc
    start = check_start_frame(start_frame)
    if not (math.isfinite(ground_size) and ground_size > 0):
        raise ValueError(f"ground_size must be finite and > 0 [m], got {ground_size!r}")
    count, n, c = len(frames), model.particle_count, model.collider_count
    if np.shape(frames) != (count, n, 3):
        raise ValueError(f"frames must have shape (F, {n}, 3), got {np.shape(frames)}")
    if velocities is not None and np.shape(velocities) != (count, n, 3):
        raise ValueError(
            f"velocities must have shape ({count}, {n}, 3), got {np.shape(velocities)}"
        )
    if collider_q is None:
        collider_q = np.broadcast_to(model.collider_center, (count, c, 3))
    if collider_rotation is None:
        collider_rotation = np.broadcast_to(model.collider_rotation, (count, c, 3, 3))
    collider_q = np.asarray(collider_q, dtype=np.float64)
    collider_rotation = np.asarray(collider_rotation, dtype=np.float64)
    if collider_q.shape != (count, c, 3) or collider_rotation.shape != (count, c, 3, 3):
        raise ValueError(
            f"collider poses must have shapes ({count}, {c}, 3) and ({count}, {c}, 3, 3), "
            f"got {collider_q.shape} and {collider_rotation.shape}"
        )
    codes = start + np.arange(count, dtype=np.float64)

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(start)
    stage.SetEndTimeCode(start + max(count - 1, 0))
    root = UsdGeom.Xform.Define(stage, "/softbody")
    stage.SetDefaultPrim(root.GetPrim())

    def vec3(array) -> Vt.Vec3fArray:
        return Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(array, np.float32))

    used = {"colliders"}
    for b, (p0, p1) in enumerate(model.body_particle_range):
        t0, t1 = model.body_tri_range[b]
        base = _prim_name(names[b], f"body_{b}")
        name, k = base, 1
        while name in used:
            name, k = f"{base}_{k}", k + 1
        used.add(name)
        mesh = UsdGeom.Mesh.Define(stage, Sdf.Path(f"/softbody/{name}"))
        faces = np.asarray(model.tri_indices[t0:t1] - p0, dtype=np.int64)
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(faces)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(faces.reshape(-1).tolist()))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
        primvars = UsdGeom.PrimvarsAPI(mesh)
        primvars.CreatePrimvar(
            "softbody:sourceVertex", Sdf.ValueTypeNames.IntArray, UsdGeom.Tokens.vertex
        ).Set(Vt.IntArray(model.particle_source_vertex[p0:p1].tolist()))
        primvars.CreatePrimvar(
            "softbody:sourceCornerVertex", Sdf.ValueTypeNames.IntArray, UsdGeom.Tokens.faceVarying
        ).Set(Vt.IntArray(model.tri_source_vertex[t0:t1].reshape(-1).tolist()))
        points = mesh.CreatePointsAttr()
        normals = mesh.CreateNormalsAttr()
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        extent = mesh.CreateExtentAttr()
        velocity = mesh.CreateVelocitiesAttr() if velocities is not None else None
        for f, code in enumerate(codes):
            q = np.asarray(frames[f][p0:p1], dtype=np.float64)
            points.Set(vec3(q), code)
            normals.Set(vec3(vertex_normals(q, faces)), code)
            # float32 bounds rounded outward so they hold the float32 points
            lo = np.nextafter(q.min(axis=0).astype(np.float32), np.float32(-np.inf))
            hi = np.nextafter(q.max(axis=0).astype(np.float32), np.float32(np.inf))
            extent.Set(vec3([lo, hi]), code)
            if velocity is not None:
                velocity.Set(vec3(velocities[f][p0:p1]), code)

    if c:
        UsdGeom.Scope.Define(stage, "/softbody/colliders")
    quats = _quaternions(collider_rotation) if c else np.zeros((count, 0, 4))
    for f in range(1, count):  # q and -q are one rotation: keep neighbours on one side
        flip = np.einsum("ij,ij->i", quats[f], quats[f - 1]) < 0
        quats[f, flip] *= -1
    for k in range(c):
        kind = ColliderKind(int(model.collider_kind[k]))
        size = np.asarray(model.collider_size[k], dtype=np.float64)
        where = f"/softbody/colliders/{kind.name.lower()}_{k}"
        if kind == ColliderKind.PLANE:
            where = f"/softbody/colliders/ground_{k}"
            geom = UsdGeom.Mesh.Define(stage, where)
            h = 0.5 * float(ground_size)
            corners = [(-h, 0, -h), (-h, 0, h), (h, 0, h), (h, 0, -h)]  # wound towards +y
            geom.CreatePointsAttr(vec3(corners))
            geom.CreateFaceVertexCountsAttr(Vt.IntArray([4]))
            geom.CreateFaceVertexIndicesAttr(Vt.IntArray([0, 1, 2, 3]))
            geom.CreateNormalsAttr(vec3([(0, 1, 0)] * 4))
            geom.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
            geom.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
            geom.CreateExtentAttr(vec3([(-h, 0, -h), (h, 0, h)]))
        elif kind == ColliderKind.MESH:  # its triangles in its local frame
            local, tris = collider_mesh(model, k)
            geom = UsdGeom.Mesh.Define(stage, where)
            geom.CreatePointsAttr(vec3(local))
            geom.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(tris)))
            geom.CreateFaceVertexIndicesAttr(Vt.IntArray(tris.reshape(-1).tolist()))
            geom.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
            geom.CreateExtentAttr(vec3([local.min(axis=0), local.max(axis=0)]))
        elif kind == ColliderKind.SPHERE:
            geom = UsdGeom.Sphere.Define(stage, where)
            geom.CreateRadiusAttr(float(size[0]))
            geom.CreateExtentAttr(vec3([-size, size]))
        else:  # BOX, BOX_CONTAINER: a cube of side 2 scaled by the half-extents
            if kind == ColliderKind.BOX_CONTAINER:
                where = f"/softbody/colliders/container_{k}"
            geom = UsdGeom.Cube.Define(stage, where)
            geom.CreateSizeAttr(2.0)
            geom.CreateExtentAttr(vec3([(-1, -1, -1), (1, 1, 1)]))
            if kind == ColliderKind.BOX_CONTAINER:
                geom.CreateDisplayOpacityAttr(Vt.FloatArray([CONTAINER_OPACITY]))
        geom.CreateDisplayColorAttr(Vt.Vec3fArray([Gf.Vec3f(*COLLIDER_COLOR)]))
        translate = geom.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble)
        orient = geom.AddOrientOp(UsdGeom.XformOp.PrecisionDouble)
        if kind in (ColliderKind.BOX, ColliderKind.BOX_CONTAINER):
            geom.AddScaleOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*size))
        moves = bool(
            np.any(collider_q[:, k] != collider_q[:1, k])
            or np.any(collider_rotation[:, k] != collider_rotation[:1, k])
        )
        for f, code in enumerate(codes if moves else codes[:1]):
            at = Usd.TimeCode(code) if moves else Usd.TimeCode.Default()
            translate.Set(Gf.Vec3d(*collider_q[f, k]), at)
            orient.Set(Gf.Quatd(*quats[f, k]), at)
    stage.GetRootLayer().Save()
