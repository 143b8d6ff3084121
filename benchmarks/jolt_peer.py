"""The ball drop raced against Jolt Physics' soft body (issue 33): x real time and the bounce.

The drop of ``benchmarks/ball_drop.py``: an icosphere of radius 1 m and 1 kg, springs of
500 N/m on its edges, nRT = 300 J, its centre 2 m up (1 m of fall), the ground plane y = 0
with restitution 0.5 and friction 0.1, gravity 9.81 m/s^2, 2 s in 1/60 s frames. The same
mesh, masses and settings go to Jolt Physics through its Python binding culverin
(CULVERIN, pinned), which needs Python >= 3.12: the script makes a virtual environment for
it once (``benchmarks/.peers/jolt-venv``, git-ignored; ``--peer-venv`` names an existing
one, used as it is) and runs ``benchmarks/peers/jolt_drop.py`` in it, one process per
drop. culverin is never a dependency of softbody. Jolt's side: edge compliance
1/500 m/N, pressure 300 (Jolt's pressure is n R T [J]), no bend constraints (softbody's
ball has edge springs only), vertex radius 0 and linear damping 0 (softbody's contact has
no thickness and the drop no drag; Jolt has no spring damping to match softbody's
0.5 N s/m), its solver iterations (each a substep with one pass over the edges) tried 10,
20, 40, ... fewest first until its drop is valid and rebounds >= 0.9 m, on
``--jolt-threads`` worker threads (default: the cores), and timed again on one worker at
the iterations found (the same drop).

softbody on one thread: XPBD at its default substeps ("xpbd"), XPBD at the fewest
substeps of XPBD_SUBSTEPS that are valid and rebound >= 0.9 m ("xpbd fewest valid"), the
same search with 4 passes per substep over-relaxed by 1.9 ("xpbd relaxed fewest valid"),
implicit Euler at 1/60 s (CG tolerance 1e-3, multigrid) and velocity Verlet at 0.9 of its
stable step (a whole number of steps per frame), each skipped where one drop would take
longer than ``--budget`` seconds (estimated from its first frames).

Every drop is checked the same way for both engines (``peers/drop_check.py``): the
volume within [0.7, 1.5] of its start every frame, the centre of mass rising after its
lowest point, and at the end the internal kinetic energy (velocities from the last two
frames' positions, for both engines) below 5% of m g h; a race entry also needs a
rebound >= 0.9 m. Speed is simulated seconds per wall second of the stepping calls alone
(2 s over their summed wall time). After the searches, ``--rounds`` timing rounds
alternate the engines (Jolt first, then softbody first, ...) wherever a drop takes at most
ROUND_BUDGET seconds; each entry keeps its best time. The ratio softbody / Jolt per size
compares the fastest softbody run that passes with the bounce kept with Jolt at its
fewest valid iterations: taken within each round (the load of the shared machine changes
from minute to minute) and the median of the rounds reported, the ratio of the best times
beside it.

Writes results/jolt_peer.{json,png}; after each size, results/jolt_peer.partial.json.
Usage: python benchmarks/jolt_peer.py [--max-subdivisions 6] [--peer-python PATH]
"""

from __future__ import annotations

import argparse
import glob
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

import softbody as sb
from ball_drop import XPBD_RELAXED, XPBD_SUBSTEPS, ball_drop
from peers.drop_check import drop_verdict, internal_kinetic_energy
from results_io import RESULTS, run_record, save_figure, write_json

HERE = Path(__file__).parent
#: the Jolt binding, pinned so that every run measures the same Jolt
CULVERIN = "culverin==0.15.0"
#: the oldest Python culverin installs on
PEER_PYTHON_MIN = (3, 12)
#: where the script makes the peer's environment (git-ignored)
PEER_VENV = HERE / ".peers" / "jolt-venv"
#: the child script run in the peer's environment
JOLT_CHILD = HERE / "peers" / "jolt_drop.py"
#: Jolt's solver iterations per step tried, fewest first
JOLT_ITERATIONS = (10, 20, 40, 80, 160, 320)
#: the frame both engines step
FRAME = 1.0 / 60.0
FRAMES = 120
#: the drop energy m g h [J] of the 1 kg ball from 1 m
DROP_ENERGY = 1.0 * 9.81 * 1.0
#: the alternating timing rounds time only drops faster than this [s]
ROUND_BUDGET = 30.0
PARTIAL = RESULTS / "jolt_peer.partial.json"

