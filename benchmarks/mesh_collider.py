"""Mesh collider cost: a 2,562-vertex ball pressed on a 5,120-triangle mesh.

The ball (icosphere of 4 subdivisions, radius 0.3 m, 1 kg, nRT = 200 J) starts touching
the top of a sphere of radius 1 m, given three ways: as a mesh collider of 5,120
triangles (icosphere of 4 subdivisions), as the analytic ColliderSphere, and not at all
(a far-away plane, so the step has a collider stage that finds nothing). And a harder
case for the mesh: the ball seated in the hole of a ring (a torus mesh of 5,120 triangles,
major radius 0.45 m, tube 0.2 m), so that every vertex of the ball lies inside the mesh's
bounding box and goes through the tree's path and inside tests each step. The sphere mesh
three more ways for the edge contacts (its faces are about 4 degrees apart, so that at the
default ``sharp_angle`` of 30 no edge is sharp, every edge bent: the chords and caps only):
``mesh-vertices`` with the edge contacts off (``sharp_angle=None``), ``mesh-edges`` with
every one of its 7,680 edges sharp (``sharp_angle=0``: the edge-edge push too), and
``ring-edges`` the ring so. And a sharp
ridge: ``ridge`` the ball touching the top edge of a 1 m box of 12,288 triangles (32 x 32
squares a side) turned 45 degrees about z, whose 384 edge pieces along the box's edges are
sharp, ``ridge-vertices`` the same without edge contacts. Midpoint at
1e-5 s; steps per second over at least ``MIN_SECONDS`` of wall time, best of
``REPEATS``. Reported: each case's step time and the mesh colliders' cost per step and per
ball vertex over the step without a collider to find.

Writes results/mesh_collider.json.
"""

from __future__ import annotations

import time

import numpy as np

import softbody as sb
from results_io import RESULTS, run_record, write_json

REPEATS = 5
MIN_SECONDS = 0.3
DT = 1e-5


def build(kind: str) -> tuple[sb.Model, sb.Simulator]:
    builder = sb.ModelBuilder()
    builder.add_soft_body(sb.icosphere(4, radius=0.3, center=(0.0, 1.2999, 0.0)), mass=1.0,
                          stiffness=800.0, damping=2.0, gas=200.0)  # fmt: skip
    angle = {"mesh-vertices": None, "mesh-edges": 0.0, "ring-edges": 0.0,
             "ridge-vertices": None}.get(kind, 30.0)  # fmt: skip
    if kind.startswith("ridge"):
        builder = sb.ModelBuilder()
        top = 0.5 * np.sqrt(2.0)
        builder.add_soft_body(sb.icosphere(4, radius=0.3, center=(0.0, top + 0.2999, 0.0)),
                              mass=1.0, stiffness=800.0, damping=2.0, gas=200.0)  # fmt: skip
        turned = sb.collision.rotation_about((0, 0, 1), np.pi / 4)
        builder.add_collider(sb.ColliderMesh(sb.box((1.0, 1.0, 1.0), subdivisions=5),
                                             restitution=0.0, rotation=turned,
                                             sharp_angle=angle))  # fmt: skip
    elif kind.startswith("ring"):
        import trimesh

        ring = trimesh.creation.torus(major_radius=0.45, minor_radius=0.2, major_sections=80,
                                      minor_sections=32)  # fmt: skip
        builder = sb.ModelBuilder()
        height = np.sqrt(0.5**2 - 0.45**2)  # the ball touches the tube all round
        builder.add_soft_body(sb.icosphere(4, radius=0.3, center=(0.0, height, 0.0)), mass=1.0,
                              stiffness=800.0, damping=2.0, gas=200.0)  # fmt: skip
        # trimesh's torus is about z: turned to lie flat, about y
        flat = sb.collision.rotation_about((1, 0, 0), np.pi / 2)
        builder.add_collider(sb.ColliderMesh(ring, restitution=0.0, rotation=flat,
                                             sharp_angle=angle))  # fmt: skip
    elif kind.startswith("mesh"):
        builder.add_collider(sb.ColliderMesh(sb.icosphere(4, radius=1.0), restitution=0.0,
                                             sharp_angle=angle))  # fmt: skip
    elif kind == "sphere":
        builder.add_collider(sb.ColliderSphere(radius=1.0, restitution=0.0))
    else:
        builder.add_collider(sb.ColliderPlane(point=(0.0, -10.0, 0.0)))
    model = builder.finalize()
    return model, sb.Simulator(model, integrator="midpoint", dt=DT)


def seconds_per_step(kinds: tuple[str, ...]) -> dict[str, float]:
    """Each case's best seconds per step over REPEATS rounds, the cases taking turns in
    each round (so that a busy machine slows them alike)."""
    built = {kind: build(kind) for kind in kinds}
    best = dict.fromkeys(kinds, np.inf)
    for _ in range(REPEATS):
        for kind, (model, sim) in built.items():
            state = model.state()
            sim.run(state, 50)  # in contact, warm
            steps, start = 0, time.perf_counter()
            while (elapsed := time.perf_counter() - start) < MIN_SECONDS:
                sim.run(state, 200)
                steps += 200
            best[kind] = min(best[kind], elapsed / steps)
    return best


def main() -> None:
    kinds = ("none", "sphere", "mesh", "mesh-vertices", "mesh-edges", "ring", "ring-edges",
             "ridge", "ridge-vertices")  # fmt: skip
    times = seconds_per_step(kinds)
    model, _ = build("mesh")
    n = model.particle_count
    for kind, t in times.items():
        extra = t - times["none"]
        print(f"{kind:>13}: {t * 1e6:8.1f} us per step; collider {extra * 1e6:7.1f} us, "
              f"{extra / n * 1e9:6.1f} ns per ball vertex")  # fmt: skip
    triangles = {k: len(build(k)[0].collider_mesh_triangles) for k in ("mesh", "ring", "ridge")}
    print(f"{n} ball vertices; mesh triangles {triangles}")
    write_json(RESULTS / "mesh_collider.json", run_record(
        "mesh_collider", vertices=n, triangles=triangles, seconds_per_step=times))  # fmt: skip


if __name__ == "__main__":
    main()
