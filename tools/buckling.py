"""Draw a compressed film buckling as Euler's column says (docs/guide/bending.md).

    python tools/buckling.py [OUT.png]   (default docs/images/buckling.png)

A 10 x 2 cm StVK strip (E = 10 MPa, nu = 0, 3 mm thick, 40 x 8 squares) with the
material bending of its thickness, its ends held (simply supported), is compressed by a
strain eps and started 1 um out of plane (tests/test_buckling.py's strip); implicit Euler
at 1 ms steps it for 0.5 s. Left: the amplitude it settles at against eps / eps_c, with
Euler's critical strain eps_c = pi^2 H^2 / (12 L^2) and the post-buckling amplitude
(2 L / pi) sqrt(eps - eps_c); right: the bent centreline against the half sine.
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
from test_buckling import L, compressed_strip, critical_strain

H = 3e-3
RATIOS = (0.5, 0.8, 0.95, 1.1, 1.25, 1.5, 2.0, 3.0, 4.0)


def main(out: Path) -> None:
    eps_c = critical_strain(H)
    amplitudes, shapes = [], {}
    for ratio in RATIOS:
        model, state = compressed_strip(H, ratio * eps_c)
        sb.Simulator(model, integrator="implicit_euler", dt=1e-3).advance(
            state, 0.5, progress=False
        )
        q = state.particle_q
        amplitudes.append(np.abs(q[:, 2]).max())
        if ratio in (1.25, 2.0, 4.0):
            middle = np.isclose(model.particle_q[:, 1], 0.0)
            order = np.argsort(q[middle, 0])
            z = q[middle, 2][order]
            shapes[ratio] = (q[middle, 0][order], z * np.sign(z[len(z) // 2]))
        print(f"eps / eps_c = {ratio}: amplitude {amplitudes[-1]:.3e} m", flush=True)

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4.2))
    r = np.linspace(0.0, max(RATIOS), 400)
    closed = 2 * L / np.pi * np.sqrt(np.clip(r - 1.0, 0.0, None) * eps_c)
    left.plot(r, closed * 1e3, "k-", lw=1, label="Euler: (2L/pi) sqrt(eps - eps_c)")
    left.plot(RATIOS, np.array(amplitudes) * 1e3, "o", label="simulated, after 0.5 s")
    left.axvline(1.0, color="grey", ls="--", lw=0.8, label="eps_c = pi^2 H^2 / (12 L^2)")
    left.set_xlabel("compression eps / eps_c")
    left.set_ylabel("amplitude [mm]")
    left.set_title(f"a {H * 1e3:.0f} mm strip, eps_c = {eps_c:.2e}")
    left.legend(fontsize=8)
    for ratio, (x, z) in shapes.items():
        (line,) = right.plot(x * 100, z * 1e3, "o", ms=3, label=f"eps = {ratio} eps_c")
        span = L * (1 - ratio * eps_c) / 2
        a = 2 * L / np.pi * np.sqrt((ratio - 1.0) * eps_c)
        xs = np.linspace(-span, span, 200)
        right.plot(xs * 100, a * np.cos(np.pi * xs / (2 * span)) * 1e3, "-", lw=1,
                   color=line.get_color())  # fmt: skip
    right.set_xlabel("x [cm]")
    right.set_ylabel("z [mm]")
    right.set_title("centreline (points) against Euler's half sine (lines)")
    right.legend(fontsize=8)
    fig.suptitle("A compressed film buckles where and as far as Euler's column says")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    root = Path(__file__).resolve().parents[1]
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else root / "docs" / "images" / "buckling.png")