#: softbody's runs: name -> Simulator options (dt: the frame, or "0.9 x stable")
SOFTBODY_RUNS = {
    "xpbd": {"integrator": "xpbd"},
    "xpbd fewest valid": {"integrator": "xpbd"},
    "xpbd relaxed fewest valid": {"integrator": "xpbd", **XPBD_RELAXED},
    "implicit_euler": {"integrator": "implicit_euler", "implicit_tolerance": 1e-3},
    "velocity_verlet": {"integrator": "velocity_verlet"},
}


class PeerError(RuntimeError):
    """The peer engine cannot be run: no suitable Python, or its install failed."""


def python_version(python: str) -> tuple[int, int] | None:
    """(major, minor) of the Python interpreter at ``python``, or None where it does not
    run."""
    try:
        out = subprocess.run(
            [python, "-c", "import sys; print(*sys.version_info[:2])"],
            capture_output=True, text=True, timeout=60, check=True,
        )  # fmt: skip
        major, minor = out.stdout.split()
        return int(major), int(minor)
    except (OSError, subprocess.SubprocessError, ValueError):
        return None


def python_candidates() -> list[str]:
    """Interpreters that may be Python >= 3.12: python3.12 ... on PATH, then pyenv's."""
    found = [shutil.which(f"python3.{minor}") for minor in range(12, 20)]
    pyenv = sorted(glob.glob(os.path.expanduser("~/.pyenv/versions/3.1[2-9]*/bin/python")))
    return [p for p in found if p] + pyenv


def find_peer_python(
    candidates: Sequence[str],
    version: Callable[[str], tuple[int, int] | None] = python_version,
) -> str:
    """The first of ``candidates`` that is Python >= PEER_PYTHON_MIN; PeerError naming
    what to do where none is."""
    for python in candidates:
        v = version(python)
        if v is not None and v >= PEER_PYTHON_MIN:
            return python
    tried = ", ".join(candidates) if candidates else "no python3.12+ on PATH or in ~/.pyenv"
    raise PeerError(
        f"Jolt's binding {CULVERIN} needs Python >= 3.12 and none was found (tried: {tried});"
        " install one (e.g. `pyenv install 3.12`) or pass --peer-python PATH"
    )


def ensure_peer_venv(python: str, venv: Path) -> Path:
    """The Python of the peer's environment at ``venv``, made with ``python`` and
    CULVERIN and NumPy installed where it is not there yet (a marker file records the pin
    it holds). PeerError with pip's last line where the install fails."""
    peer = venv / "bin" / "python"
    marker = venv / "softbody-peer.txt"
    if peer.exists() and marker.exists() and marker.read_text().strip() == CULVERIN:
        return peer
    steps = [[python, "-m", "venv", str(venv)]] if not peer.exists() else []
    steps.append([str(peer), "-m", "pip", "install", "--quiet", CULVERIN, "numpy"])
    for command in steps:
        out = subprocess.run(command, capture_output=True, text=True)
        if out.returncode != 0:
            lines = (out.stderr or out.stdout).strip().splitlines()
            raise PeerError(
                f"installing {CULVERIN} into {venv} failed ({lines[-1] if lines else 'no output'});"
                f" check that PyPI is reachable, or pass --peer-venv to an environment that"
                f" has {CULVERIN} and numpy"
            )
    marker.write_text(CULVERIN + "\n")
    return peer


