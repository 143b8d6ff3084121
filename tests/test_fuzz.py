"""Bounded fuzz test of scene files and ``--set`` overrides (issue 19, "Tests").

Random scenes and overrides drawn from the schema's types, plus values out of range
(negative, zero, NaN, infinities, huge, wrong types, unknown keys, long strings): every
case must end in a successful short run (exit 0) or one line on stderr and exit 2, never
a traceback, a signal, a hang or a file written outside ``--out``. Hypothesis runs
derandomized (``tests/conftest.py``), so the cases are the same every run; runs are tiny
(an icosphere of 12 to 42 vertices, 0.01 s, no video), about a minute in all.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from softbody.cli import main

#: Seconds one in-process case may take before it counts as a hang.
CASE_TIMEOUT = 60
RUN = ["--no-video", "--no-gif", "--duration", "0.01", "--integrator", "midpoint"]
FUZZ = settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


def base_scene() -> dict:
    """A valid, tiny scene: one 12-vertex ball on a plane, 10 steps."""
    return {
        "name": "fuzz",
        "simulation": {"integrator": "midpoint", "dt": 0.001, "duration": 0.01},
        "render": {"width": 32, "height": 32, "fps": 100},
        "bodies": [
            {
                "mesh": {"shape": "icosphere", "subdivisions": 0, "radius": 0.3},
                "position": [0.0, 0.5, 0.0],
                "mass": 1.0,
                "stiffness": 100.0,
                "damping": 0.5,
                "gas": {"law": "isothermal", "nrt": 5.0},
            }
        ],
        "colliders": [{"type": "plane"}],
    }


def toml_value(value) -> str:
    """``value`` written as TOML (inline tables and arrays; NaN and infinities as TOML
    writes them)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value)  # JSON's escapes are TOML basic-string escapes
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(v)}" for k, v in value.items()) + "}"


def toml_document(data: dict) -> str:
    return "".join(f"{json.dumps(k)} = {toml_value(v)}\n" for k, v in data.items())


# -- strategies: values of each key's type, and values out of range -----------------------
BAD = st.sampled_from(
    [
        -1,
        0,
        -1e300,
        1e300,
        math.nan,
        math.inf,
        -math.inf,
        True,
        "x",
        "../../x",
        "a" * 5000,
        [],
        [1, 2],
        {},
        {"zz": 1},
        2**70,
        1e3,
        1.5,
    ]
)
finite = st.floats(min_value=-10, max_value=10, allow_nan=False)
positive = st.floats(min_value=1e-3, max_value=100)
vec3 = st.lists(finite, min_size=3, max_size=3)
safe_text = st.text(alphabet="abcdefghijklmnopqrstuvwxyz0123456789 _-", min_size=1, max_size=30)

