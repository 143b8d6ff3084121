"""The scene schema (issue 19, "Scene validation as a schema", items 3, 7 and 11): every
key's type and bounds, one-line errors naming the dotted key, the JSON Schema, size
guards that refuse before allocating, and scene files read safely."""

from __future__ import annotations

import json
import re
import resource
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from conftest import BUILT_IN
from softbody import limits
from softbody.cli import main
from softbody.errors import SizeLimitError
from softbody.scenes import SceneError, load_scene

ROOT = Path(__file__).resolve().parents[1]
#: ``dotted.key: reason, got value`` and nothing else on the line
ONE_LINE = re.compile(r"^[\w.]+: [^\n]+$")


@pytest.fixture(autouse=True)
def _memory_limit(monkeypatch):
    """The same memory limit on every machine, so the guards' verdicts do not depend on
    how much memory the test machine has."""
    monkeypatch.setenv("SOFTBODY_MEMORY_LIMIT", "1G")


def _error(scene: str, overrides: list[str]) -> str:
    with pytest.raises(ValueError) as info:
        load_scene(scene, overrides)
    return str(info.value)


# -- types and bounds, a sample per table --------------------------------------------------
@pytest.mark.parametrize(
    "override,expected",
    [
        # simulation
        ("simulation.dt=-1", 'simulation.dt: must be finite seconds >= 1e-09 or "auto", got -1'),
        ("simulation.duration=inf", "simulation.duration: must be finite, got inf"),
        ("simulation.duration=1e9", "simulation.duration: must be <= 86400, got 1000000000.0"),
        ('simulation.integrator="rk5"', "simulation.integrator: must be one of 'euler'"),
        ("simulation.gravity=[0, nan, 0]", "simulation.gravity.1: must be finite, got nan"),
        # contact
        ('contact.mode="sticky"', "contact.mode: must be one of 'none', 'bounding' or 'surface'"),
        ("contact.restitution=1.5", "contact.restitution: must be <= 1, got 1.5"),
        ("contact.margin=-1", "contact.margin: must be > 0, got -1"),
        # render
        ("render.width=8", "render.width: must be >= 16, got 8"),
        ("render.fps=1e-6", "render.fps: must be >= 0.01, got 1e-06"),
        ("render.fov=0", "render.fov: must be > 0, got 0"),
        ("render.velocity_scale=nan", "render.velocity_scale: must be finite, got nan"),
        ('render.velocity_vectors="yes"', "render.velocity_vectors: must be true or false"),
        # bodies
        ("bodies.0.mass=true", "bodies.0.mass: must be a number, got True"),
        ('bodies.0.stiffness="300"', "bodies.0.stiffness: must be a number, got '300'"),
        ("bodies.0.damping=-0.5", "bodies.0.damping: must be >= 0, got -0.5"),
        ("bodies.0.seed=-1", "bodies.0.seed: must be >= 0, got -1"),
        ('bodies.0.color="red"', "bodies.0.color: must be a colour '#rrggbb', got 'red'"),
        ("bodies.0.scale=0", "bodies.0.scale: must be finite and > 0"),
        # mesh
        ("bodies.0.mesh.radius=0", "bodies.0.mesh.radius: must be > 0, got 0"),
        ("bodies.0.mesh.subdivisions=1.5", "bodies.0.mesh.subdivisions: must be an integer"),
        ('bodies.0.mesh.shape="cone"', "bodies.0.mesh.shape: unknown value 'cone' (valid: "),
        # gas
        ("bodies.0.gas.nrt=-5", "bodies.0.gas.nrt: must be >= 0, got -5"),
        ('bodies.0.gas={law="adiabatic", nrt=1, gamma=1}', "bodies.0.gas.gamma: must be > 1"),
        ("bodies.0.gas={nrt=1, schedule=[[1, 2], [0, 3]]}", "bodies.0.gas.schedule: times"),
        # colliders and motions
        ("colliders.0.half_extents=[1, 0, 1]", "colliders.0.half_extents: every entry must be"),
        ("colliders.0.friction=-1", "colliders.0.friction: must be >= 0, got -1"),
        (
            "colliders.0.motion.angular_velocity=[0, 0, inf]",
            "colliders.0.motion.angular_velocity.2: must be finite, got inf",
        ),
        # the whole scene
        ("bodies=[]", "bodies: must not be empty"),
        ("name=[5]", "name: must be a string, got [5]"),
    ],
)
def test_each_bound_and_type_is_checked(override, expected):
    """A sample of each table's types and bounds (schema: Field(gt/ge/le), strict numbers,
    finite values): the error is one line, starts with the dotted key and gives the
    value. Before the schema several were accepted (a fov of 0, a NaN velocity scale,
    ``true`` as a mass, ``"300"`` as a stiffness) or failed deep in the builder."""
    message = _error("bouncing-balls", [override])
    assert message.startswith(expected), message
    assert ONE_LINE.match(message), message


