"""The documentation builds with no warning, and the README's Python example runs.

The site (docs/) is built as CI builds it: ``sphinx-build -W --keep-going -b html`` into
a temporary folder, with every tutorial notebook executed. Reference: a warning is an
error (a broken cross-reference, a missing page, a docstring Sphinx cannot read, a
notebook cell that raises), so the build's exit status must be 0 and its output free of
``WARNING`` and ``ERROR``.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_docs_build_without_warnings(tmp_path):
    """``sphinx-build -W --keep-going`` over docs/ exits 0 with no warning; the pages
    generated from the code (API, scene keys, CLI, benchmarks, verification) exist."""
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_nb")
    out = tmp_path / "html"
    env = {**os.environ, "PYDEVD_DISABLE_FILE_VALIDATION": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
         "-d", str(tmp_path / "doctrees"), str(ROOT / "docs"), str(out)],
        capture_output=True, text=True, timeout=900, env=env, cwd=ROOT,
    )  # fmt: skip
    problems = [
        line for line in (proc.stdout + proc.stderr).splitlines()
        if re.search(r"\b(WARNING|ERROR)\b", line) and "IPKernelApp" not in line
    ]  # fmt: skip
    assert proc.returncode == 0 and not problems, "\n".join(problems) or proc.stderr[-4000:]
    for page in ["index", "reference/api", "generated/scene-keys", "generated/cli",
                 "generated/verification", "generated/benchmarks/ball_drop",
                 "tutorials/balloon"]:  # fmt: skip
        assert (out / f"{page}.html").is_file(), page
    api = (out / "reference" / "api.html").read_text()
    import softbody

    missing = [name for name in softbody.__all__ if f'id="softbody.{name}"' not in api]
    assert not missing, f"public names without an API entry: {missing}"


def test_readme_example_runs(tmp_path):
    """The README's Python example (its one ```python block) runs as written and prints
    the ball's volume and pressure: finite, positive numbers (P V = nRT within 1%)."""
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) == 1
    proc = subprocess.run(
        [sys.executable, "-c", blocks[0]], capture_output=True, text=True, timeout=300,
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    numbers = [float(x) for x in re.findall(r"[-+]?\d+\.\d*(?:e[-+]?\d+)?", proc.stdout)]
    assert len(numbers) == 2, proc.stdout
    volume, pressure = numbers
    assert volume > 0 and pressure > 0
    assert abs(pressure * volume / 300.0 - 1) < 0.01


def test_readme_speed_matches_benchmark():
    """The README's quoted speed is the one ``benchmarks/ball_drop.py`` wrote: implicit
    Euler at CG tolerance 1e-2 on the 10,242-vertex ball, simulated over wall seconds,
    to the two decimals quoted."""
    data = json.loads((ROOT / "benchmarks" / "results" / "ball_drop.json").read_text())
    size = next(s for s in data["sizes"] if s["vertex_count"] == 10242)
    speed = size["integrators"]["implicit_euler cg 1e-2"]["simulated_per_wall_second"]
    assert f"10,242-vertex ball drop at {speed:.2f}x real time" in (ROOT / "README.md").read_text()


def _summary() -> dict:
    return json.loads((ROOT / "benchmarks" / "results" / "summary.json").read_text())


def test_benchmark_summary_is_the_result_files():
    """benchmarks/results/summary.json is what ``benchmarks/summary.py`` takes from the
    result files now (so a rerun benchmark cannot leave the table behind), and each row
    names an existing result file and script, an integrator and a step."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import summary

    assert json.loads(json.dumps(summary.summarise())) == _summary()
    assert (ROOT / "benchmarks" / "results" / "summary.png").is_file()
    for row in _summary()["rows"]:
        assert (ROOT / "benchmarks" / "results" / row["source"]).is_file(), row
        script = row["command"].split()[1]
        assert script == f"benchmarks/{row['source'].removesuffix('.json')}.py", row
        assert (ROOT / script).is_file() and row["integrator"] and row["step"], row


def test_readme_speed_figures_name_their_integrator_and_step():
    """Each speed the README quotes is a row of benchmarks/results/summary.json, given with
    the integrator and step it ran at: the five balls' 75x is symplectic Euler at its 2.0 ms
    step, and the scene as `softbody run` runs it (midpoint at 0.5 ms) is quoted beside it;
    the explicit step's throughput is symplectic Euler's; the 40,962-vertex drop's is
    implicit Euler's at 1/60 s and, with the bounce kept, XPBD's; the race against Jolt's
    ratios are the race's. Reference: issue 29, item 19 (a 75x headline beside a CLI
    that prints 7-10x)."""
    rows = {row["key"]: row for row in _summary()["rows"]}
    readme = (ROOT / "README.md").read_text().splitlines()
    feature = next(line for line in readme if line.startswith("| measured speed |"))
    target = next(line for line in readme if line.startswith("| the paper's five balls"))
    explicit = next(line for line in readme if line.startswith("| explicit step >= 60 M"))
    drop = next(line for line in readme if line.startswith("| a bouncing ball drop"))
    fast, scene = rows["five-balls-symplectic"], rows["five-balls-scene-step"]
    five_balls = [
        f"{fast['value']:.0f}x", "symplectic Euler", f"{1e3 * fast['dt_s']:.1f} ms",
        f"{scene['value']:.1f}x", f"midpoint at {1e3 * scene['dt_s']:.1f} ms",
        "softbody run bouncing-balls",
    ]  # fmt: skip
    for line in (feature, target):
        missing = [phrase for phrase in five_balls if phrase not in line]
        assert not missing, (missing, line)
    assert f"{rows['five-balls-symplectic-f32']['value']:.0f}x with float32" in target
    for line in (feature, explicit):
        assert f"{rows['explicit-step']['value']:.0f} M" in line
        assert "symplectic Euler" in line and "AVX-512" in line
    big, drop_10k = rows["ball-drop-40962-implicit"], rows["ball-drop-implicit"]
    assert f"{big['value']:.2f}x" in drop and "implicit Euler at 1/60 s" in drop
    assert f"{drop_10k['value']:.2f}x real time (implicit Euler at 1/60 s" in feature
    # the bounce kept at 40,962 vertices (XPBD, its substeps and passes named), and the
    # race against Jolt: softbody's rate over Jolt's at each size, in the README's order
    xpbd = rows["ball-drop-40962-xpbd"]
    assert f"{xpbd['value']:.2f}x" in drop and "`xpbd` at 32 substeps of 4 passes" in drop
    race = next(line for line in readme if line.startswith("| softbody >= 4x Jolt"))
    ratios = ", ".join(f"{rows[f'jolt-race-{n}']['value']:.2f}x"
                       for n in (642, 2562, 10242, 40962))  # fmt: skip
    assert ratios in race


@pytest.mark.parametrize(
    "page", sorted(p.relative_to(ROOT / "docs").as_posix()
                   for p in (ROOT / "docs").rglob("*.md")
                   if "```python" in p.read_text() and "generated" not in p.parts),
)  # fmt: skip
def test_guide_code_blocks_run(page, tmp_path):
    """Every ```python block of the hand-written pages runs as written, each page's
    blocks in order in one fresh process (the tutorials' cells run in the build)."""
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / page).read_text(), flags=re.S)
    # the sweep page's examples name the sweep files of examples/sweeps as if run there
    for example in (ROOT / "examples" / "sweeps").glob("*.toml"):
        shutil.copyfile(example, tmp_path / example.name)
    proc = subprocess.run(
        [sys.executable, "-c", "\n".join(blocks)], capture_output=True, text=True,
        timeout=300, cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
