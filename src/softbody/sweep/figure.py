"""A sweep's summary figure: each metric against each varied parameter, or heat maps.

With two varied parameters each metric is a heat map over their grid (the mean where a
cell holds several runs); otherwise each metric is plotted against each varied
parameter. Runs that blew up are marked with crosses; errors are left out.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from softbody.sweep.spec import SweepSpec

#: Metrics drawn by default (those present and not constant), body 0's first.
DEFAULT = ("body0.sag", "body0.aspect_final", "body0.volume_ratio_final", "body0.rebound_ratio",
           "body0.settling_time", "body0.pressure_final", "energy_drift_relative")  # fmt: skip
MAX_METRICS = 6


def _pick(spec: SweepSpec, rows: list[dict], metrics: list[str] | None) -> list[str]:
    wanted = list(metrics) if metrics else []
    if not wanted:
        if spec.metrics:
            wanted = [f"body0.{m}" for m in spec.metrics] + list(spec.metrics)
        wanted += list(DEFAULT) + [f"{m}" for m in spec.user_metrics]
    out = []
    for m in wanted:
        values = np.array([r.get(m) for r in rows if r.get("status") != "error"], dtype=float)
        finite = values[np.isfinite(values)]
        if m not in out and finite.size and np.ptp(finite) > 0:
            out.append(m)
    return out[:MAX_METRICS]


def _axis(values: list) -> tuple[list, dict, bool]:
    """Distinct values in order, their index, whether they are numbers."""
    numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)
    distinct = sorted(set(values)) if numeric else list(dict.fromkeys(map(str, values)))
    return distinct, {v: i for i, v in enumerate(distinct)}, numeric


def _label(v) -> str:
    return f"{v:.3g}" if isinstance(v, float) else str(v)


def cell_labels(grid: np.ndarray, cell_points: float) -> tuple[list[str], float, str]:
    """The heat map's cell texts for ``grid``'s values (NaN: none), the font size [pt]
    that fits the widest in a cell ``cell_points`` wide (0: they do not fit at 4.5 pt, so
    none is drawn) and the scale the texts are in (" (x 1e5)", or "" when they are the
    values themselves). Values of 1e4 and above, or all below 1e-2, are shown divided by
    the power of ten of the largest, so a row of pressures near 1e5 reads 1.09, not
    1.09e+05 over and over."""
    finite = np.abs(grid[np.isfinite(grid)])
    largest = finite.max() if finite.size else 0.0
    scale, note = 1.0, ""
    if largest >= 1e4 or 0.0 < largest < 1e-2:
        power = int(np.floor(np.log10(largest)))
        scale, note = 10.0**power, f" (x 1e{power})"
    texts = ["" if not np.isfinite(v) else f"{v / scale:.3g}" for v in grid.ravel()]
    widest = max((len(t) for t in texts), default=0)
    size = min(7.0, cell_points / (0.62 * widest)) if widest else 0.0
    return texts, (size if size >= 4.5 else 0.0), note


def summary_figure(
    spec: SweepSpec, rows: list[dict], path: Path, metrics: list[str] | None = None
) -> Path | None:
    """Draw the summary figure of ``rows`` (the sweep's table) to ``path`` (PNG, written
    whole or not at all); None when there is nothing to draw."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from softbody.sweep.store import _atomic

    names = _pick(spec, rows, metrics)
    varied = spec.varied
    if not names or not varied:
        return None
    usable = [r for r in rows if r.get("status") != "error"]
    heat = len(varied) == 2
    if heat:
        cols = min(3, len(names))
        nrows = math.ceil(len(names) / cols)
        fig, axes = plt.subplots(nrows, cols, figsize=(4.6 * cols, 3.8 * nrows), squeeze=False)
        xs, xi, xnum = _axis([r[varied[0]] for r in usable])
        ys, yi, ynum = _axis([r[varied[1]] for r in usable])
        for ax, m in zip(axes.flat, names, strict=False):
            grid = np.full((len(ys), len(xs)), np.nan)
            count = np.zeros_like(grid)
            blown = np.zeros_like(grid, dtype=bool)
            for r in usable:
                x = xi[r[varied[0]] if xnum else str(r[varied[0]])]
                y = yi[r[varied[1]] if ynum else str(r[varied[1]])]
                v = r.get(m)
                if v is not None and np.isfinite(v):
                    grid[y, x] = np.nan_to_num(grid[y, x]) + v
                    count[y, x] += 1
                blown[y, x] |= r["status"] == "blew up"
            grid = np.where(count > 0, grid / np.maximum(count, 1), np.nan)
            im = ax.imshow(grid, origin="lower", aspect="auto", cmap="viridis")
            fig.colorbar(im, ax=ax)
            # a cell's width in points: the axes' share of the figure (as tight_layout
            # leaves it, about 0.62 of a panel beside its colour bar) over the columns
            cell = 0.62 * 4.6 * 72 / len(xs)
            texts, size, note = cell_labels(grid, cell)
            for y in range(len(ys)):
                for x in range(len(xs)):
                    if size and np.isfinite(grid[y, x]):
                        light = im.norm(grid[y, x]) > 0.6  # dark text on viridis' yellows
                        ax.text(x, y, texts[y * len(xs) + x], ha="center", va="center",
                                fontsize=size, color="k" if light else "w")  # fmt: skip
                    if blown[y, x]:
                        ax.plot(x, y, "rx", ms=12, mew=2)
            ax.set_xticks(range(len(xs)), [_label(v) for v in xs], rotation=45, fontsize=8)
            ax.set_yticks(range(len(ys)), [_label(v) for v in ys], fontsize=8)
            ax.set_xlabel(varied[0])
            ax.set_ylabel(varied[1])
            ax.set_title(m + (note if size else ""), fontsize=10)
        for ax in list(axes.flat)[len(names) :]:
            ax.axis("off")
    else:
        fig, axes = plt.subplots(len(names), len(varied),
                                 figsize=(4.2 * len(varied), 2.8 * len(names)),
                                 squeeze=False)  # fmt: skip
        for j, key in enumerate(varied):
            values, index, numeric = _axis([r[key] for r in usable])
            for i, m in enumerate(names):
                ax = axes[i, j]
                for status, style in (("ok", "o"), ("blew up", "x")):
                    pts = [(r[key] if numeric else index[str(r[key])], r.get(m))
                           for r in usable if r["status"] == status]  # fmt: skip
                    pts = [(x, y) for x, y in pts if y is not None and np.isfinite(y)]
                    if pts:
                        x, y = zip(*pts, strict=True)
                        ax.plot(x, y, style, ms=4, color="C0" if status == "ok" else "C3",
                                label=status)  # fmt: skip
                if not numeric:
                    ax.set_xticks(range(len(values)), values, fontsize=8)
                elif values and min(values) > 0 and max(values) / min(values) > 50:
                    ax.set_xscale("log")
                ax.set_ylabel(m, fontsize=8)
                if i == len(names) - 1:
                    ax.set_xlabel(key)
    done = sum(r["status"] == "ok" for r in rows)
    fig.suptitle(f"{spec.scene_name}: {len(rows)} runs ({done} ok)", fontsize=11)
    fig.tight_layout()
    path = Path(path)
    _atomic(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)
    return path