def peer_version(peer: Path) -> str:
    """culverin's version string as the peer's Python at ``peer`` reports it (its Jolt
    build: precision, threading); PeerError where that Python cannot import culverin and
    NumPy, or holds another version than CULVERIN pins."""
    probe = "import culverin, numpy; print(culverin.__version__)"
    try:
        out = subprocess.run([str(peer), "-c", probe], capture_output=True, text=True)
    except OSError as error:
        raise PeerError(f"cannot run the peer's Python {peer} ({error.strerror})") from None
    if out.returncode != 0:
        lines = out.stderr.strip().splitlines() or ["no output"]
        raise PeerError(
            f"{peer} cannot import culverin and numpy ({lines[-1]}); install {CULVERIN} and"
            " numpy there, or leave out --peer-venv to let the script make its environment"
        )
    version = out.stdout.strip()
    if version.split()[0] != CULVERIN.split("==")[1]:
        raise PeerError(f"{peer} has culverin {version.split()[0]}; the race pins {CULVERIN}")
    return version


def fewest_valid(counts: Sequence[int], drop: Callable[[int], dict | None]) -> tuple[dict, list]:
    """Try ``drop(count)`` for each of ``counts``, fewest first, until one is ``ok`` (valid
    and the bounce kept); ``drop`` returns None where the count is too slow to run. Returns
    the last entry run (ok or not) and the tries, each ``{"count", "ok", "rebound_m",
    "volume_ratio_range", "simulated_per_wall_second"}``."""
    tries: list[dict] = []
    entry: dict | None = None
    for count in counts:
        result = drop(count)
        if result is None:
            tries.append({"count": count, "ok": None, "skipped": "slower than the budget"})
            break
        entry = result
        tries.append({
            "count": count,
            "ok": entry["ok"],
            "rebound_m": entry["rebound_m"],
            "volume_ratio_range": entry["volume_ratio_range"],
            "simulated_per_wall_second": entry.get("simulated_per_wall_second"),
        })  # fmt: skip
        if entry["ok"]:
            break
    if entry is None:
        return {"ok": None, "skipped": "slower than the budget"}, tries
    return entry, tries


def paired_ratios(rates: dict[str, list[float]], passing: Sequence[str], jolt: str) -> list:
    """Per timing round, softbody's rate over Jolt's in that round: the fastest of the
    ``passing`` runs' rates (simulated seconds per wall second) over the rate of the Jolt
    entry ``jolt``; ``rates`` maps each entry to its rates, one per round it was timed in.
    Rounds where Jolt or no passing run was timed are left out."""
    out = []
    for k, jolt_rate in enumerate(rates.get(jolt, [])):
        mine = [rates[name][k] for name in passing if len(rates.get(name, [])) > k]
        if mine:
            out.append(max(mine) / jolt_rate)
    return out


def speed_ratio(softbody: dict, jolt: dict) -> float | None:
    """softbody's simulated seconds per wall second over Jolt's: the fastest of softbody's
    runs that passes with the bounce kept against Jolt's entry, where both pass."""
    good = [e["simulated_per_wall_second"] for e in softbody.values() if e.get("ok")]
    if not good or not jolt.get("ok"):
        return None
    return max(good) / jolt["simulated_per_wall_second"]


class SoftbodyDrop:
    """softbody's side: a run of SOFTBODY_RUNS on one ball."""

    def __init__(self, model: sb.Model, name: str, substeps: int | None = None):
        options = dict(SOFTBODY_RUNS[name])
        self.model, self.name = model, name
        if options["integrator"] == "velocity_verlet":
            stable = sb.Simulator(model, integrator="velocity_verlet", dt=1e-6).stable_dt
            self.steps = math.ceil(FRAME / (0.9 * stable))
        else:
            self.steps = 1
            if substeps is not None:
                options["xpbd_substeps"] = substeps
        self.sim = sb.Simulator(model, dt=FRAME / self.steps, **options)

    def settings(self) -> dict:
        out = {"dt_s": self.sim.dt, "steps_per_frame": self.steps}
        if self.sim.integrator == sb.Integrator.XPBD:
            out["xpbd_substeps"] = self.sim.solver.substeps
        return out

    def estimate(self) -> float:
        """Wall seconds [s] a 2 s drop would take, from its first frames (>= 0.3 s)."""
        state = self.model.state()
        n, t0 = 0, time.perf_counter()
        while n < 2 or time.perf_counter() - t0 < 0.3:
            self.sim.run(state, self.steps)
            n += 1
            if n >= FRAMES:
                break
        return (time.perf_counter() - t0) / n * FRAMES

    def drop(self) -> dict:
        """The 2 s drop: the checks and the wall time of the stepping calls; a drop that
        blows up (SimulationError) fails, with no speed."""
        try:
            return self._drop()
        except sb.SimulationError as error:
            return {**self.settings(), "error": str(error), "rebound_m": None,
                    "volume_ratio_range": [None, None], "valid": False, "ok": False}  # fmt: skip

    def _drop(self) -> dict:
        model, state = self.model, self.model.state()
        x = state.particle_q.copy()
        heights = [sb.body_center_of_mass(model, state)[0, 1]]
        volumes = [sb.body_volume(model, state)[0]]
        wall = 0.0
        for _ in range(FRAMES):
            x_prev = x
            t0 = time.perf_counter()
            self.sim.run(state, self.steps)
            wall += time.perf_counter() - t0
            x = state.particle_q.copy()
            heights.append(sb.body_center_of_mass(model, state)[0, 1])
            volumes.append(sb.body_volume(model, state)[0])
        masses = model.particle_mass
        resting = internal_kinetic_energy((x - x_prev) / FRAME, masses)
        entry = drop_verdict(np.array(heights), np.array(volumes), resting, DROP_ENERGY)
        entry["internal_kinetic_energy_state_j"] = internal_kinetic_energy(
            state.particle_qd, masses
        )
        return {**self.settings(), **timing(wall), **entry}


