"""Ball drop against mesh size: how much simulated time each integrator gets per second.

The case (issue 5): an icosphere of radius 1 m and 1 kg, inflated (nRT = 300 J, springs
500 N/m), dropped from 1 m onto the ground. Each integrator runs at its largest stable
step (0.9 x the estimate; implicit Euler and BDF2 at 1/60 s with the multigrid
preconditioner, at CG tolerance 1e-3 and again at 1e-2: on the 10,242-vertex ball the
error each tolerance adds to the drop is measured against a solve to 1e-6). Steps per
second are measured over at least half a second of wall time (best of 3), so sizes that
would take hours to simulate 2 s are still measured. Wherever the full 2 s drop takes at
most 90 s, it is then simulated and checked (volume within [0.7, 1.5] of its start, the
centre of mass back up at least 5 cm after the first contact, and at the end the kinetic
energy of motion relative to the centre of mass below 5% of the drop energy m g h, so a
ball shaking from a too-long step fails), so no broken scene counts as real time. Peak
memory per vertex is the growth of the peak resident set of building the model, a
simulator and one step, in a fresh process after the same on a small ball (so loading
the modules and the compiled core is not counted), divided by the vertex count, for
implicit Euler (with its multigrid hierarchy) and for velocity Verlet (with its
stability estimate's Lanczos runs); ``--memory-only`` measures it again into the last
result.

With panda3d installed (``pip install -e ".[bench]"``), the same drop runs in Bullet's
soft body with its pressure coefficient kPR at Bullet's usual fixed 1/60 s step, in the
same process. Bullet's position-solver iterations (4, 8, ..., 128), each with kPR = 10,
20 and 40, are tried fewest iterations first until its ball passes the same check, so
both sides are timed with a valid ball; the ratio softbody (fastest valid integrator) /
Bullet is printed per size.

XPBD with small steps ("xpbd") runs at 1/60 s with its default substeps, and again as
"xpbd fewest valid": the fewest substeps of XPBD_SUBSTEPS (one constraint pass each) whose
2 s drop is valid and rebounds >= 0.9 m, tried fewest first (as Bullet's iterations are);
"xpbd relaxed fewest valid" the same search at XPBD_RELAXED (4 passes per substep, the
last 3 over-relaxed by 1.9).
``--runs xpbd "xpbd fewest valid"`` measures only those runs and merges them into the rows
of the same sizes in results/ball_drop.json, keeping every other run's entries (and the
memory and CG tolerance measurements) as they were.

Writes results/ball_drop.{json,png}. After each size, the sizes measured so far go to
results/ball_drop.partial.json (removed when the run completes), so a run stopped or
crashed at a large size keeps what it measured and the last complete result is left as
it was.
Usage: python benchmarks/ball_drop.py [--max-subdivisions 7]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import softbody as sb
from results_io import RESULTS, run_record, save_figure, write_json

#: implicit schemes' CG tolerance (relative residual) in the runs named after them; the
#: full-drop check below shows the ball stays round and bouncing with it
IMPLICIT_TOLERANCE = 1e-3
#: the looser tolerance of the runs named "<scheme> cg 1e-2"; ``tolerance_error`` below
#: measures what it costs in accuracy against a tight solve
LOOSE_TOLERANCE = 1e-2
#: the sizes measured so far, while a run is going on
PARTIAL = RESULTS / "ball_drop.partial.json"

#: run name -> (integrator, CG tolerance or None for the explicit schemes)
RUNS = {
    "symplectic_euler": ("symplectic_euler", None),
    "velocity_verlet": ("velocity_verlet", None),
    "midpoint": ("midpoint", None),
    "rk4": ("rk4", None),
    "implicit_euler": ("implicit_euler", IMPLICIT_TOLERANCE),
    "bdf2": ("bdf2", IMPLICIT_TOLERANCE),
    "implicit_euler cg 1e-2": ("implicit_euler", LOOSE_TOLERANCE),
    "bdf2 cg 1e-2": ("bdf2", LOOSE_TOLERANCE),
    "xpbd": ("xpbd", None),
    "xpbd fewest valid": ("xpbd", None),
    "xpbd relaxed fewest valid": ("xpbd", None),
}

#: the frame XPBD runs at, its substeps cut from it
XPBD_DT = 1.0 / 60.0
#: XPBD's substeps per 1/60 s frame tried by "xpbd fewest valid", fewest first
XPBD_SUBSTEPS = (8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256)
#: the rebound [m] "xpbd fewest valid" asks for (issue 33: the bounce kept)
XPBD_REBOUND = 0.9
#: "xpbd relaxed fewest valid": the same search with these passes per substep, all but the
#: first over-relaxed (docs/guide/integrators.md)
XPBD_RELAXED = {"xpbd_iterations": 4, "xpbd_relaxation": 1.9}


def ball_drop(subdivisions: int, *, self_contact: bool = False) -> sb.Model:
    """The drop's ball (1 m radius, 1 kg, k = 500 N/m edges, nRT = 300 J) 1 m above the
    ground; with ``self_contact``, surface contacts with a thickness on (benchmarks/
    self_contact.py)."""
    builder = sb.ModelBuilder()
    if self_contact:
        builder.set_soft_contact("surface", self_contact=True)
    builder.add_soft_body(
        sb.icosphere(subdivisions, radius=1.0, center=(0.0, 2.0, 0.0)),
        mass=1.0,
        stiffness=500.0,
        damping=0.5,
        gas=sb.Gas.isothermal(300.0),
    )
    builder.add_collider(sb.ColliderPlane(restitution=0.5, friction=0.1))
    return builder.finalize()


def simulator(model, run: str, substeps: int | None = None) -> sb.Simulator:
    integrator, tolerance = RUNS[run]
    if integrator == "xpbd":
        options = {} if substeps is None else {"xpbd_substeps": substeps}
        if run == "xpbd relaxed fewest valid":
            options.update(XPBD_RELAXED)
        return sb.Simulator(model, integrator="xpbd", dt=XPBD_DT, **options)
    if tolerance is not None:
        return sb.Simulator(model, integrator=integrator, dt=1 / 60, implicit_tolerance=tolerance)
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


#: skip the 2 s validity check of an integrator that would take longer than this [s]
CHECK_BUDGET = 90.0


#: the drop energy m g h [J] of the 1 kg ball from 1 m
DROP_ENERGY = 1.0 * 9.81 * 1.0


def internal_kinetic_energy(model, state) -> float:
    """Kinetic energy [J] of the particles' motion relative to the centre of mass."""
    m = model.particle_mass[:, None]
    v = state.particle_qd - (m * state.particle_qd).sum(axis=0) / m.sum()
    return 0.5 * float((m * v**2).sum())


