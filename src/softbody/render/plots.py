"""Time-series plots of a run: volume, pressure and energies per body."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_time_series(
    path: Path, time: np.ndarray, series: dict, names: list[str], title: str
) -> None:
    """Four panels: volume, pressure, kinetic and total energy per body.

    series: 'volume' (F, B) [m^3], 'pressure' (F, B) [Pa], 'kinetic' (F, B) [J],
    'total' (F,) [J] (the whole model's energy).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 7), dpi=100)
    panels = [
        ("volume", "volume [m^3]"),
        ("pressure", "pressure [Pa]"),
        ("kinetic", "kinetic energy [J]"),
    ]
    for ax, (key, label) in zip(axes.flat, panels, strict=False):
        data = _finite(series[key])
        for b in range(data.shape[1]):
            if np.all(np.isnan(data[:, b])):
                continue
            ax.plot(time, data[:, b], color=f"C{b}", label=names[b])
        ax.set_ylabel(label)
    ax = axes.flat[3]
    ax.plot(time, _finite(series["total"]), color="k")
    ax.set_ylabel("total energy [J]")
    for ax in axes.flat:
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
    if len(names) <= 8:
        axes.flat[0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, format="png")
    plt.close(fig)


def _finite(data) -> np.ndarray:
    """``data`` as floats with infinities and values beyond 1e300 as NaN (a gap in the
    line): matplotlib cannot scale an axis to an infinite value or one whose span
    overflows."""
    data = np.array(data, dtype=float)
    with np.errstate(invalid="ignore"):
        data[~(np.abs(data) <= 1e300)] = np.nan
    return data


def plot_bounding_volumes(path: Path, time: np.ndarray, volumes: dict, name: str) -> None:
    """Each volume method's volume of one body against the exact one (paper, Figure 5)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4), dpi=100)
    volumes = {method: _finite(v) for method, v in volumes.items()}
    exact = volumes["exact"]
    for k, (method, v) in enumerate(volumes.items()):
        ax.plot(
            time,
            v,
            color=f"C{k}",
            label=method.replace("_", " "),
            lw=2.2 if method == "exact" else 1.4,
        )
        if method != "exact":
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = _finite(v / exact)
            ax2.plot(time, ratio, color=f"C{k}", label=method.replace("_", " "))
    ax.set_ylabel("volume [m^3]")
    ax2.set_ylabel("volume / exact volume")
    for a in (ax, ax2):
        a.set_xlabel("time [s]")
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(f"Volume methods on {name} (paper, Figure 5)")
    fig.tight_layout()
    fig.savefig(path, format="png")
    plt.close(fig)
