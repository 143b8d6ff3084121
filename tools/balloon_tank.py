"""Draw a rubber balloon inflated from a tank through the peak of its curve
(docs/guide/membranes.md): the balloon-tank scene (softbody run balloon-tank), measured.

    python tools/balloon_tank.py [OUT.png]   (default docs/images/balloon-tank.png)

A party balloon (a neo-Hookean membrane on a 162-vertex icosphere of R = 0.1 m, mu =
200 kPa, H = 1 mm) is joined by an orifice of 10 cm^2 to a rigid 109-litre tank (every
vertex pinned) that an inflator fills with 2 g/s of air at 293 K; 1 bar outside, the air
isothermal. Implicit Euler at 2 ms steps them for 10 s. The balloon's gauge pressure
against its stretch s = (V / V0)^(1/3) lies on the closed-form curve c (1/s - 1/s^7), c =
2 mu H A0 / (3 V0), up to the peak at s = 7^(1/6) and past it: the tank's air, whose
pressure falls faster than the rubber's as the balloon draws on it, holds each state.
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

MU, H, P_A = 2e5, 1e-3, 1e5  # the scene's rubber: shear modulus [Pa], thickness [m]; 1 bar


def main(out: Path) -> None:
    scene = load_scene("balloon-tank")
    model = scene.model
    balloon, tank = 0, 1
    v0 = model.body_rest_volume[balloon]
    c = 2 * MU * H * model.membrane_rest_area.sum() / (3 * v0)
    state = model.state()
    sim = sb.Simulator(model, integrator=scene.integrator, dt=scene.dt)
    stretch, gauges = [1.0], [np.zeros(2)]
    for _ in range(round(scene.duration / 0.1)):
        sim.advance(state, 0.1)
        stretch.append((sb.body_volume(model, state)[balloon] / v0) ** (1 / 3))
        gauges.append(sb.body_pressure(model, state) - P_A)
    stretch, gauges = np.array(stretch), np.array(gauges)

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    s = np.linspace(1.0, max(1.7, stretch.max() + 0.05), 400)
    ax.plot(s, c * (1 / s - 1 / s**7), "k-", lw=1, label="closed form c (1/s - 1/s^7)")
    ax.plot(stretch, gauges[:, balloon], "o", ms=3, label="balloon, every 0.1 s")
    ax.plot(stretch, gauges[:, tank], "x", ms=3, color="tab:grey", label="tank")
    ax.axvline(7 ** (1 / 6), color="grey", ls="--", lw=0.8, label="peak 7^(1/6)")
    ax.set_xlabel("balloon stretch s = (V / V0)^(1/3)")
    ax.set_ylabel("gauge pressure [Pa]")
    ax.set_title("A rubber balloon inflated from a tank through its peak")
    ax.legend(fontsize=8)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    on_curve = gauges[1:, balloon] - c * (1 / stretch[1:] - 1 / stretch[1:] ** 7)
    print(f"{out}: end stretch {stretch[-1]:.4f}; balloon minus the curve "
          f"{on_curve.min():.1f} to {on_curve.max():.1f} Pa")  # fmt: skip


if __name__ == "__main__":
    root = Path(__file__).resolve().parents[1]
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else root / "docs" / "images" / "balloon-tank.png")
