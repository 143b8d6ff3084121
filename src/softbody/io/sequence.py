"""One mesh file per frame (OBJ or PLY): every body, vertex order kept."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from softbody.sim.model import Model


def write_mesh_frame(path: Path, model: Model, q: np.ndarray, names: list[str]) -> None:
    """Write all bodies at positions ``q`` (N, 3) [m] to ``path`` (.obj or .ply).

    OBJ: one ``o`` object per body, vertices in particle order (so frame k, vertex i is
    particle i). PLY: all bodies in one binary mesh, same vertex order.
    """
    suffix = path.suffix.lower()
    if suffix == ".obj":
        lines = []
        for b, (p0, p1) in enumerate(model.body_particle_range):
            t0, t1 = model.body_tri_range[b]
            name = names[b].replace(" ", "_")
            lines.append(f"o {name}")
            lines.extend(f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in q[p0:p1])
            faces = model.tri_indices[t0:t1] + 1  # OBJ counts from 1; offset = global index
            lines.extend(f"f {a} {b_} {c}" for a, b_, c in faces)
        path.write_text("\n".join(lines) + "\n")
    elif suffix == ".ply":
        import trimesh

        lo, hi = model.body_particle_range[0, 0], model.body_particle_range[-1, 1]
        mesh = trimesh.Trimesh(q[lo:hi], model.tri_indices - lo, process=False)
        path.write_bytes(mesh.export(file_type="ply"))
    else:
        raise ValueError(f"mesh sequence format must be obj or ply, got {suffix!r}")
