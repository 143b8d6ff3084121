"""Ball drop against mesh size: how much simulated time each integrator gets per second.

The case (issue 5): an icosphere of radius 1 m and 1 kg, inflated (nRT = 300 J, springs
500 N/m), dropped from 1 m onto the ground. Each integrator runs at its largest stable
step (0.9 x the estimate; implicit Euler at 1/60 s). Steps per second are measured over
at least half a second of wall time (best of 3), so sizes that would take hours to
simulate 2 s are still measured. For every size that runs at least in real time, the
full 2 s drop is then simulated and checked (volume within [0.7, 1.5] of its start, the
centre of mass back up at least 5 cm after the first contact), so no broken scene is
timed. Peak memory per vertex is the tracemalloc peak of building the model, the
simulator and one step, divided by the vertex count.

With panda3d installed (``pip install -e ".[bench]"``), the same drop runs in Bullet's
soft body with its pressure coefficient kPR = 10 (its ball then stays within [0.76, 1.08]
of its volume and rebounds), at Bullet's usual fixed 1/60 s step with 4 position
iterations, in the same process, and the ratio softbody / Bullet (best integrator) is
printed per size.

Writes results/ball_drop.{json,png}.
Usage: python benchmarks/ball_drop.py [--max-subdivisions 7]
"""

from __future__ import annotations

import argparse
import json
import os
import time
import tracemalloc
import warnings
from pathlib import Path

import numpy as np

import softbody as sb

RESULTS = Path(__file__).parent / "results"
INTEGRATORS = ["symplectic_euler", "velocity_verlet", "midpoint", "rk4", "implicit_euler"]


def ball_drop(subdivisions: int) -> sb.Model:
    builder = sb.ModelBuilder()
    builder.add_soft_body(
        sb.icosphere(subdivisions, radius=1.0, center=(0.0, 2.0, 0.0)),
        mass=1.0,
        stiffness=500.0,
        damping=0.5,
        gas=sb.Gas.isothermal(300.0),
    )
    builder.add_collider(sb.ColliderPlane(restitution=0.5, friction=0.1))
    return builder.finalize()


def simulator(model, integrator) -> sb.Simulator:
    if integrator == "implicit_euler":
        return sb.Simulator(model, integrator=integrator, dt=1 / 60)
    probe = sb.Simulator(model, integrator=integrator, dt=1e-6)
    return sb.Simulator(model, integrator=integrator, dt=0.9 * probe.stable_dt)


