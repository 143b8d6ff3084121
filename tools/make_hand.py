"""Generate the soft hand of the ``hand-punch`` scene (paper, Figure 8: ~386 vertices).

A signed distance field (rounded-box palm, five capsule fingers, smooth union) is meshed
with marching cubes, clustered to ~390 well-shaped triangles (ACVD, pyacvd) and projected
back onto the field. The result is checked (closed, manifold, outward, no slivers) and
written to src/softbody/scenes/meshes/hand.obj, which ships with the package, so this
script is needed only to change the hand. It needs extra packages (not project
dependencies): pip install numpy scikit-image pyacvd pyvista

Units are metres; the palm faces +z, fingers point +y, the wrist is at y = 0.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parents[1] / "src" / "softbody" / "scenes" / "meshes" / "hand.obj"
TARGET_VERTICES = 390


def capsule(p, a, b, r):
    pa, ba = p - a, b - a
    h = np.clip((pa @ ba) / (ba @ ba), 0.0, 1.0)
    return np.linalg.norm(pa - h[..., None] * ba, axis=-1) - r


def rounded_box(p, center, half, r):
    q = np.abs(p - center) - (np.asarray(half) - r)
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0) - r


def smooth_min(a, b, k):
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b * (1 - h) + a * h - k * h * (1 - h)


def hand_sdf(p):
    """Signed distance [m] to the hand surface (negative inside)."""
    d = rounded_box(p, np.array([0.0, 0.055, 0.0]), (0.042, 0.05, 0.014), 0.012)
    fingers = [  # base (on the palm's top edge), tip, radius
        ((-0.030, 0.098, 0.0), (-0.036, 0.160, 0.0), 0.0085),  # little
        ((-0.011, 0.102, 0.0), (-0.012, 0.185, 0.0), 0.0095),  # ring
        ((0.009, 0.104, 0.0), (0.010, 0.192, 0.0), 0.0100),  # middle
        ((0.028, 0.100, 0.0), (0.033, 0.178, 0.0), 0.0095),  # index
        ((0.036, 0.035, 0.004), (0.078, 0.085, 0.010), 0.0110),  # thumb
    ]
    for a, b, r in fingers:
        d = smooth_min(d, capsule(p, np.array(a), np.array(b), r), 0.008)
    return d


def gradient(p, h=1e-5):
    g = np.zeros_like(p)
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        g[:, k] = (hand_sdf(p + e) - hand_sdf(p - e)) / (2 * h)
    return g


def main() -> None:
    import pyacvd
    import pyvista as pv
    from skimage.measure import marching_cubes

    spacing = 0.0015
    lo, hi = np.array([-0.07, -0.02, -0.04]), np.array([0.11, 0.22, 0.04])
    axes = [np.arange(lo[k], hi[k], spacing) for k in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    field = hand_sdf(grid.reshape(-1, 3)).reshape(grid.shape[:3])
    verts, faces, _, _ = marching_cubes(field, 0.0, spacing=(spacing,) * 3)
    verts += lo
    surf = pv.PolyData(verts, np.hstack([np.full((len(faces), 1), 3), faces]).ravel())
    clus = pyacvd.Clustering(surf)
    clus.subdivide(2)
    clus.cluster(TARGET_VERTICES)
    remesh = clus.create_mesh()
    v = np.asarray(remesh.points, dtype=np.float64)
    f = np.asarray(remesh.faces).reshape(-1, 4)[:, 1:]
    for _ in range(10):  # project back onto the surface along the field's gradient
        g = gradient(v)
        v -= hand_sdf(v)[:, None] * g / np.sum(g * g, axis=1, keepdims=True)

    import softbody as sb

    mesh = sb.validate_mesh(sb.TriMesh(v, f), name="hand")
    a, b, c = (mesh.vertices[mesh.faces[:, k]] for k in range(3))

    def angle(p, q, r):
        u, w = q - p, r - p
        cos = np.sum(u * w, 1) / np.linalg.norm(u, axis=1) / np.linalg.norm(w, axis=1)
        return np.degrees(np.arccos(np.clip(cos, -1, 1)))

    min_angle = min(angle(a, b, c).min(), angle(b, c, a).min(), angle(c, a, b).min())
    euler = mesh.vertex_count - len(mesh.edges) + mesh.face_count
    print(
        f"hand: {mesh.vertex_count} vertices, {mesh.face_count} faces, Euler {euler}, "
        f"volume {mesh.volume * 1e6:.1f} cm^3, smallest angle {min_angle:.1f} deg"
    )
    if euler != 2 or min_angle < 15:
        raise SystemExit("hand mesh failed its checks")
    sb.save_mesh(mesh.reordered(), OUT)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