#: dotted key -> strategy of plausible values of its type
KEYS = {
    "simulation.dt": st.sampled_from([1e-3, 5e-4, 2e-3, "auto"]),
    "simulation.duration": st.floats(min_value=1e-3, max_value=0.02),
    "simulation.gravity": vec3,
    "simulation.implicit_tolerance": st.floats(min_value=1e-8, max_value=0.5),
    "simulation.integrator": st.sampled_from(["midpoint", "rk4", "bdf2", "implicit"]),
    "contact.mode": st.sampled_from(["none", "bounding", "surface", "sticky"]),
    "contact.restitution": st.floats(min_value=0, max_value=1),
    "contact.margin": positive,
    "render.width": st.integers(8, 64),
    "render.height": st.integers(8, 64),
    "render.fps": st.floats(min_value=1, max_value=1000),
    "render.fov": st.floats(min_value=1, max_value=179),
    "render.camera": vec3,
    "render.style": st.sampled_from(["solid", "wireframe", "both", "neon"]),
    "render.velocity_vectors": st.booleans(),
    "bodies.0.mass": positive,
    "bodies.0.stiffness": st.floats(min_value=0, max_value=500),
    "bodies.0.damping": st.floats(min_value=0, max_value=2),
    "bodies.0.bend_stiffness": st.floats(min_value=0, max_value=10),
    "bodies.0.position": vec3,
    "bodies.0.rotation": st.lists(finite, min_size=4, max_size=4),
    "bodies.0.scale": st.one_of(positive, st.lists(positive, min_size=3, max_size=3)),
    "bodies.0.velocity": vec3,
    "bodies.0.name": safe_text,
    "bodies.0.color": st.sampled_from(["#ff0000", "#00Ff00", "red", "#12345"]),
    "bodies.0.mass_distribution": st.sampled_from(["uniform", "area"]),
    "bodies.0.volume_method": st.sampled_from(
        ["exact", "bounding_box", "bounding_sphere", "bounding_ellipsoid", "monte_carlo"]
    ),
    "bodies.0.monte_carlo_samples": st.integers(1, 5000),
    "bodies.0.seed": st.integers(0, 2**32),
    "bodies.0.pin": st.sampled_from(
        [{"above": 0.7}, {"indices": [0, 1]}, {"indices": [99]}, {"boundary": True}, {}]
    ),
    "bodies.0.mesh.subdivisions": st.integers(0, 1),
    "bodies.0.mesh.radius": st.floats(min_value=0.05, max_value=1),
    "bodies.0.mesh": st.sampled_from(
        [
            {"shape": "uv_sphere", "rings": 3, "segments": 4, "radius": 0.3},
            {"shape": "box", "extents": [0.4, 0.4, 0.4]},
            {"shape": "capsule", "radius": 0.2, "length": 0.2, "rings": 2, "segments": 4},
            {"shape": "cylinder", "radius": 0.3, "height": 0.3, "segments": 4},
            {"shape": "rectangle"},
            {"file": "missing.obj"},
            {"builtin": "hand"},
            {"shape": "icosphere", "file": "x.obj"},
        ]
    ),
    "bodies.0.gas": st.one_of(
        positive,
        st.sampled_from(
            [
                {"law": "fixed_pressure", "pressure": 10.0},
                {"law": "adiabatic", "nrt": 5.0, "gamma": 1.4},
                {"moles": 0.001},
                {"nrt": 5.0, "schedule": [[0.0, 5.0], [0.005, 8.0]]},
                {"law": "vdw", "nrt": 1.0},
            ]
        ),
    ),
    "bodies.0.gas.nrt": st.floats(min_value=0, max_value=50),
    "bodies.0.kind": st.sampled_from(["soft", "cloth", "jelly"]),
    "colliders.0.type": st.sampled_from(["plane", "box", "sphere", "cone"]),
    "colliders.0.normal": vec3,
    "colliders.0.friction": st.floats(min_value=0, max_value=1),
    "colliders.0.motion": st.sampled_from(
        [
            {"type": "rotation", "angular_velocity": [0.0, 0.0, 1.0]},
            {"type": "translation", "velocity": [0.0, 1.0, 0.0]},
            {"type": "oscillation", "amplitude": [0.0, 0.1, 0.0], "frequency": 1.0},
            {"type": "spin"},
        ]
    ),
    "attachments": st.sampled_from(
        [
            [{"body": 0, "anchor": [0.0, 1.0, 0.0], "stiffness": 10.0}],
            [{"body": 3, "anchor": [0.0, 1.0, 0.0], "stiffness": 10.0}],
            [{"body": 0, "vertex": 99, "anchor": [0.0, 1.0, 0.0], "stiffness": 10.0}],
        ]
    ),
    "name": safe_text,
    "description": st.text(max_size=50),
}
UNKNOWN = ["simulation.dtt", "bodies.0.gass", "render.colour", "bodies.0.mesh.rings", "zz"]
#: overrides that walk through a value (a TypeError traceback before the fix)
THROUGH_VALUES = ["simulation.gravity.0.x", "bodies.0.position.1.y", "simulation.dt.x"]


def _set(data: dict, dotted: str, value) -> None:
    node = data
    parts = dotted.split(".")
    for part in parts[:-1]:
        node = node[int(part)] if isinstance(node, list) else node.setdefault(part, {})
    if isinstance(node, list):
        node[int(parts[-1])] = value
    else:
        node[parts[-1]] = value


@st.composite
def scenes(draw) -> dict:
    """The base scene with 1 to 4 keys set to a value of their type or an out-of-range
    one, and now and then an unknown key."""
    data = base_scene()
    for key in draw(st.lists(st.sampled_from(sorted(KEYS)), min_size=1, max_size=4)):
        value = draw(st.one_of(KEYS[key], BAD) if draw(st.booleans()) else KEYS[key])
        _set(data, key, value)
    if draw(st.integers(0, 5)) == 0:
        _set(data, draw(st.sampled_from(UNKNOWN)), draw(BAD))
    return data


# -- the property --------------------------------------------------------------------------
class _Hang(Exception):
    pass


def _on_alarm(signum, frame):
    raise _Hang(f"a case ran past {CASE_TIMEOUT} s")


def run_case(folder: Path, argv: list[str]) -> None:
    """``softbody run`` in-process in ``folder``; assert the issue's contract."""
    before = {p for p in folder.rglob("*")}
    out, err = io.StringIO(), io.StringIO()
    previous = signal.signal(signal.SIGALRM, _on_alarm)
    signal.alarm(CASE_TIMEOUT)
    cwd = os.getcwd()
    try:
        os.chdir(folder)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(["run", *argv, "--out", "out", *RUN])
    finally:
        os.chdir(cwd)
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    stderr = err.getvalue()
    assert code in (0, 2), (code, stderr)
    if code == 2:
        assert stderr.startswith("softbody: error: ") and stderr.count("\n") == 1, stderr
    else:
        assert list((folder / "out").glob("*-summary.json")), out.getvalue()
    written = {p for p in folder.rglob("*")} - before
    outside = [p for p in written if folder / "out" not in p.parents and p != folder / "out"]
    assert outside == [], outside