def timing(wall: float) -> dict:
    """A drop's wall time [s] of stepping and simulated seconds per wall second."""
    return {"wall_s": wall, "simulated_per_wall_second": FRAMES * FRAME / wall}


class JoltDrop:
    """Jolt's side: the child script in the peer's Python, one process per drop."""

    def __init__(self, peer: Path, model: sb.Model, subdivisions: int, folder: Path,
                 threads: int):  # fmt: skip
        mesh = sb.icosphere(subdivisions, radius=1.0)
        if mesh.vertices.shape[0] != model.particle_count:
            raise RuntimeError("the Jolt mesh and softbody's ball differ in vertex count")
        self.peer, self.folder, self.threads = peer, folder, threads
        self.mesh_path = folder / f"ball{subdivisions}.npz"
        # softbody's ball is this mesh moved up 2 m, with these masses
        np.testing.assert_allclose(mesh.vertices + np.array([0.0, 2.0, 0.0]), model.particle_q)
        np.savez(self.mesh_path, vertices=mesh.vertices, faces=mesh.faces,
                 masses=model.particle_mass)  # fmt: skip

    def settings(self, iterations: int) -> dict:
        return {
            "height": 2.0, "frames": FRAMES, "dt": FRAME, "iterations": iterations,
            "compliance": 1.0 / 500.0, "pressure": 300.0, "restitution": 0.5,
            "friction": 0.1, "linear_damping": 0.0, "vertex_radius": 0.0,
            "threads": self.threads,
        }  # fmt: skip

    def drop(self, iterations: int, timeout: float) -> dict | None:
        """Jolt's 2 s drop at ``iterations``: the checks and the stepping's wall time; None
        where it runs past ``timeout`` [s]."""
        settings_path = self.folder / "settings.json"
        out_path = self.folder / "out.json"
        settings_path.write_text(json.dumps(self.settings(iterations)))
        out_path.unlink(missing_ok=True)
        try:
            run = subprocess.run(
                [str(self.peer), str(JOLT_CHILD), str(self.mesh_path), str(settings_path),
                 str(out_path)],
                capture_output=True, text=True, timeout=timeout,
            )  # fmt: skip
        except subprocess.TimeoutExpired:
            return None
        if run.returncode != 0:
            last = (run.stderr.strip().splitlines() or ["no output"])[-1]
            raise PeerError(f"Jolt's drop failed at {iterations} iterations: {last}")
        out = json.loads(out_path.read_text())
        entry = drop_verdict(
            np.array(out["heights_m"]), np.array(out["volumes_m3"]),
            out["internal_kinetic_energy_j"], DROP_ENERGY,
        )  # fmt: skip
        return {"iterations": iterations, "threads": self.threads, **timing(out["wall_s"]),
                **entry}  # fmt: skip