def check_drop(model, sim) -> dict:
    """Simulate the full 2 s and check the ball stays round, bounces and is not shaking."""
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
    shaking = internal_kinetic_energy(model, state)
    ok = 0.7 < min(ratios) and max(ratios) < 1.5 and rebound > 0.05
    ok = bool(ok and shaking < 0.05 * DROP_ENERGY)
    return {
        "wall_s": wall,
        "simulated_per_wall_second": state.time / wall,
        "rebound_m": rebound,
        "volume_ratio_range": [min(ratios), max(ratios)],
        "internal_kinetic_energy_j": shaking,
        "final_height_m": float(heights[-1]),
        "ok": ok,
    }


BULLET_KPR = 10.0
#: panda3d 1.10.16's Bullet crashed (segmentation fault) on the 163,842-vertex ball here
BULLET_MAX_VERTICES = 50_000
BULLET_DT = 1.0 / 60.0


#: Bullet's position-solver iterations tried, fewest first, each with the pressure
#: coefficients BULLET_KPRS, until its ball is valid (kPR = 10 alone left every ball
#: above 642 vertices squashed below 0.6 of its volume on impact even at 128 iterations)
BULLET_ITERATIONS = (4, 8, 16, 32, 64, 128)
BULLET_KPRS = (10.0, 20.0, 40.0)
#: skip Bullet's validity check when its 2 s drop would take longer than this [s]
BULLET_CHECK_BUDGET = 90.0