def steps_per_second(model, sim) -> float:
    state = model.state()
    sim.run(state, 1)
    best = 0.0
    for _ in range(3):
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < 0.5 or n < 2:
            sim.run(state, 1 if n < 2 else max(1, n // 2))
            n = state.step_count - 1 if n == 0 else n + (1 if n < 2 else max(1, n // 2))
        best = max(best, n / (time.perf_counter() - t0))
        state = model.state()
        sim.run(state, 1)
    return best


def check_drop(model, sim) -> dict:
    """Simulate the full 2 s and check the ball stays round and bounces."""
    state = model.state()
    v0 = sb.body_volume(model, state)[0]
    heights, ratios = [], []
    frame = max(1, round(0.02 / sim.dt))
    t0 = time.perf_counter()
    while state.time < 2.0 - 1e-9:
        sim.run(state, frame)
        heights.append(sb.body_center_of_mass(model, state)[0, 1])
        ratios.append(sb.body_volume(model, state)[0] / v0)
    wall = time.perf_counter() - t0
    heights = np.array(heights)
    bottom = int(np.argmin(heights))
    rebound = float(heights[bottom:].max() - heights[bottom])
    ok = 0.7 < min(ratios) and max(ratios) < 1.5 and rebound > 0.05
    return {
        "wall_s": wall,
        "simulated_per_wall_second": state.time / wall,
        "rebound_m": rebound,
        "volume_ratio_range": [min(ratios), max(ratios)],
        "ok": ok,
    }


BULLET_KPR = 10.0
#: panda3d 1.10.16's Bullet crashed (segmentation fault) on the 163,842-vertex ball here
BULLET_MAX_VERTICES = 50_000
BULLET_DT = 1.0 / 60.0


class BulletDrop:
    """The same ball drop in Bullet's soft body (panda3d), z up."""

    def __init__(self, subdivisions: int):
        from panda3d.bullet import (
            BulletPlaneShape,
            BulletRigidBodyNode,
            BulletSoftBodyNode,
            BulletWorld,
        )
        from panda3d.core import LVecBase3f, PTA_int, PTA_LVecBase3f, Vec3

        mesh = sb.icosphere(subdivisions, radius=1.0)
        self.world = BulletWorld()
        self.world.setGravity(Vec3(0, 0, -9.81))
        info = self.world.getWorldInfo()
        info.setAirDensity(1.2)
        info.setWaterDensity(0)
        info.setGravity(Vec3(0, 0, -9.81))
        points = PTA_LVecBase3f()
        for x, y, z in mesh.vertices:  # rotate y-up into z-up, centre 2 m up
            points.push_back(LVecBase3f(x, -z, y + 2.0))
        indices = PTA_int()
        for i in mesh.faces.reshape(-1):
            indices.push_back(int(i))
        self.body = BulletSoftBodyNode.makeTriMesh(info, points, indices, False)
        cfg = self.body.getCfg()
        cfg.setPressureCoefficient(BULLET_KPR)
        cfg.setDampingCoefficient(0.01)
        cfg.setPositionsSolverIterations(4)
        self.body.getMaterial(0).setLinearStiffness(0.5)
        self.body.setTotalMass(1.0)
        self.world.attachSoftBody(self.body)
        ground = BulletRigidBodyNode("ground")
        ground.addShape(BulletPlaneShape(Vec3(0, 0, 1), 0))
        self.world.attachRigidBody(ground)
        self.count = self.body.getNumNodes()

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self.world.doPhysics(BULLET_DT, 1, BULLET_DT)

    def height(self) -> float:
        n = self.count
        return float(
            np.mean([self.body.getNode(i).getPos()[2] for i in range(0, n, max(1, n // 200))])
        )


def bullet_entry(subdivisions: int) -> dict:
    """Steps per second of Bullet's drop (best of 3 windows of >= 0.5 s), and the full
    2 s drop checked when it keeps real time."""
    best = 0.0
    for _ in range(3):
        drop = BulletDrop(subdivisions)
        drop.step(1)
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < 0.5 or n < 2:
            drop.step(1)
            n += 1
        best = max(best, n / (time.perf_counter() - t0))
    entry = {
        "dt_s": BULLET_DT,
        "steps_per_second": best,
        "simulated_per_wall_second": best * BULLET_DT,
        "vertex_count": drop.count,
    }
    if entry["simulated_per_wall_second"] >= 1.0:
        drop = BulletDrop(subdivisions)
        v0 = drop.body.getVolume()
        heights, ratios = [], []
        t0 = time.perf_counter()
        for _ in range(120):
            drop.step(1)
            heights.append(drop.height())
            ratios.append(drop.body.getVolume() / v0)
        wall = time.perf_counter() - t0
        heights = np.array(heights)
        bottom = int(np.argmin(heights))
        rebound = float(heights[bottom:].max() - heights[bottom])
        entry["full_drop"] = {
            "simulated_per_wall_second": 2.0 / wall,
            "rebound_m": rebound,
            "volume_ratio_range": [min(ratios), max(ratios)],
            "ok": 0.7 < min(ratios) and max(ratios) < 1.5 and rebound > 0.05,
        }
    return entry


def memory_per_vertex(subdivisions: int) -> float:
    tracemalloc.start()
    model = ball_drop(subdivisions)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator="implicit_euler", dt=1 / 60)
    sim.run(model.state(), 1)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / model.particle_count


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--min-subdivisions", type=int, default=2)
    parser.add_argument("--max-subdivisions", type=int, default=7)
    args = parser.parse_args()
    rows = []
    for s in range(args.min_subdivisions, args.max_subdivisions + 1):
        model = ball_drop(s)
        row = {
            "vertex_count": model.particle_count,
            "bytes_per_vertex": memory_per_vertex(s),
            "integrators": {},
        }
        for name in INTEGRATORS:
            sim = simulator(model, name)
            rate = steps_per_second(model, sim)
            entry = {
                "dt_s": sim.dt,
                "steps_per_second": rate,
                "simulated_per_wall_second": rate * sim.dt,
                "vertex_steps_per_second": rate * model.particle_count,
            }
            if entry["simulated_per_wall_second"] >= 1.0:
                entry["full_drop"] = check_drop(model, sim)
            row["integrators"][name] = entry
            print(
                f"{model.particle_count:>7} {name:17s} dt {sim.dt:.2e} s  "
                f"{rate:10.1f} steps/s  {entry['simulated_per_wall_second']:9.4f}x real time"
                + (f"  drop ok={entry['full_drop']['ok']}" if "full_drop" in entry else ""),
                flush=True,
            )
        try:
            import panda3d.bullet  # noqa: F401

            if model.particle_count > BULLET_MAX_VERTICES:
                raise ImportError("skipped: above BULLET_MAX_VERTICES")

            row["bullet"] = bullet_entry(s)
            best = max(e["simulated_per_wall_second"] for e in row["integrators"].values())
            row["softbody_over_bullet"] = best / row["bullet"]["simulated_per_wall_second"]
            print(
                f"{model.particle_count:>7} bullet            dt {BULLET_DT:.2e} s  "
                f"{row['bullet']['steps_per_second']:10.1f} steps/s  "
                f"{row['bullet']['simulated_per_wall_second']:9.4f}x real time"
                + (
                    f"  drop ok={row['bullet']['full_drop']['ok']}"
                    if "full_drop" in row["bullet"]
                    else ""
                )
                + f"  -> softbody/bullet = {row['softbody_over_bullet']:.3g}",
                flush=True,
            )
        except ImportError:
            pass
        rows.append(row)
    realtime = {}
    for name in INTEGRATORS:
        good = [
            r["vertex_count"]
            for r in rows
            if r["integrators"][name].get("full_drop", {}).get("ok")
            and r["integrators"][name]["full_drop"]["simulated_per_wall_second"] >= 1.0
        ]
        realtime[name] = max(good) if good else 0
    bullet_ok = [
        r["vertex_count"] for r in rows if r.get("bullet", {}).get("full_drop", {}).get("ok")
    ]
    if any("bullet" in r for r in rows):
        realtime["bullet"] = max(bullet_ok) if bullet_ok else 0
    print("largest real-time ball drop (vertices):", realtime)
    RESULTS.mkdir(exist_ok=True)
    result = {
        "benchmark": "ball_drop",
        "date": time.strftime("%Y-%m-%d"),
        "cores": os.cpu_count(),
        "threads": 1,
        "dtype": "float64",
        "sizes": rows,
        "largest_realtime_vertex_count": realtime,
        "bullet": {"kPR": BULLET_KPR, "dt_s": BULLET_DT, "position_iterations": 4}
        if any("bullet" in r for r in rows)
        else None,
    }
    (RESULTS / "ball_drop.json").write_text(json.dumps(result, indent=2))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 5.5), dpi=110)
    n = [r["vertex_count"] for r in rows]
    for k, name in enumerate(INTEGRATORS):
        ax.plot(
            n,
            [r["integrators"][name]["simulated_per_wall_second"] for r in rows],
            "o-",
            color=f"C{k}",
            label=name,
        )
    if any("bullet" in r for r in rows):
        ax.plot(
            [r["vertex_count"] for r in rows if "bullet" in r],
            [r["bullet"]["simulated_per_wall_second"] for r in rows if "bullet" in r],
            "s--",
            color="k",
            label="Bullet soft body (kPR, 1/60 s)",
        )
    ax.axhline(1.0, color="k", lw=1, ls=":", label="real time")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("vertices")
    ax.set_ylabel("simulated seconds per wall second")
    ax.set_title("Ball drop (1 m, 1 kg, inflated), each integrator at its largest stable dt")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    tmp = RESULTS / "ball_drop.tmp.png"
    fig.savefig(tmp)
    os.replace(tmp, RESULTS / "ball_drop.png")
    print(f"wrote {RESULTS / 'ball_drop.json'} and .png")


if __name__ == "__main__":
    main()
