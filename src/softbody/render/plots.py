"""Time-series plots of a run: volume, pressure and energies per body."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_time_series(
    path: Path, time: np.ndarray, series: dict, names: list[str], title: str
) -> None:
    """Volume, pressure, kinetic and total energy per body; with gas that is state or that
    flows, more panels: the centre-of-mass height, the gas amount and temperature, and
    the mass flows in and out.

    series: 'volume' (F, B) [m^3], 'pressure' (F, B) [Pa], 'kinetic' (F, B) [J],
    'total' (F,) [J] (the whole model's energy); optional: 'height' (F, B) [m] (centre
    of mass y), 'gas_moles' (F, B) [mol], 'gas_temperature' (F, B) [K], 'mass_inflow'
    and 'mass_outflow' (F, B) [kg/s] (NaN for a body without a gas state: no line). The
    gas panels appear when 'gas_moles' is given, the flow panel when 'mass_inflow' is.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [
        ("volume", "volume [m^3]"),
        ("pressure", "pressure [Pa]"),
        ("kinetic", "kinetic energy [J]"),
        ("total", "total energy [J]"),
    ]
    if "gas_moles" in series:
        panels += [
            ("height", "centre of mass height [m]"),
            ("gas_moles", "gas amount [mol]"),
            ("gas_temperature", "gas temperature [K]"),
        ]
        if "mass_inflow" in series:
            panels.append(("flows", "mass flow [kg/s] (in: solid, out: dashed)"))
    rows = (len(panels) + 1) // 2
    fig, axes = plt.subplots(rows, 2, figsize=(11, 3.5 * rows), dpi=100)
    for ax, (key, label) in zip(axes.flat, panels, strict=False):
        if key == "total":
            ax.plot(time, _finite(series["total"]), color="k")
        elif key == "flows":
            inflow, outflow = _finite(series["mass_inflow"]), _finite(series["mass_outflow"])
            for b in range(inflow.shape[1]):
                if np.all(np.isnan(inflow[:, b])):
                    continue
                ax.plot(time, inflow[:, b], color=f"C{b}")
                ax.plot(time, outflow[:, b], color=f"C{b}", ls="--")
        else:
            data = _finite(series[key])
            for b in range(data.shape[1]):
                if np.all(np.isnan(data[:, b])):
                    continue
                ax.plot(time, data[:, b], color=f"C{b}", label=names[b])
        ax.set_ylabel(label)
    for ax in axes.flat[len(panels) :]:
        ax.remove()
    for ax in axes.flat[: len(panels)]:
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
