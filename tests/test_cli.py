"""The command line: the demo's outputs and one-line errors."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

import softbody as sb
from softbody.cli import main

ROOT = Path(__file__).resolve().parents[1]


def test_demo_writes_outputs_and_balls_sag_by_gas(tmp_path, capsys):
    """The hanging balls settle where less gas means less volume and lower pressure, and
    each pressure is nRT / V (isothermal law) at the final volume."""
    assert main(["demo", "--out", str(tmp_path), "--duration", "1.5"]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["hanging-balls-plots.png", "hanging-balls.png", "summary.json"]
    summary = json.loads((tmp_path / "summary.json").read_text())
    bodies = summary["bodies"]
    volumes = [b["volume_m3"] for b in bodies]
    assert volumes == sorted(volumes)
    for b in bodies:
        assert np.isclose(b["pressure_Pa"], b["gas_nrt_J"] / b["volume_m3"], rtol=1e-12)
    for png in ("hanging-balls.png", "hanging-balls-plots.png"):
        assert (tmp_path / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_demo_refuses_unstable_dt(tmp_path, capsys):
    """A dt above the stability estimate is one line on stderr, exit 2, and no files."""
    assert main(["demo", "--out", str(tmp_path / "o"), "--dt", "0.05"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("softbody: error: dt = 0.05 s exceeds the stable estimate")
    assert "\n" not in err
    assert not (tmp_path / "o").exists()


def test_info_reports_problems(tmp_path, capsys):
    """`softbody info` says whether a mesh can hold gas and why not (exit 1)."""
    m = sb.icosphere(1)
    good = sb.save_mesh(m, tmp_path / "ball.ply")
    bad = sb.save_mesh(sb.TriMesh(m.vertices, m.faces[1:]), tmp_path / "open.ply")
    assert main(["info", str(good)]) == 0
    assert "can hold gas" in capsys.readouterr().out
    assert main(["info", str(bad)]) == 1
    assert "problem: open: 3 boundary edges" in capsys.readouterr().out
    assert main(["info", str(tmp_path / "none.obj")]) == 2
    assert capsys.readouterr().err.strip().endswith("none.obj: no such file")


def test_console_script_runs_without_terminal():
    """The installed entry point works as a subprocess (no tty, as in CI)."""
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "softbody.cli",
            "info",
            str(ROOT / "tests" / "data" / "spot_triangulated.obj"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    assert "2930 vertices after welding" in out.stdout


def test_readme_test_command_is_what_ci_runs():
    """.ci/run runs exactly the README's test command."""
    readme = (ROOT / "README.md").read_text()
    commands = re.findall(r"```(?:sh|bash)\n(.*?)\n```", readme, flags=re.S)
    test_command = next(c for c in commands if "pytest" in c)
    assert test_command.strip() in (ROOT / ".ci" / "run").read_text()