@FUZZ
@given(data=scenes())
def test_fuzz_scene_files(tmp_path_factory, data):
    """Random scene files: a short run or a one-line error, nothing outside --out."""
    folder = tmp_path_factory.mktemp("scene")
    (folder / "s.toml").write_text(toml_document(data), encoding="utf-8")
    run_case(folder, ["s.toml"])


OVERRIDE_VALUES = st.one_of(
    st.sampled_from(
        [
            "-1",
            "0",
            "nan",
            "-inf",
            "1e308",
            "true",
            '"x"',
            "[1, 2, 3]",
            "{a = 1}",
            '"' + "a" * 3000 + '"',
            "../../x",
            "1e3",
            "",
            "[[1]]",
        ]
    ),
    st.floats(allow_nan=True, allow_infinity=True).map(toml_value),
    st.integers(-(2**70), 2**70).map(str),
)


@st.composite
def overrides(draw) -> list[tuple[str, str]]:
    """1 to 3 ``(key, value)`` overrides: a value of the key's type written as TOML, or one
    out of range, for known keys, unknown keys and paths through values."""
    out = []
    for key in draw(
        st.lists(st.sampled_from(sorted(KEYS) + UNKNOWN + THROUGH_VALUES), min_size=1, max_size=3)
    ):
        typed = KEYS[key].map(toml_value) if key in KEYS else OVERRIDE_VALUES
        out.append((key, draw(st.one_of(typed, OVERRIDE_VALUES))))
    return out


@FUZZ
@given(pairs=overrides())
@example(pairs=[("bodies.0.position.1.y", "1")])  # a TypeError traceback before the fix
def test_fuzz_set_overrides(tmp_path_factory, pairs):
    """Random ``--set key=value`` on a valid scene: a short run or a one-line error."""
    folder = tmp_path_factory.mktemp("set")
    (folder / "s.toml").write_text(toml_document(base_scene()), encoding="utf-8")
    argv = ["s.toml"]
    for key, value in pairs:
        argv += ["--set", f"{key}={value}"]
    run_case(folder, argv)


@pytest.mark.parametrize(
    "override",
    [
        "render.fps=1e-6",  # hung: about 1e9 steps per frame
        "bodies.0.mesh.subdivisions=1e3",  # took all memory until killed
        "simulation.dt=1e-12",  # ran 1e10 steps silently
        "bodies.0.monte_carlo_samples=1e12",  # MemoryError traceback
    ],
)
def test_fuzz_cases_in_a_subprocess(tmp_path, override):
    """The reproductions of issue 19 items 2 and 3 as a user runs them: the process exits
    2 with one line on stderr, within the timeout, not by a signal (a negative return
    code) or the out-of-memory killer. The child runs under a 4 GiB address-space limit
    so that a regression cannot take the machine down."""
    import resource

    (tmp_path / "s.toml").write_text(toml_document(base_scene()), encoding="utf-8")

    def limit_memory():
        resource.setrlimit(resource.RLIMIT_AS, (4 * 1024**3, 4 * 1024**3))

    argv = ["run", "s.toml", "--out", "out", *RUN, "--set", override]
    result = subprocess.run(
        [sys.executable, "-m", "softbody.cli", *argv],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=180,
        preexec_fn=limit_memory,
    )
    assert result.returncode == 2, (result.returncode, result.stderr[-2000:])
    assert result.stderr.startswith("softbody: error: ") and result.stderr.count("\n") == 1
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


@pytest.mark.parametrize("name", ["../../escaped", "<absolute>"])
def test_fuzz_path_like_scene_names_stay_in_out(tmp_path, name):
    """A path-like scene ``name`` (relative, or an absolute path elsewhere) writes
    nothing outside --out: the name becomes a safe file stem."""
    folder = tmp_path / "a" / "b"
    folder.mkdir(parents=True)
    if name == "<absolute>":
        name = str(tmp_path / "elsewhere" / "escaped")
    data = base_scene()
    data["name"] = name
    (folder / "s.toml").write_text(toml_document(data), encoding="utf-8")
    run_case(folder, ["s.toml"])
    written = [p for p in tmp_path.rglob("*") if p.is_file() and folder not in p.parents]
    assert written == []
    assert any((folder / "out").iterdir())  # the run wrote its files where it was told
