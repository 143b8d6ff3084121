"""The ball drop in Jolt Physics' soft body through its Python binding culverin.

Run by ``benchmarks/jolt_peer.py`` in its own Python >= 3.12 environment (culverin and
NumPy only; never imported by softbody). Usage:

    python jolt_drop.py MESH.npz SETTINGS.json OUT.json

MESH.npz holds ``vertices`` (V, 3) [m] of the ball at rest, centred on the origin,
``faces`` (F, 3) wound outward and ``masses`` (V,) [kg]. SETTINGS.json holds ``height``
[m] (the ball's centre at the start), ``frames``, ``dt`` [s], ``iterations`` (Jolt's
solver iterations per step, each a substep with one pass over the edges), ``compliance``
[m/N], ``pressure`` (n R T [J]), ``restitution``, ``friction``, ``linear_damping`` [1/s],
``vertex_radius`` [m] and ``threads`` (Jolt's worker threads beside the calling one).
OUT.json gets the centre-of-mass height [m] and the enclosed volume [m^3] at the start
and after every frame, the internal kinetic energy [J] at the end (velocities from the
last two frames' positions: culverin gives no vertex velocities), and ``wall_s``, the
wall time of the stepping calls alone.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from drop_check import center_of_mass_height, internal_kinetic_energy, mesh_volume


def main() -> None:
    import culverin as cv

    mesh_path, settings_path, out_path = sys.argv[1:4]
    mesh = np.load(mesh_path)
    vertices = np.ascontiguousarray(mesh["vertices"], dtype=np.float32)
    faces = np.ascontiguousarray(mesh["faces"], dtype=np.uint32)
    masses = np.asarray(mesh["masses"], dtype=float)
    s = json.loads(Path(settings_path).read_text())

    world = cv.PhysicsWorld(settings={"num_threads": int(s["threads"]), "max_bodies": 16})
    # the ground: the plane y = 0, normal up, as softbody's ColliderPlane; Jolt combines
    # friction as the geometric mean and restitution as the maximum of the two bodies', so
    # both get the drop's values
    world.create_body(
        pos=(0.0, 0.0, 0.0), shape=cv.SHAPE_PLANE, size=(0.0, 1.0, 0.0, 0.0),
        motion=cv.MOTION_STATIC, friction=s["friction"], restitution=s["restitution"],
    )  # fmt: skip
    shared = cv.SoftBodySharedSettings()
    shared.add_vertices(vertices.ravel(), (1.0 / masses).astype(np.float32))
    shared.add_faces(faces.ravel())
    # the mesh's edges as distance constraints of compliance 1/k; no bend constraints
    # (softbody's ball has springs on its edges only)
    shared.create_constraints(s["compliance"], cv.BEND_NONE)
    shared.optimize()
    body = world.create_soft_body(
        shared, (0.0, s["height"], 0.0), (0.0, 0.0, 0.0, 1.0),
        pressure=s["pressure"], vertex_radius=s["vertex_radius"],
        linear_damping=s["linear_damping"], num_iterations=int(s["iterations"]),
        friction=s["friction"], restitution=s["restitution"],
    )  # fmt: skip
    world.step(0.0)  # the body is created at the first step; a zero step moves nothing

    def positions() -> np.ndarray:
        # world positions, float64 in rows of 4 (x, y, z, padding)
        x = np.array(memoryview(world.get_soft_body_vertices(body)), dtype=float)
        x = x.reshape(-1, 4)[:, :3]
        if x.shape[0] != len(masses):
            raise RuntimeError(f"Jolt reports {x.shape[0]} vertices, the mesh has {len(masses)}")
        return x

    x = positions()
    heights, volumes = [center_of_mass_height(x, masses)], [mesh_volume(x, faces)]
    wall = 0.0
    dt = float(s["dt"])
    for _ in range(int(s["frames"])):
        x_prev = x
        t0 = time.perf_counter()
        world.step(dt)
        wall += time.perf_counter() - t0
        x = positions()
        heights.append(center_of_mass_height(x, masses))
        volumes.append(mesh_volume(x, faces))
    resting = internal_kinetic_energy((x - x_prev) / dt, masses)
    out = {
        "heights_m": heights,
        "volumes_m3": volumes,
        "internal_kinetic_energy_j": resting,
        "wall_s": wall,
        "culverin": cv.__version__ if hasattr(cv, "__version__") else None,
    }
    Path(out_path).write_text(json.dumps(out))


if __name__ == "__main__":
    main()