class BulletDrop:
    """The same ball drop in Bullet's soft body (panda3d), z up."""

    def __init__(self, subdivisions: int, iterations: int = 4, kpr: float = BULLET_KPR):
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
        cfg.setPressureCoefficient(kpr)
        cfg.setDampingCoefficient(0.01)
        cfg.setPositionsSolverIterations(iterations)
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


def bullet_steps_per_second(subdivisions: int, iterations: int) -> tuple[float, int]:
    """Bullet's steps per second (best of 3 windows of >= 0.5 s) and its node count."""
    best = 0.0
    for _ in range(3):
        drop = BulletDrop(subdivisions, iterations)
        drop.step(1)
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < 0.5 or n < 2:
            drop.step(1)
            n += 1
        best = max(best, n / (time.perf_counter() - t0))
    return best, drop.count


def bullet_full_drop(subdivisions: int, iterations: int, kpr: float = BULLET_KPR) -> dict:
    """Bullet's 2 s drop, checked like softbody's (volume and rebound)."""
    drop = BulletDrop(subdivisions, iterations, kpr)
    v0 = drop.body.getVolume()
    heights, ratios = [], []
    t0 = time.perf_counter()
    for _ in range(round(2.0 / BULLET_DT)):
        drop.step(1)
        heights.append(drop.height())
        ratios.append(drop.body.getVolume() / v0)
    wall = time.perf_counter() - t0
    heights = np.array(heights)
    bottom = int(np.argmin(heights))
    rebound = float(heights[bottom:].max() - heights[bottom])
    return {
        "wall_s": wall,
        "simulated_per_wall_second": 2.0 / wall,
        "rebound_m": rebound,
        "volume_ratio_range": [min(ratios), max(ratios)],
        "ok": bool(0.7 < min(ratios) and max(ratios) < 1.5 and rebound > 0.05),
    }


def bullet_entry(subdivisions: int) -> dict:
    """Bullet at its fewest position iterations (BULLET_ITERATIONS, each with the pressure
    coefficients BULLET_KPRS) whose 2 s drop is valid: a fair race times Bullet only with
    a ball that stays round and bounces. Tries are recorded; with none valid, the last
    try is reported with ok = False."""
    tries = []
    done = False
    for iterations in BULLET_ITERATIONS:
        rate, count = bullet_steps_per_second(subdivisions, iterations)
        for kpr in BULLET_KPRS:
            entry = {
                "position_iterations": iterations,
                "kPR": kpr,
                "dt_s": BULLET_DT,
                "steps_per_second": rate,
                "simulated_per_wall_second": rate * BULLET_DT,
                "vertex_count": count,
            }
            if 2.0 / BULLET_DT / rate > BULLET_CHECK_BUDGET:
                entry["full_drop"] = {"ok": None, "skipped": "slower than the check budget"}
                tries.append(entry)
                done = True
                break
            entry["full_drop"] = bullet_full_drop(subdivisions, iterations, kpr)
            tries.append(entry)
            if entry["full_drop"]["ok"]:
                done = True
                break
        if done:
            break
    result = dict(tries[-1])
    result["tries"] = [
        {
            "position_iterations": t["position_iterations"],
            "kPR": t["kPR"],
            "simulated_per_wall_second": t["simulated_per_wall_second"],
            "ok": t["full_drop"]["ok"],
            "volume_ratio_range": t["full_drop"].get("volume_ratio_range"),
        }
        for t in tries
    ]
    return result


