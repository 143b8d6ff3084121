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