def test_walking_an_override_into_a_number_is_an_error():
    """``--set simulation.gravity.0.x=1`` walks into a number: a SceneError, not the
    TypeError ("argument of type 'float' is not iterable") that escaped as a traceback."""
    with pytest.raises(SceneError, match=r"simulation\.gravity\.0 is a value, not a table"):
        load_scene("bouncing-balls", ["simulation.gravity.0.x=1"])


# -- unknown keys --------------------------------------------------------------------------
@pytest.mark.parametrize(
    "override,key,valid",
    [
        ("bodies.0.mesh.rings=4", "bodies.0.mesh.rings", "radius, reorder, shape, subdivisions"),
        (
            "bodies.0.gas.gamma=1.3",
            "bodies.0.gas.gamma",
            "ambient_pressure, law, moles, nrt, schedule, temperature",
        ),
        ("colliders.0.radius=1", "colliders.0.radius", "center, container, friction"),
        ("colliders.0.motion.pivot2=1", "colliders.0.motion.pivot2", "angular_velocity, pivot"),
        ('bodies.0.kind="cloth"', "bodies.0.gas", "bend_damping, bend_stiffness, bending, color"),
    ],
)
def test_unknown_key_lists_the_keys_of_that_variant(override, key, valid):
    """An unknown key lists the keys valid where it stands: an icosphere's keys, not every
    generator's (before, ``rings`` on an icosphere reached the generator as a TypeError);
    an isothermal gas's keys; a box collider's; a rotation's; a cloth has no gas."""
    message = _error("bouncing-balls", [override])
    assert message.startswith(f"unknown scene key {key} (valid: ")
    assert valid in message, message
    if key == "bodies.0.gas":
        assert "pressure" in message and "gas," not in message


def test_several_problems_give_the_first_and_a_count():
    """Only the first problem is shown, with a count of the rest, on one line, and none of
    pydantic's own text (URLs, 'Input should be')."""
    message = _error("bouncing-balls", ["bodies.0.mass=-1", "bodies.1.mass=-1", "render.fov=0"])
    assert message == "render.fov: must be > 0, got 0 (and 2 more problems)"


# -- JSON Schema ---------------------------------------------------------------------------
def test_json_schema_has_units_defaults_and_bounds(capsys):
    """``scene_json_schema()`` and ``softbody scenes --schema``: the same JSON Schema,
    closed tables, units in the descriptions, defaults and bounds."""
    from softbody.scenes import scene_json_schema

    schema = scene_json_schema()
    assert main(["scenes", "--schema"]) == 0
    assert json.loads(capsys.readouterr().out) == schema
    defs = schema["$defs"]
    dt = defs["Simulation"]["properties"]["dt"]
    assert "[s]" in dt["description"] and dt["default"] == 1e-3
    assert {"const": "auto"} in dt["anyOf"]
    radius = defs["Icosphere"]["properties"]["radius"]
    assert radius["exclusiveMinimum"] == 0 and "[m]" in radius["description"]
    fps = defs["Render"]["properties"]["fps"]
    assert fps["minimum"] == 0.01 and fps["maximum"] == 1000
    mass = defs["SoftBody"]["properties"]["mass"]  # optional: a membrane's density instead
    assert any(o.get("exclusiveMinimum") == 0 for o in mass["anyOf"]) and "[kg]" in str(mass)
    layer = defs["NeoHookean"]["properties"]
    assert "[Pa]" in layer["shear_modulus"]["description"]
    assert layer["thickness"]["exclusiveMinimum"] == 0
    assert all(d.get("additionalProperties") is False for d in defs.values() if "properties" in d)
    assert schema["required"] == ["bodies"]


