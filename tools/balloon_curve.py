"""Draw the neo-Hookean balloon curve with simulated equilibria on it (docs/guide/membranes.md).

    python tools/balloon_curve.py [OUT.png]   (default docs/images/balloon-curve.png)

A membrane-only neo-Hookean balloon (icosphere of 642 particles, R = 0.2 m, mu = 200 kPa,
H = 1 mm, damped) is stepped by implicit Euler until it settles: under a fixed pressure
below the peak (the rising branch), and under a fixed amount of isothermal gas chosen to
balance it past the peak (the falling branch, stable there because the gas's pressure falls
faster with volume than the membrane's). Each settled stretch s = (V / V0)^(1/3) and its
pressure is a point; the line is P(s) = A0 H W'(s) / (3 V0 s^2) with the mesh's A0, V0.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import softbody as sb
from softbody.membrane import equibiaxial_pressure

RUBBER = sb.Membrane.neo_hookean(2e5, 1e-3, damping=2e-3)


def balloon(gas: sb.Gas) -> sb.Model:
    b = sb.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_soft_body(sb.icosphere(3, radius=0.2), mass=0.05, gas=gas, membrane=RUBBER)
    return b.finalize()


def settle(model: sb.Model, seconds: float = 1.5) -> tuple[float, float]:
    """(stretch, absolute pressure [Pa]) after implicit Euler at 1 ms for ``seconds``."""
    state = model.state()
    sb.Simulator(model, integrator="implicit_euler", dt=1e-3).run(state, round(seconds / 1e-3))
    volume = sb.body_volume(model, state)[0]
    return (volume / model.body_rest_volume[0]) ** (1 / 3), sb.body_pressure(model, state)[0]


def main(out: Path) -> None:
    rest = balloon(sb.Gas.fixed_pressure(0.0))
    area, volume = rest.membrane_rest_area.sum(), rest.body_rest_volume[0]
    peak_s = 7 ** (1 / 6)
    peak = float(equibiaxial_pressure(RUBBER, peak_s, area, volume))
    rising = [settle(balloon(sb.Gas.fixed_pressure(f * peak))) for f in (0.3, 0.5, 0.7, 0.85, 0.95)]
    falling = []
    for s in (1.6, 2.0, 2.5, 3.0):
        nrt = float(equibiaxial_pressure(RUBBER, s, area, volume)) * volume * s**3
        falling.append(settle(balloon(sb.Gas.isothermal(nrt))))
    s = np.linspace(1.0, 3.4, 400)
    fig, ax = plt.subplots(figsize=(6.4, 3.8), dpi=120)
    ax.plot(s, equibiaxial_pressure(RUBBER, s, area, volume), color="0.3",
            label=r"$P(s) = A_0 H W'(s) / (3 V_0 s^2)$")  # fmt: skip
    ax.plot(*zip(*rising, strict=True), "o", color="tab:blue",
            label="fixed pressure (rising branch)")  # fmt: skip
    ax.plot(*zip(*falling, strict=True), "s", color="tab:orange",
            label="fixed amount of gas (past the peak)")  # fmt: skip
    ax.axvline(peak_s, color="0.7", lw=0.8, ls="--")
    ax.annotate(r"peak at $s = 7^{1/6}$", (peak_s, peak), (peak_s + 0.25, 1.02 * peak))
    ax.set_xlabel("stretch s")
    ax.set_ylabel("pressure [Pa]")
    ax.set_title("neo-Hookean balloon: mu = 200 kPa, H = 1 mm, R = 0.2 m", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_ylim(0, 1.15 * peak)
    fig.tight_layout()
    fig.savefig(out)
    for label, points in (("rising", rising), ("falling", falling)):
        for st, p in points:
            expected = float(equibiaxial_pressure(RUBBER, st, area, volume))
            print(f"{label}: s = {st:.4f}, P = {p:.1f} Pa, closed form {expected:.1f} Pa")


if __name__ == "__main__":
    root = Path(__file__).resolve().parents[1]
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else root / "docs" / "images" / "balloon-curve.png")