def best(entry: dict, again: dict) -> dict:
    """``entry`` with the faster of its time and ``again``'s (the same settings, so the
    same drop), and the count of timings."""
    out = dict(entry)
    out["timings"] = entry.get("timings", 1) + 1
    if again["wall_s"] < entry["wall_s"]:
        out.update(timing(again["wall_s"]))
    return out


def race_size(s: int, peer: Path, folder: Path, args: argparse.Namespace) -> dict:
    """One size: the searches, the other runs, then the alternating timing rounds."""
    model = ball_drop(s)
    n = model.particle_count
    row: dict = {"vertex_count": n, "softbody": {}}
    jolt = JoltDrop(peer, model, s, folder, args.jolt_threads)

    def jolt_drop(iterations: int) -> dict | None:
        entry = jolt.drop(iterations, args.budget)
        report(n, f"jolt {iterations} it.", entry)
        return entry

    def xpbd_drop(substeps: int, name: str = "xpbd fewest valid") -> dict | None:
        run = SoftbodyDrop(model, name, substeps)
        try:
            if run.estimate() > args.budget:
                return None
        except sb.SimulationError:
            pass  # it blows up within its first frames: drop() records that
        entry = run.drop()
        report(n, f"{name.removesuffix(' fewest valid')} {substeps} substeps", entry)
        return entry

    row["jolt"], row["jolt_tries"] = fewest_valid(JOLT_ITERATIONS, jolt_drop)
    # the same Jolt drop on one worker thread: Jolt's steps do not depend on the thread
    # count, its speed on a shared machine does
    jolt_one = JoltDrop(peer, model, s, folder, 1) if args.jolt_threads != 1 else None
    if jolt_one is not None and "iterations" in row["jolt"]:
        row["jolt_one_worker"] = jolt_one.drop(row["jolt"]["iterations"], args.budget)
        report(n, f"jolt {row['jolt']['iterations']} it., 1 worker", row["jolt_one_worker"])
    for name in ("xpbd fewest valid", "xpbd relaxed fewest valid"):
        entry, tries = fewest_valid(args.xpbd_substeps, lambda k, name=name: xpbd_drop(k, name))
        row["softbody"][name] = {**entry, "tries": tries}
    for name in ("xpbd", "implicit_euler", "velocity_verlet"):
        run = SoftbodyDrop(model, name)
        try:
            estimate = run.estimate()
        except sb.SimulationError:
            estimate = 0.0  # it blows up within its first frames: drop() records that
        if estimate > args.budget:
            row["softbody"][name] = {**run.settings(), "ok": None, "estimated_wall_s": estimate,
                                     "skipped": "slower than the budget"}  # fmt: skip
            print(f"{n:>7} {name:24s} skipped: about {estimate:.0f} s per drop", flush=True)
            continue
        row["softbody"][name] = run.drop()
        report(n, name, row["softbody"][name])

    # alternating timing rounds, each engine's entries at their chosen settings; each
    # round's rates are kept, so that the ratio can be taken within a round (the machine's
    # load changes from one minute to the next)
    rates: dict[str, list[float]] = {}
    for k in range(args.rounds):
        for side in ("softbody", "jolt") if k % 2 else ("jolt", "softbody"):
            if side == "jolt":
                for key, engine in (("jolt", jolt), ("jolt_one_worker", jolt_one)):
                    j = row.get(key) or {}
                    if "wall_s" in j and j["wall_s"] <= ROUND_BUDGET:
                        again = engine.drop(j["iterations"], args.budget)
                        if again is not None:
                            row[key] = best(j, again)
                            rates.setdefault(key, []).append(again["simulated_per_wall_second"])
                continue
            for name, e in row["softbody"].items():
                if "wall_s" in e and e["wall_s"] <= ROUND_BUDGET:
                    again = SoftbodyDrop(model, name, e.get("xpbd_substeps")).drop()
                    row["softbody"][name] = best(e, again)
                    if "simulated_per_wall_second" in again:
                        rates.setdefault(name, []).append(again["simulated_per_wall_second"])
    row["round_rates"] = rates
    passing = [name for name, e in row["softbody"].items() if e.get("ok")]
    row["softbody_over_jolt"] = None
    for suffix, key in (("", "jolt"), ("_one_worker", "jolt_one_worker")):
        if not (row.get(key) or {}).get("ok"):
            continue
        # the ratio of the best times, and the median of the ratios within a round
        row[f"softbody_over_jolt{suffix}_best"] = speed_ratio(row["softbody"], row[key])
        paired = paired_ratios(rates, passing, key)
        row[f"softbody_over_jolt{suffix}_rounds"] = paired
        row[f"softbody_over_jolt{suffix}"] = (
            float(np.median(paired)) if paired else row[f"softbody_over_jolt{suffix}_best"]
        )
    return row