@pytest.mark.parametrize("name", BUILT_IN)
def test_every_built_in_scene_validates(name):
    """Each built-in scene passes the schema as written, and its keys are all in the JSON
    Schema's properties (the documentation lists every key a built-in uses)."""
    from softbody.scenes import scene_json_schema, validate

    data = tomllib.loads((ROOT / "src/softbody/scenes" / f"{name}.toml").read_text())
    spec = validate(data)
    assert len(spec.bodies) == len(data["bodies"])
    top = scene_json_schema()["properties"]
    assert set(data) <= set(top)


# -- size guards ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "override,key",
    [
        ("bodies.0.mesh.subdivisions=12", "bodies.0.mesh.subdivisions"),
        ('bodies.0.mesh={shape="uv_sphere", rings=1e5}', "bodies.0.mesh.rings"),
        ('bodies.0.mesh={shape="capsule", segments=1e8}', "bodies.0.mesh.segments"),
        ('bodies.0.mesh={shape="cylinder", segments=1e9}', "bodies.0.mesh.segments"),
        ('bodies.0.mesh={shape="box", subdivisions=14}', "bodies.0.mesh.subdivisions"),
        ("bodies.0.monte_carlo_samples=1e12", "bodies.0.monte_carlo_samples"),
    ],
)
def test_size_guards_name_the_key_estimate_and_limit(override, key):
    """Sizes that would not fit in memory (limit 1 GiB here) are refused from the keys
    alone, with the key, the estimate and the limit: before, subdivisions = 12, 1e5 rings
    and 1e12 Monte Carlo samples ended in a MemoryError traceback."""
    with pytest.raises(SizeLimitError) as info:
        load_scene("bouncing-balls", [override])
    message = str(info.value)
    assert message.startswith(f"{key}: ") and "\n" not in message
    assert "of memory, over the limit of 1 GiB" in message


def test_rectangle_resolution_and_image_size_are_guarded():
    """A cloth's resolution and the rendered image size count against the same limit."""
    with pytest.raises(SizeLimitError, match=r"^bodies\.0\.mesh\.resolution: a mesh of"):
        load_scene("cloth-wind", ["bodies.0.mesh.resolution=[100000, 100000]"])
    with pytest.raises(SizeLimitError, match=r"^render\.width: 4096 x 4096 frames would need"):
        load_scene("cloth-wind", ["render.width=4096", "render.height=4096"])
    limits.check_memory("render.width", 160 * 640 * 480, "default frames")  # the default fits


def test_time_steps_below_a_nanosecond_are_refused():
    """``dt = 1e-12`` (1e13 steps for this 10 s scene) ran silently for ever. A step under
    MIN_DT (1 ns, far below any soft body's stable step) is refused naming the key; how
    many steps a longer dt makes is the run's check (``--max-steps``, test_outputs)."""
    message = _error("bouncing-balls", ["simulation.dt=1e-12"])
    assert message.startswith("simulation.dt: must be finite seconds >= 1e-09")
    load_scene("bouncing-balls", ["simulation.dt=1e-9"])  # the bound itself is allowed


@pytest.mark.parametrize(
    "key,alias,canonical",
    [
        ("simulation.integrator", "verlet", "velocity_verlet"),
        ("simulation.integrator", "RK4", "rk4"),
        ("simulation.integrator", "implicit", "implicit_euler"),
        ("bodies.0.volume_method", "bounding-sphere", "bounding_sphere"),
    ],
)
def test_names_the_library_accepts_are_accepted(key, alias, canonical):
    """A scene may name an integrator or volume method as ``Integrator.parse`` and
    ``VolumeMethod.parse`` accept it (the loader did before the schema); it is stored
    under its canonical name."""
    from softbody.scenes import validate

    data = tomllib.loads((ROOT / "src/softbody/scenes/bouncing-balls.toml").read_text())
    section, *rest = key.split(".")
    node = data[section]
    if rest[0].isdigit():
        node = node[int(rest[0])]
    node[rest[-1]] = alias
    spec = validate(data)
    value = spec.simulation.integrator if section == "simulation" else spec.bodies[0].volume_method
    assert value == canonical


