"""Generate the mesh colliders of the contact scenes (issue 32): the rounded block of
``vacuum-gripper``, the ring of ``balloon-ring`` and the stair of ``cloth-stair``.

Each mesh is built here from its closed form (NumPy only), checked (one closed, outward
wound surface that does not cross itself: ``softbody.collision.mesh_collider.checked_mesh``,
the check every mesh collider passes) and written to src/softbody/scenes/meshes/NAME.obj,
which ships with the package (a scene names it ``mesh = { builtin = "NAME" }``), so this
script is needed only to change them. Units are metres.

    python tools/make_contact_meshes.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import softbody as sb
from softbody.collision.mesh_collider import checked_mesh

OUT = Path(__file__).resolve().parents[1] / "src" / "softbody" / "scenes" / "meshes"


def rounded_block(half=(0.12, 0.2, 0.12), exponent=6.0, subdivisions=3) -> sb.TriMesh:
    """A superellipsoid |x/a|^p + |y/b|^p + |z/c|^p = 1 (p = ``exponent``): a block with
    nearly flat faces and rounded edges, its centre at the origin. An icosphere's vertices
    are moved along their directions onto it (a radial map: still closed, never crossing)."""
    sphere = sb.icosphere(subdivisions)
    d = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    r = np.sum(np.abs(d / np.asarray(half)) ** exponent, axis=1) ** (-1.0 / exponent)
    return sb.TriMesh(d * r[:, None], sphere.faces.copy())


def torus(major=0.2, minor=0.055, around=48, tube=16) -> sb.TriMesh:
    """A ring about the y axis in the xz plane: tube radius ``minor`` [m] about a circle of
    radius ``major`` [m], ``around`` x ``tube`` quads, each split in two, wound outward."""
    u = 2 * np.pi * np.arange(around) / around  # about the y axis
    v = 2 * np.pi * np.arange(tube) / tube  # about the tube
    uu, vv = np.meshgrid(u, v, indexing="ij")
    rho = major + minor * np.cos(vv)
    vertices = np.stack([rho * np.cos(uu), minor * np.sin(vv), rho * np.sin(uu)], axis=-1)
    i, j = np.meshgrid(np.arange(around), np.arange(tube), indexing="ij")
    a = i * tube + j
    b = ((i + 1) % around) * tube + j
    c = ((i + 1) % around) * tube + (j + 1) % tube
    d = i * tube + (j + 1) % tube
    faces = np.concatenate([np.stack([a, d, c], -1), np.stack([a, c, b], -1)], axis=None)
    return sb.TriMesh(vertices.reshape(-1, 3), faces.reshape(-1, 3).astype(np.int64))


def stair(steps=3, run=0.3, rise=0.15, width=1.2) -> sb.TriMesh:
    """A flight of ``steps`` steps rising along +x (each ``run`` deep and ``rise`` high [m]),
    ``width`` [m] wide along z, standing on y = 0 from x = 0: its side profile extruded
    along z. Each cap is cut into the steps' columns, column k (x from k run to (k + 1)
    run, y up to (k + 1) rise) a fan from its bottom right corner over its corners,
    including the corner of the lower step on its left side (no T-junction)."""
    # the profile, counter-clockwise seen from +z: the bottom left to right, then the steps
    bottom = [(k * run, 0.0) for k in range(steps + 1)]
    top = []
    for k in range(steps, 0, -1):
        top += [(k * run, k * rise), ((k - 1) * run, k * rise)]
    p = np.array(bottom + top)
    n = len(p)

    def at(x: float, y: float) -> int:
        return int(np.flatnonzero(np.all(np.abs(p - (x, y)) < 1e-12, axis=1))[0])

    cap = []
    for k in range(steps):
        x0, x1, y1 = k * run, (k + 1) * run, (k + 1) * rise
        corners = [at(x1, 0.0), at(x1, y1), at(x0, y1)]
        if k > 0:
            corners.append(at(x0, k * rise))  # the lower step's corner on the left side
        corners.append(at(x0, 0.0))
        cap += [(corners[0], corners[j], corners[j + 1]) for j in range(1, len(corners) - 1)]
    front = np.column_stack([p, np.full(n, 0.5 * width)])
    back = np.column_stack([p, np.full(n, -0.5 * width)])
    faces = [f for a, b, c in cap for f in ((a, b, c), (n + a, n + c, n + b))]
    for k in range(n):  # sides: one quad per profile edge
        m = (k + 1) % n
        faces += [(k, n + k, n + m), (k, n + m, m)]
    return sb.TriMesh(np.vstack([front, back]), np.array(faces, dtype=np.int64))


def main() -> None:
    for name, mesh in [("rounded-block", rounded_block()), ("ring", torus()),
                       ("stair", stair())]:  # fmt: skip
        checked, _ = checked_mesh(mesh)
        path = sb.save_mesh(checked, OUT / f"{name}.obj")
        print(f"{path}: {len(checked.vertices)} vertices, {len(checked.faces)} triangles")


if __name__ == "__main__":
    main()