def report(n: int, name: str, entry: dict | None) -> None:
    if entry is None:
        print(f"{n:>7} {name:24s} skipped: slower than the budget", flush=True)
        return
    if entry["rebound_m"] is None:
        print(f"{n:>7} {name:24s} blew up", flush=True)
        return
    low, high = entry["volume_ratio_range"]
    print(
        f"{n:>7} {name:24s} {entry['simulated_per_wall_second']:8.3f}x real time  rebound "
        f"{entry['rebound_m']:.3f} m  volume {low:.3f}-{high:.3f}  resting KE "
        f"{entry['internal_kinetic_energy_j']:.3f} J  valid={entry['valid']} ok={entry['ok']}",
        flush=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--min-subdivisions", type=int, default=3)
    parser.add_argument("--max-subdivisions", type=int, default=6)
    parser.add_argument("--peer-python", help="a Python >= 3.12 to make the peer's venv with")
    parser.add_argument(
        "--peer-venv",
        type=Path,
        help=f"an environment holding {CULVERIN} and numpy, used as it is (by default the"
        f" script makes {PEER_VENV.relative_to(HERE.parent)} once)",
    )
    parser.add_argument(
        "--jolt-threads",
        type=int,
        default=os.cpu_count() or 1,
        help="Jolt's worker threads (default: the cores)",
    )
    parser.add_argument("--rounds", type=int, default=3, help="alternating timing rounds")
    parser.add_argument(
        "--budget",
        type=float,
        default=150.0,
        help="skip a drop estimated to take longer than this [s]",
    )
    parser.add_argument(
        "--xpbd-substeps",
        type=int,
        nargs="+",
        default=list(XPBD_SUBSTEPS),
        help="XPBD substeps tried by 'xpbd fewest valid', fewest first",
    )
    parser.add_argument(
        "--plot-only", action="store_true", help="redraw the plot from results/jolt_peer.json"
    )
    args = parser.parse_args()
    if not 0 <= args.min_subdivisions <= args.max_subdivisions:
        parser.error("the sizes need 0 <= --min-subdivisions <= --max-subdivisions")
    if args.plot_only:
        plot(json.loads((RESULTS / "jolt_peer.json").read_text()), RESULTS / "jolt_peer.png")
        return
    try:
        if args.peer_venv is not None:
            peer = args.peer_venv / "bin" / "python"
        else:
            python = args.peer_python or find_peer_python(python_candidates())
            if args.peer_python and (python_version(python) or (0, 0)) < PEER_PYTHON_MIN:
                raise PeerError(f"--peer-python {python} is not Python >= 3.12")
            peer = ensure_peer_venv(python, PEER_VENV)
        build = peer_version(peer)
    except PeerError as error:
        sys.exit(f"error: {error}")
    rows = []
    command = "python benchmarks/jolt_peer.py " + " ".join(sys.argv[1:])
    head = {
        "command": command.strip(),
        "threads": {"softbody": 1, "jolt_workers": args.jolt_threads},
        "dtype": "float64 (softbody); float32 vertices, float64 world (Jolt)",
        "peer": CULVERIN,
        "peer_build": build,
        "frame_s": FRAME,
        "drop_s": FRAMES * FRAME,
        "jolt_iterations_tried": list(JOLT_ITERATIONS),
        "xpbd_substeps_tried": args.xpbd_substeps,
        "rounds": args.rounds,
    }
    with tempfile.TemporaryDirectory() as folder:
        for s in range(args.min_subdivisions, args.max_subdivisions + 1):
            try:
                rows.append(race_size(s, peer, Path(folder), args))
            except PeerError as error:
                sys.exit(f"error: {error}")
            r = rows[-1]
            print(f"{r['vertex_count']:>7} softbody / Jolt = {r['softbody_over_jolt']} (rounds: "
                  f"{r.get('softbody_over_jolt_rounds')}; best times: "
                  f"{r.get('softbody_over_jolt_best')}; 1 worker: "
                  f"{r.get('softbody_over_jolt_one_worker')})", flush=True)  # fmt: skip
            write_json(PARTIAL, run_record("jolt_peer", **head, sizes=rows))
    result = run_record("jolt_peer", **head, sizes=rows)
    write_json(RESULTS / "jolt_peer.json", result)
    plot(result, RESULTS / "jolt_peer.png")
    PARTIAL.unlink(missing_ok=True)
    print(f"wrote {RESULTS / 'jolt_peer.json'} and .png")


def plot(result: dict, path: Path) -> None:
    """Left: simulated seconds per wall second against vertices, softbody's runs and Jolt
    (filled: valid with the bounce kept). Right: the rebound, with the 0.9 m the race
    asks for."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["sizes"]
    fig, (speed, bounce) = plt.subplots(1, 2, figsize=(12, 5.3), dpi=110)
    lines = [(name, "softbody " + name, f"C{k}", "o-") for k, name in enumerate(SOFTBODY_RUNS)]
    lines.append(("jolt", f"Jolt ({result['threads']['jolt_workers']} workers), fewest valid "
                  "iterations", "k", "s--"))  # fmt: skip
    lines.append(("jolt_one_worker", "Jolt (1 worker), the same iterations", "0.5", "s:"))
    for key, label, color, style in lines:
        pts = []
        for r in rows:
            e = r.get(key) or {} if key.startswith("jolt") else r["softbody"].get(key, {})
            if "simulated_per_wall_second" in e:
                pts.append((r["vertex_count"], e))
        if not pts:
            continue
        xs = [p[0] for p in pts]
        if key == "jolt":
            label += ": " + ", ".join(str(p[1]["iterations"]) for p in pts)
        elif key in ("xpbd fewest valid", "xpbd relaxed fewest valid"):
            label += ": " + ", ".join(str(p[1]["xpbd_substeps"]) for p in pts) + " substeps"
        for ax, field in ((speed, "simulated_per_wall_second"), (bounce, "rebound_m")):
            have = [(x, p[1]) for x, p in zip(xs, pts, strict=True) if p[1][field] is not None]
            ys = [e[field] for _, e in have]
            ax.plot([x for x, _ in have], ys, style, color=color, label=label,
                    markerfacecolor="none")  # fmt: skip
            good = [(x, e[field]) for x, e in have if e["ok"]]
            if good:
                ax.plot(*zip(*good, strict=True), style[0], color=color)
    speed.axhline(1.0, color="k", lw=1, ls=":")
    bounce.axhline(0.9, color="k", lw=1, ls=":")
    for ax in (speed, bounce):
        ax.set_xscale("log")
        ax.set_xlabel("vertices")
        ax.grid(alpha=0.3, which="both")
    speed.set_yscale("log")
    speed.set_ylabel("simulated seconds per wall second")
    bounce.set_ylabel("rebound of the centre of mass after its lowest point [m]")
    speed.legend(fontsize=7)

    def ratios(key: str) -> str:
        return ", ".join(
            f"{r['vertex_count']:,}: {r[key]:.2f}x" if r.get(key) else f"{r['vertex_count']:,}: -"
            for r in rows
        )

    fig.suptitle(
        "Ball drop at 1/60 s frames, softbody (one thread) against Jolt Physics (culverin); "
        "filled: valid, rebound >= 0.9 m\n"
        "softbody (fastest passing run) / Jolt, median of the ratios within a timing round "
        "(the points: best times)\n"
        f"against Jolt on {result['threads']['jolt_workers']} workers: "
        f"{ratios('softbody_over_jolt')}; on 1 worker: "
        f"{ratios('softbody_over_jolt_one_worker')}",
        fontsize=10,
    )
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


if __name__ == "__main__":
    main()