def test_thousand_subdivisions_refused_without_allocating():
    """``subdivisions = 1e3`` took all 24 GB of memory until the kernel killed it. Now it is
    refused naming the key, and the process's peak memory does not grow by more than
    50 MiB while it is (the child runs under a 4 GiB address-space limit, so that a
    regression fails with a MemoryError instead of taking the machine down)."""
    code = (
        "import json, resource\n"
        "from softbody.scenes import load_scene\n"
        "before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "try:\n"
        "    load_scene('bouncing-balls', ['bodies.0.mesh.subdivisions=1e3'])\n"
        "    error = ''\n"
        "except BaseException as exc:\n"
        "    error = f'{type(exc).__name__}: {exc}'\n"
        "grew = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before\n"
        "print(json.dumps({'error': error, 'grew_kib': grew}))\n"
    )

    def limit_memory():
        resource.setrlimit(resource.RLIMIT_AS, (4 * 1024**3, 4 * 1024**3))

    result = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=limit_memory,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert report["error"].startswith("SizeLimitError: bodies.0.mesh.subdivisions: a mesh of")
    assert report["grew_kib"] < 50 * 1024


# -- scene files ---------------------------------------------------------------------------
def test_binary_scene_file_is_named(tmp_path):
    """A binary (non-UTF-8) file given as a scene: the error names the file. Before it was
    "'utf-8' codec can't decode byte 0x89 ...", naming nothing."""
    path = tmp_path / "picture.toml"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe")
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert str(info.value).startswith(f"{path}: not a scene file")


def test_invalid_toml_error_names_the_path(tmp_path):
    """A TOML syntax error names the file's path, not only its stem."""
    path = tmp_path / "s.toml"
    path.write_text("[simulation\n")
    with pytest.raises(SceneError, match=rf"^{re.escape(str(path))}: not valid TOML"):
        load_scene(path)


def test_oversized_scene_file_is_refused_by_size(tmp_path):
    """A file over limits.MAX_SCENE_FILE_BYTES is refused from its size, naming it (a
    sparse file: nothing is written to disk). Before, a 2 GB file took 4.3 GB of memory
    before failing."""
    path = tmp_path / "huge.toml"
    with path.open("wb") as f:
        f.truncate(limits.MAX_SCENE_FILE_BYTES + 1)
    with pytest.raises(SizeLimitError, match=rf"^{re.escape(str(path))}: the file is 64 MiB"):
        load_scene(path)


@pytest.mark.parametrize("argv", [["--show", "/etc/passwd"], ["--copy", "/etc/passwd", "x"]])
def test_scenes_show_and_copy_only_built_in_scenes(tmp_path, monkeypatch, capsys, argv):
    """``softbody scenes --show /etc/passwd`` printed the file; --show and --copy take
    built-in scene names only: exit 2, one line naming the built-ins, nothing printed
    or written."""
    monkeypatch.chdir(tmp_path)
    assert main(["scenes", *argv]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith("softbody: error: unknown scene '/etc/passwd'; built-in")
    assert captured.err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_scenes_show_refuses_a_local_scene_file(tmp_path, monkeypatch, capsys):
    """A scene file in the current folder is not a built-in scene either."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.toml").write_text('name = "mine"\n')
    assert main(["scenes", "--show", "mine.toml"]) == 2
    assert capsys.readouterr().out == ""


def test_numbers_as_names_read_as_their_text():
    """``name = 2024`` was taken as the text "2024" before the schema (the loader called
    str()), and still is, for the scene, a body and the description; a boolean is not a
    name."""
    scene = load_scene("hanging-ball", ["name=2024", "bodies.0.name=7", "description=1.5"])
    assert (scene.name, scene.body_names[0], scene.description) == ("2024", "7", "1.5")
    assert _error("hanging-ball", ["name=true"]) == "name: must be a string, got True"