#: run in a fresh process by _peak_bytes: the growth of the peak resident set [bytes] of
#: building a ball, a simulator and one step, after the same on a small ball and the
#: imports the simulator makes lazily (so that loading modules and the compiled core is
#: not counted)
_MEMORY_PROBE = """
import resource, sys, warnings
import scipy.linalg, scipy.sparse, scipy.sparse.csgraph, scipy.sparse.linalg  # lazy elsewhere
import softbody as sb
from ball_drop import ball_drop
subdivisions, integrator = int(sys.argv[1]), sys.argv[2]
implicit = sb.Integrator.parse(integrator).implicit
def step(s):
    model = ball_drop(s)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.StabilityWarning)
        sim = sb.Simulator(model, integrator=integrator, dt=1 / 60 if implicit else "auto")
    sim.run(model.state(), 1)
    return model.particle_count
step(1)
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
count = step(subdivisions)
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(1024 * (after - before), count)
"""


def _peak_bytes(subdivisions: int, integrator: str) -> tuple[int, int]:
    """Growth of the peak resident set [bytes] of building the model, a simulator
    (implicit: at 1/60 s; explicit: at the step its estimate picks) and one step, in a
    fresh process after the same on a 42-vertex ball; and the vertex count. The resident
    set counts the compiled core's buffers, which Python's tracemalloc does not see."""
    out = subprocess.run(
        [sys.executable, "-c", _MEMORY_PROBE, str(subdivisions), integrator],
        cwd=Path(__file__).parent, capture_output=True, text=True, check=True,
    )  # fmt: skip
    peak, count = out.stdout.split()
    return int(peak), int(count)


def memory_per_vertex(subdivisions: int) -> dict:
    """Peak memory per vertex [bytes] of the implicit Euler simulator (model, multigrid
    hierarchy, one step) and of an explicit one (velocity Verlet: model, its stability
    estimate's Lanczos runs, one step), each in a fresh process (_peak_bytes)."""
    out = {}
    for integrator in ("implicit_euler", "velocity_verlet"):
        peak, count = _peak_bytes(subdivisions, integrator)
        out[integrator] = peak / count
    return out


#: the ball (10,242 vertices) on which the CG tolerance's error is measured
TOLERANCE_CHECK_SUBDIVISIONS = 5
#: the tight CG tolerance the looser ones are compared with
TIGHT_TOLERANCE = 1e-6


