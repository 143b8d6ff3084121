"""Draw the two-balloon instability (docs/guide/membranes.md).

    python tools/two_balloons.py [OUT.png]   (default docs/images/two-balloons.png)

Two neo-Hookean balloons (icospheres of 162 particles, R = 0.2 m, mu = 200 kPa, H = 1 mm,
damped) start past the peak of the balloon curve at stretches 1.65 and 1.55, each holding
the isothermal air that balances it (1 bar outside), and are joined by an orifice of
0.05 m^2 (core/terms/flows.hpp). Implicit Euler at 2 ms steps them for 8 s. Left: each
balloon's stretch s = (V / V0)^(1/3) over time, with the closed-form end state (equal
pressures, one balloon on each side of the peak, the air the two began with); right: their
path on the balloon curve P = c (1 / s - 1 / s^7). tests/test_two_balloons.py checks the
end state.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import softbody as sb

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_two_balloons import P_A, PEAK, gauge, joined_balloons, stable_pair


def main(out: Path) -> None:
    start = np.array([1.65, 1.55])
    model, state, c, v0 = joined_balloons(start)
    s1, s2 = stable_pair(state.body_gas_moles.sum(), c, v0)
    sim = sb.Simulator(model, integrator="implicit_euler", dt=2e-3)
    times, stretch, pressure = [0.0], [start.copy()], [sb.body_pressure(model, state) - P_A]
    for _ in range(160):
        sim.advance(state, 0.05)
        times.append(state.time)
        stretch.append((sb.body_volume(model, state) / v0) ** (1 / 3))
        pressure.append(sb.body_pressure(model, state) - P_A)
    stretch, pressure = np.array(stretch), np.array(pressure)

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    for k, colour in enumerate(("tab:blue", "tab:orange")):
        left.plot(times, stretch[:, k], color=colour, label=f"balloon {k}")
        right.plot(stretch[:, k], pressure[:, k], ".", color=colour, ms=3)
    left.axhline(s2, color="k", ls=":", lw=1)
    left.axhline(s1, color="k", ls=":", lw=1, label="closed-form end state")
    left.axhline(PEAK, color="grey", ls="--", lw=0.8, label="peak 7^(1/6)")
    left.set_xlabel("time [s]")
    left.set_ylabel("stretch s = (V / V0)^(1/3)")
    left.legend(fontsize=8)
    s = np.linspace(1.0, 2.2, 400)
    right.plot(s, gauge(s, c), "k-", lw=1, label="balloon curve c (1/s - 1/s^7)")
    right.plot([s1, s2], gauge(np.array([s1, s2]), c), "ks", mfc="none", label="closed form")
    right.set_xlabel("stretch s")
    right.set_ylabel("gauge pressure [Pa]")
    right.legend(fontsize=8)
    fig.suptitle("Two joined neo-Hookean balloons: the smaller empties into the larger")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"{out}: end stretches {stretch[-1]}, closed form {s2:.5f}, {s1:.5f}")


if __name__ == "__main__":
    root = Path(__file__).resolve().parents[1]
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else root / "docs" / "images" / "two-balloons.png")
