"""Writing benchmark results whole or not at all: JSON and PNG go to a temporary file in
the same folder first and are renamed into place, so an interrupted run never leaves a
half-written result next to the README's figures."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

RESULTS = Path(__file__).parent / "results"


def run_record(benchmark: str, **fields) -> dict:
    """A result's common head (benchmark name, date, core count), then ``fields``."""
    return {
        "benchmark": benchmark,
        "date": time.strftime("%Y-%m-%d"),
        "cores": os.cpu_count(),
        **fields,
    }


def write_json(path: Path, data: dict) -> None:
    """``data`` as indented JSON at ``path`` (its folder is created)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.json")
    tmp.write_text(json.dumps(data, indent=2))
    os.replace(tmp, path)


def save_figure(fig, path: Path) -> None:
    """A matplotlib figure as PNG at ``path`` (its folder is created)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp)
    os.replace(tmp, path)


def plot_core_against_numba(
    path: Path, labels: list[str], core_ms: list[float], numba_ms: list[float], title: str
) -> None:
    """Bars of milliseconds per step, the compiled core beside the Numba loop, for each
    label (a size, or a size and an option), as PNG at ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    x = np.arange(len(labels))
    fig, ax = plt.subplots(figsize=(max(7.0, 1.6 * len(labels) + 2.0), 4.0))
    ax.bar(x - 0.2, numba_ms, 0.4, label="Numba loop", color="0.6")
    ax.bar(x + 0.2, core_ms, 0.4, label="C++ core", color="tab:green")
    for k in range(len(labels)):
        ax.annotate(f"{numba_ms[k] / core_ms[k]:.2f}x", (x[k] + 0.2, core_ms[k]),
                    ha="center", va="bottom", fontsize=9)  # fmt: skip
    ax.set_xticks(x, labels)
    ax.set_ylabel("ms per step")
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
