"""USD export: one UsdGeom.Mesh per body with time-sampled points (a point cache that
Blender and Houdini import). Needs the optional ``usd`` extra (usd-core)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from softbody.sim.model import Model


def write_usd(path: Path, model: Model, frames: np.ndarray, fps: float, names: list[str]) -> None:
    """Write ``frames`` (F, N, 3) [m] of positions, ``fps`` frames per second, to ``path``
    (.usd, .usda or .usdc). Y is up and one unit is one metre."""
    try:
        from pxr import Sdf, Usd, UsdGeom, Vt
    except ImportError as exc:
        raise RuntimeError("USD export needs usd-core: pip install 'softbody[usd]'") from exc
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(len(frames) - 1)
    root = UsdGeom.Xform.Define(stage, "/softbody")
    stage.SetDefaultPrim(root.GetPrim())
    used = set()
    for b, (p0, p1) in enumerate(model.body_particle_range):
        t0, t1 = model.body_tri_range[b]
        base = "".join(ch if ch.isalnum() else "_" for ch in names[b]) or f"body_{b}"
        if base[0].isdigit():
            base = f"b_{base}"
        name, k = base, 1
        while name in used:
            name, k = f"{base}_{k}", k + 1
        used.add(name)
        mesh = UsdGeom.Mesh.Define(stage, Sdf.Path(f"/softbody/{name}"))
        faces = model.tri_indices[t0:t1] - p0
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(faces)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(faces.reshape(-1).tolist()))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        points = mesh.CreatePointsAttr()
        for f, q in enumerate(frames):
            points.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(q[p0:p1], np.float32)), f)
    stage.GetRootLayer().Save()
