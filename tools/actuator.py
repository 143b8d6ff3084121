"""Draw a pneumatic bending actuator curling as it is inflated (docs/guide/membranes.md).

    python tools/actuator.py [OUT.png]   (default docs/images/actuator.png)

The bending-actuator scene (softbody run bending-actuator), measured. A soft-robot
finger as such grippers are built: a closed box chamber 2 x 10 x 2 cm of
soft silicone (neo-Hookean, mu = 39 kPa, Ecoflex 00-30's; 2 mm thick), one long side
bonded to an inextensible layer (a StVK sheet of E H = 100 kN/m, paper), its base clamped
(every base vertex pinned). The gas pressure rises slowly from 0 to 5.5 kPa over 4 s
(implicit Euler at 2 ms, damped: nearly static). The free side lengthens and the bonded
one cannot, so the finger curls toward the layer. Left: the tip's angle (the normal of its
end face) against the pressure; right: the finger's centreline (the mean of each
cross-section of the mesh) at a few pressures. Past
about 6 kPa the silicone balloons past the peak of its curve and the finger runs away.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import softbody as sb
from softbody.scenes import load_scene

SCENE = "bending-actuator"
LENGTH = 0.1  # the chamber's length [m]: its base at y = -LENGTH / 2, its tip at +LENGTH / 2


def finger() -> tuple[sb.Model, np.ndarray]:
    """The actuator's model (the bending-actuator scene) and the particles of its free end
    face."""
    model = load_scene(SCENE).model
    return model, np.flatnonzero(model.particle_q[:, 1] > LENGTH / 2 - 1e-9)


def tip_angle(q: np.ndarray, tip: np.ndarray) -> float:
    """The tip's rotation [deg] about z: its end face's normal against +y."""
    centred = q[tip] - q[tip].mean(axis=0)
    n = np.linalg.svd(centred)[2][-1]
    n = n if n[1] > 0 else -n
    return float(np.degrees(np.arctan2(-n[0], n[1])))


def main(out: Path) -> None:
    scene = load_scene(SCENE)
    model, tip = finger()
    sim = sb.Simulator(model, integrator=scene.integrator, dt=scene.dt)
    state = model.state()
    pressures, angles, shapes = [0.0], [0.0], {}
    for k in range(1, 41):
        sim.advance(state, scene.duration / 40, progress=False)
        pressures.append(float(sb.body_pressure(model, state)[0]))
        angles.append(tip_angle(state.particle_q, tip))
        if k in (10, 20, 30, 40):
            shapes[pressures[-1]] = state.particle_q.copy()

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4.2))
    left.plot(np.array(pressures) / 1e3, angles, "o-", ms=3)
    left.set_xlabel("gauge pressure [kPa]")
    left.set_ylabel("tip angle [deg]")
    left.set_title("tip angle against pressure")
    rest = model.particle_q
    levels = np.round(rest[:, 1] / (LENGTH / 16)).astype(int)  # the mesh's cross-sections

    def centreline(q):  # the mean of each cross-section's vertices [cm]
        return np.array([q[levels == k].mean(axis=0) for k in np.unique(levels)]) * 100

    for p, q in ((0.0, rest), *shapes.items()):
        line = centreline(q)
        right.plot(line[:, 0], line[:, 1], "-", lw=2, label=f"{p / 1e3:.2f} kPa")
    right.set_aspect("equal")
    right.set_xlabel("x [cm] (the paper layer on the -x side)")
    right.set_ylabel("y [cm] (base clamped at -5)")
    right.set_title("centreline, side view")
    right.legend(fontsize=8)
    fig.suptitle("A pneumatic bending actuator: silicone chamber with a strain-limiting layer")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"{out}: tip angle {angles[-1]:.1f} deg at {pressures[-1]:.0f} Pa")


if __name__ == "__main__":
    root = Path(__file__).resolve().parents[1]
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else root / "docs" / "images" / "actuator.png")