def _drop_track(model, integrator: str, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre-of-mass height [m] and volume / start volume after every 1/60 s step of the
    2 s drop."""
    sim = sb.Simulator(
        model,
        integrator=integrator,
        dt=1 / 60,
        implicit_tolerance=tolerance,
        implicit_max_iterations=1000,
    )
    state = model.state()
    v0 = sb.body_volume(model, state)[0]
    heights, ratios = [], []
    while state.time < 2.0 - 1e-9:
        sim.run(state, 1)
        heights.append(sb.body_center_of_mass(model, state)[0, 1])
        ratios.append(sb.body_volume(model, state)[0] / v0)
    return np.array(heights), np.array(ratios)


def tolerance_error(subdivisions: int) -> dict:
    """What an inexact CG solve costs: for each implicit scheme, the largest difference over
    the 2 s drop in centre-of-mass height [m] and in volume / start volume between its run
    at each benchmark tolerance and at TIGHT_TOLERANCE; for scale, the difference in height
    between the two schemes themselves (both tight), a measure of their own time error."""
    model = ball_drop(subdivisions)
    result = {"vertex_count": model.particle_count, "tight_tolerance": TIGHT_TOLERANCE}
    tight = {}
    for integrator in ("implicit_euler", "bdf2"):
        tight[integrator] = _drop_track(model, integrator, TIGHT_TOLERANCE)
        for tolerance in (IMPLICIT_TOLERANCE, LOOSE_TOLERANCE):
            heights, ratios = _drop_track(model, integrator, tolerance)
            result[f"{integrator} cg {tolerance:g}"] = {
                "max_height_difference_m": float(np.abs(heights - tight[integrator][0]).max()),
                "max_volume_ratio_difference": float(np.abs(ratios - tight[integrator][1]).max()),
            }
    result["schemes_max_height_difference_m"] = float(
        np.abs(tight["implicit_euler"][0] - tight["bdf2"][0]).max()
    )
    print("CG tolerance error:", result, flush=True)
    return result


def measure(model, name: str, substeps: int | None = None) -> dict:
    """A run's rate (steps_per_second) and, within CHECK_BUDGET, its checked 2 s drop."""
    sim = simulator(model, name, substeps)
    rate = steps_per_second(model, sim)
    entry = {
        "dt_s": sim.dt,
        "steps_per_second": rate,
        "simulated_per_wall_second": rate * sim.dt,
        "vertex_steps_per_second": rate * model.particle_count,
    }
    if sim.integrator == sb.Integrator.XPBD:
        entry["xpbd_substeps"] = sim.solver.substeps
        entry["xpbd_iterations"] = sim.solver.iterations_per_substep
        entry["xpbd_relaxation"] = sim.solver.relaxation
    if 2.0 / entry["simulated_per_wall_second"] <= CHECK_BUDGET:
        entry["full_drop"] = check_drop(model, sim)
    return entry


def xpbd_fewest_valid(model, name: str = "xpbd fewest valid") -> dict:
    """XPBD (run ``name``) at the fewest substeps of XPBD_SUBSTEPS whose drop is valid
    (check_drop) and rebounds >= XPBD_REBOUND; the tries recorded. With none valid (or the
    next too slow to check), the last try is reported, its drop not ok."""
    tries = []
    for substeps in XPBD_SUBSTEPS:
        entry = measure(model, name, substeps)
        drop = entry.get("full_drop")
        tries.append({
            "xpbd_substeps": substeps,
            "simulated_per_wall_second": entry["simulated_per_wall_second"],
            "ok": drop["ok"] if drop else None,
            "rebound_m": drop["rebound_m"] if drop else None,
            "volume_ratio_range": drop["volume_ratio_range"] if drop else None,
        })  # fmt: skip
        if drop is None:
            break
        if drop["ok"] and drop["rebound_m"] >= XPBD_REBOUND:
            break
    if entry.get("full_drop") and entry["full_drop"]["rebound_m"] < XPBD_REBOUND:
        entry["full_drop"]["ok"] = False
    entry["tries"] = tries
    return entry


def merge(rows: list[dict], names: list[str]) -> dict:
    """The last results/ball_drop.json with the runs ``names`` of ``rows`` written into the
    rows of the same vertex counts (rows of new sizes appended), everything else kept."""
    result = json.loads((RESULTS / "ball_drop.json").read_text())
    by_count = {r["vertex_count"]: r for r in result["sizes"]}
    for row in rows:
        old = by_count.get(row["vertex_count"])
        if old is None:
            result["sizes"].append(row)
            continue
        for name in names:
            old["integrators"][name] = row["integrators"][name]
    result["sizes"].sort(key=lambda r: r["vertex_count"])
    result[f"{'+'.join(names)} measured"] = time.strftime("%Y-%m-%d")
    result["largest_realtime_vertex_count"] = largest_realtime(result["sizes"])
    return result


def largest_realtime(rows: list[dict]) -> dict:
    """Per run, the most vertices whose checked drop ran at real time or faster."""
    realtime = {}
    for name in RUNS:
        good = [
            r["vertex_count"]
            for r in rows
            if r["integrators"].get(name, {}).get("full_drop", {}).get("ok")
            and r["integrators"][name]["full_drop"]["simulated_per_wall_second"] >= 1.0
        ]
        realtime[name] = max(good) if good else 0
    bullet_ok = [
        r["vertex_count"]
        for r in rows
        if r.get("bullet", {}).get("full_drop", {}).get("ok")
        and r["bullet"]["full_drop"]["simulated_per_wall_second"] >= 1.0
    ]
    if any("bullet" in r for r in rows):
        realtime["bullet"] = max(bullet_ok) if bullet_ok else 0
    return realtime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--min-subdivisions", type=int, default=2)
    parser.add_argument("--max-subdivisions", type=int, default=7)
    parser.add_argument(
        "--plot-only", action="store_true", help="redraw the plot from results/ball_drop.json"
    )
    parser.add_argument(
        "--memory-only", action="store_true",
        help="measure the memory per vertex again into results/ball_drop.json",
    )  # fmt: skip
    parser.add_argument(
        "--runs", nargs="+", choices=list(RUNS), default=None,
        help="measure only these runs and merge them into results/ball_drop.json",
    )  # fmt: skip
    args = parser.parse_args()
    names = list(RUNS) if args.runs is None else args.runs
    subset = args.runs is not None
    if args.plot_only:
        plot(json.loads((RESULTS / "ball_drop.json").read_text()), RESULTS / "ball_drop.png")
        return
    if args.memory_only:
        result = json.loads((RESULTS / "ball_drop.json").read_text())
        for row in result["sizes"]:
            subdivisions = round(float(np.log2((row["vertex_count"] - 2) / 10)) / 2)
            row["peak_bytes_per_vertex"] = memory_per_vertex(subdivisions)
            print(row["vertex_count"], row["peak_bytes_per_vertex"], flush=True)
        result["memory_measured"] = time.strftime("%Y-%m-%d")
        write_json(RESULTS / "ball_drop.json", result)
        return
    rows = []
    for s in range(args.min_subdivisions, args.max_subdivisions + 1):
        model = ball_drop(s)
        row = {"vertex_count": model.particle_count, "integrators": {}}
        if not subset:
            row["peak_bytes_per_vertex"] = memory_per_vertex(s)
        for name in names:
            if name.endswith("fewest valid"):
                entry = xpbd_fewest_valid(model, name)
            else:
                entry = measure(model, name)
            row["integrators"][name] = entry
            drop = entry.get("full_drop")
            print(
                f"{model.particle_count:>7} {name:17s} dt {entry['dt_s']:.2e} s  "
                f"{entry['steps_per_second']:10.1f} steps/s  "
                f"{entry['simulated_per_wall_second']:9.4f}x real time"
                + (f"  substeps {entry['xpbd_substeps']}" if "xpbd_substeps" in entry else "")
                + (
                    f"  drop ok={drop['ok']} rebound {drop['rebound_m']:.3f} m volume "
                    f"{drop['volume_ratio_range'][0]:.3f}-{drop['volume_ratio_range'][1]:.3f}"
                    if drop
                    else ""
                ),
                flush=True,
            )
        if subset:
            rows.append(row)
            write_json(PARTIAL, run_record("ball_drop", threads=1, dtype="float64", sizes=rows))
            continue
        try:
            import panda3d.bullet  # noqa: F401

            if model.particle_count > BULLET_MAX_VERTICES:
                raise ImportError("skipped: above BULLET_MAX_VERTICES")

            row["bullet"] = bullet_entry(s)
            # the race: softbody's fastest integrator with a valid drop against Bullet at
            # its fewest iterations with a valid drop
            valid = [
                e["simulated_per_wall_second"]
                for e in row["integrators"].values()
                if e.get("full_drop", {}).get("ok")
            ]
            if valid and row["bullet"]["full_drop"]["ok"]:
                row["softbody_over_bullet"] = (
                    max(valid) / row["bullet"]["simulated_per_wall_second"]
                )
            b = row["bullet"]
            print(
                f"{model.particle_count:>7} bullet            dt {BULLET_DT:.2e} s  "
                f"{b['steps_per_second']:10.1f} steps/s  "
                f"{b['simulated_per_wall_second']:9.4f}x real time  "
                f"iterations {b['position_iterations']} kPR {b['kPR']:g}  "
                f"drop ok={b['full_drop']['ok']}"
                + (
                    f"  -> softbody/bullet = {row['softbody_over_bullet']:.3g}"
                    if "softbody_over_bullet" in row
                    else ""
                ),
                flush=True,
            )
        except ImportError:
            pass
        rows.append(row)
        write_json(PARTIAL, run_record("ball_drop", threads=1, dtype="float64", sizes=rows))
    if subset:
        result = merge(rows, names)
        print("largest real-time ball drop (vertices):", result["largest_realtime_vertex_count"])
        write_json(RESULTS / "ball_drop.json", result)
        plot(result, RESULTS / "ball_drop.png")
        PARTIAL.unlink(missing_ok=True)
        print(f"merged {names} into {RESULTS / 'ball_drop.json'} and .png")
        return
    realtime = largest_realtime(rows)
    print("largest real-time ball drop (vertices):", realtime)
    result = run_record(
        "ball_drop",
        threads=1,
        dtype="float64",
        sizes=rows,
        largest_realtime_vertex_count=realtime,
        implicit_tolerance=IMPLICIT_TOLERANCE,
        loose_tolerance=LOOSE_TOLERANCE,
        tolerance_error=tolerance_error(min(TOLERANCE_CHECK_SUBDIVISIONS, args.max_subdivisions)),
        bullet={
            "kPR_tried": list(BULLET_KPRS),
            "dt_s": BULLET_DT,
            "position_iterations_tried": list(BULLET_ITERATIONS),
        }
        if any("bullet" in r for r in rows)
        else None,
    )
    write_json(RESULTS / "ball_drop.json", result)
    plot(result, RESULTS / "ball_drop.png")
    PARTIAL.unlink(missing_ok=True)
    print(f"wrote {RESULTS / 'ball_drop.json'} and .png")


def plot(result: dict, path: Path) -> None:
    """Simulated seconds per wall second against vertices, per integrator and Bullet."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["sizes"]
    fig, ax = plt.subplots(figsize=(9, 5.5), dpi=110)

    def plot(xs, entries, style, color, label):
        ys = [e["simulated_per_wall_second"] for e in entries]
        ax.plot(xs, ys, style, color=color, label=label, markerfacecolor="none")
        good = [
            (x, y)
            for x, y, e in zip(xs, ys, entries, strict=True)
            if e.get("full_drop", {}).get("ok")
        ]
        if good:
            ax.plot([g[0] for g in good], [g[1] for g in good], style[0], color=color)

    for k, name in enumerate(RUNS):
        style = "o:" if name.endswith(" cg 1e-2") else "o-"
        have = [r for r in rows if name in r["integrators"]]
        if name.startswith("xpbd"):
            style = "D-" if name == "xpbd" else "D:"
        plot([r["vertex_count"] for r in have], [r["integrators"][name] for r in have], style,
             f"C{k}", name)  # fmt: skip
    if any("bullet" in r for r in rows):
        plot(
            [r["vertex_count"] for r in rows if "bullet" in r],
            [r["bullet"] for r in rows if "bullet" in r],
            "s--",
            "k",
            "Bullet soft body (kPR, 1/60 s, fewest valid iterations)",
        )
    ax.axhline(1.0, color="k", lw=1, ls=":", label="real time")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("vertices")
    ax.set_ylabel("simulated seconds per wall second")
    ax.set_title(
        "Ball drop (1 m, 1 kg, inflated): explicit schemes at 0.9 of their stable dt, "
        "implicit ones and xpbd at 1/60 s\n"
        "filled: the 2 s drop checked round and bouncing; hollow: failed or not checked",
        fontsize=10,
    )
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


if __name__ == "__main__":
    main()
