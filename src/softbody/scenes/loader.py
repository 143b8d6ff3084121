"""Scenes are data: a TOML file describing bodies, colliders, contacts, integration and
rendering, loaded into a :class:`~softbody.ModelBuilder`.

Every key is checked: an unknown or misspelt key is an error that lists the valid ones.
Overrides use dotted paths (``simulation.dt=0.001``, ``bodies.0.gas.nrt=50``).
See ``docs/scenes.md`` or any built-in scene (``softbody scenes --show NAME``).
"""

from __future__ import annotations

import copy
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from softbody.collision.colliders import (
    ColliderBox,
    ColliderPlane,
    ColliderSphere,
    MotionOscillation,
    MotionRotation,
    MotionTranslation,
    rotation_about,
)
from softbody.gas import Gas
from softbody.mesh import generators
from softbody.mesh.io import load_mesh
from softbody.mesh.topology import half_edges
from softbody.mesh.tri_mesh import TriMesh
from softbody.render.frame import PALETTE, RenderSettings
from softbody.render.raster import Camera
from softbody.sim.builder import ModelBuilder
from softbody.sim.model import Model


class SceneError(ValueError):
    """A scene file or override is wrong; the message says where and why."""


# -- schema: allowed keys per table ------------------------------------------------------
SIMULATION_KEYS = {"integrator", "dt", "duration", "gravity", "implicit_tolerance"}
CONTACT_KEYS = {"mode", "restitution", "friction", "margin"}
RENDER_KEYS = {
    "width",
    "height",
    "fps",
    "camera",
    "target",
    "fov",
    "style",
    "velocity_vectors",
    "velocity_scale",
    "bounding_objects",
    "ground_size",
}
BODY_KEYS = {
    "name",
    "kind",
    "mesh",
    "position",
    "rotation",
    "scale",
    "mass",
    "stiffness",
    "damping",
    "bend_stiffness",
    "bend_damping",
    "gas",
    "pressure",
    "volume_method",
    "contact_shape",
    "velocity",
    "pin",
    "color",
    "mass_distribution",
    "monte_carlo_samples",
    "seed",
}
MESH_KEYS = {
    "shape",
    "file",
    "builtin",
    "subdivisions",
    "radius",
    "extents",
    "length",
    "height",
    "rings",
    "segments",
    "size",
    "resolution",
    "reorder",
}
GAS_KEYS = {
    "law",
    "nrt",
    "pressure",
    "gamma",
    "reference_volume",
    "ambient_pressure",
    "schedule",
    "moles",
    "temperature",
}
PIN_KEYS = {"indices", "above", "below", "boundary"}
ATTACHMENT_KEYS = {"body", "vertex", "anchor", "stiffness", "damping", "rest_length"}
COLLIDER_KEYS = {
    "type",
    "center",
    "point",
    "normal",
    "half_extents",
    "radius",
    "rotation",
    "container",
    "restitution",
    "friction",
    "motion",
}
MOTION_KEYS = {"type", "angular_velocity", "pivot", "velocity", "amplitude", "frequency"}
TOP_KEYS = {
    "name",
    "description",
    "simulation",
    "contact",
    "render",
    "bodies",
    "attachments",
    "colliders",
}


def _check_keys(table: dict, allowed: set[str], where: str) -> None:
    if not isinstance(table, dict):
        raise SceneError(f"{where} must be a table, got {type(table).__name__}")
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise SceneError(
            f"unknown scene key {where + '.' if where else ''}{unknown[0]} "
            f"(valid: {', '.join(sorted(allowed))})"
        )


# -- built-in scenes ---------------------------------------------------------------------
def _scene_dir():
    return resources.files("softbody.scenes")


def list_scenes() -> dict[str, str]:
    """Built-in scene names and their one-line descriptions."""
    out = {}
    for entry in sorted(_scene_dir().iterdir(), key=lambda p: p.name):
        if entry.name.endswith(".toml"):
            data = tomllib.loads(entry.read_text())
            out[entry.name[:-5]] = data.get("description", "")
    return out


def scene_text(name_or_path: str | Path) -> tuple[str, str, Path | None]:
    """(name, TOML text, folder relative meshes are read from) of a built-in scene or a file."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        if not p.is_file():
            raise SceneError(f"{p}: no such scene file")
        return p.stem, p.read_text(), p.parent
    entry = _scene_dir() / f"{name_or_path}.toml"
    if not entry.is_file():
        names = ", ".join(list_scenes())
        raise SceneError(
            f"unknown scene {str(name_or_path)!r}; built-in scenes: {names} "
            "(or give a path to a .toml file)"
        )
    return str(name_or_path), entry.read_text(), None


# -- overrides ---------------------------------------------------------------------------
def parse_override(text: str) -> tuple[list[str], Any]:
    """'a.b.0.c=value' -> (['a', 'b', '0', 'c'], value); the value is read as TOML
    (numbers, booleans, arrays, quoted strings) or else taken as a bare string."""
    if "=" not in text:
        raise SceneError(f"override {text!r} must look like key=value")
    key, value = text.split("=", 1)
    path = [k for k in key.strip().split(".") if k]
    if not path:
        raise SceneError(f"override {text!r} has an empty key")
    try:
        parsed = tomllib.loads(f"v = {value.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        parsed = value.strip()
    return path, parsed


def apply_overrides(data: dict, overrides: list[str]) -> dict:
    """A copy of scene ``data`` with dotted-path overrides applied (keys are checked when
    the scene is built)."""
    out = copy.deepcopy(data)
    for text in overrides:
        path, value = parse_override(text)
        node: Any = out
        for depth, key in enumerate(path[:-1]):
            where = ".".join(path[: depth + 1])
            if isinstance(node, list):
                if not key.isdigit() or int(key) >= len(node):
                    raise SceneError(
                        f"override {text!r}: {where} is not an index of the {len(node)} entries"
                    )
                node = node[int(key)]
            else:
                if key not in node:
                    node[key] = {}
                node = node[key]
                if not isinstance(node, dict | list):
                    raise SceneError(f"override {text!r}: {where} is a value, not a table")
        last = path[-1]
        if isinstance(node, list):
            if not last.isdigit() or int(last) >= len(node):
                raise SceneError(f"override {text!r}: no entry {last}")
            node[int(last)] = value
        else:
            node[last] = value
    return out


# -- building ------------------------------------------------------------------------------
def _vec(value, where, n=3) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"{where} must be {n} numbers, got {value!r}") from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise SceneError(f"{where} must be {n} finite numbers, got {value!r}")
    return v


def _mesh(spec: dict, where: str, base: Path | None) -> TriMesh:
    _check_keys(spec, MESH_KEYS, where)
    kinds = [k for k in ("shape", "file", "builtin") if k in spec]
    if len(kinds) != 1:
        raise SceneError(f"{where} needs exactly one of shape, file or builtin")
    if "file" in spec:
        path = Path(spec["file"])
        if not path.is_absolute() and base is not None:
            path = base / path
        mesh = load_mesh(path)
    elif "builtin" in spec:
        name = str(spec["builtin"])
        entry = _scene_dir() / "meshes" / f"{name}.obj"
        if not entry.is_file():
            raise SceneError(f"{where}.builtin: no built-in mesh {name!r} (have: hand)")
        with resources.as_file(entry) as p:
            mesh = load_mesh(p)
    else:
        shape = spec["shape"]
        args = {k: v for k, v in spec.items() if k not in ("shape", "reorder")}
        makers = {
            "icosphere": generators.icosphere,
            "uv_sphere": generators.uv_sphere,
            "box": generators.box,
            "capsule": generators.capsule,
            "cylinder": generators.cylinder,
            "rectangle": generators.rectangle,
        }
        if shape not in makers:
            raise SceneError(f"{where}.shape: unknown shape {shape!r} (valid: {', '.join(makers)})")
        if shape == "icosphere":
            args.setdefault("subdivisions", 2)
        try:
            mesh = makers[shape](**args)
        except TypeError as exc:
            raise SceneError(f"{where}: {exc}") from None
    return mesh.reordered() if spec.get("reorder", False) else mesh


def _gas(spec, where: str, *, cloth: bool) -> Gas:
    if isinstance(spec, int | float):
        return Gas.fixed_pressure(spec) if cloth else Gas.isothermal(spec)
    _check_keys(spec, GAS_KEYS, where)
    law = spec.get("law", "isothermal")
    common = {"ambient_pressure": spec.get("ambient_pressure", 0.0)}
    schedule = spec.get("schedule")
    if law == "isothermal":
        if "moles" in spec:
            return Gas.ideal(spec["moles"], spec.get("temperature", 293.15), **common)
        return Gas.isothermal(_required(spec, "nrt", where), schedule=schedule, **common)
    if law == "fixed_pressure":
        return Gas.fixed_pressure(_required(spec, "pressure", where), schedule=schedule, **common)
    if law == "adiabatic":
        return Gas.adiabatic(
            _required(spec, "nrt", where),
            gamma=spec.get("gamma", 1.4),
            reference_volume=spec.get("reference_volume"),
            schedule=schedule,
            **common,
        )
    raise SceneError(
        f"{where}.law: unknown gas law {law!r} (valid: isothermal, fixed_pressure, adiabatic)"
    )


def _required(spec: dict, key: str, where: str):
    if key not in spec:
        raise SceneError(f"{where}.{key} is required")
    return spec[key]


def _pins(spec, mesh: TriMesh, where: str) -> np.ndarray | None:
    if spec is None:
        return None
    _check_keys(spec, PIN_KEYS, where)
    mask = np.zeros(mesh.vertex_count, dtype=bool)
    if "indices" in spec:
        idx = np.asarray(spec["indices"], dtype=np.int64)
        if idx.size and (idx.min() < 0 or idx.max() >= mesh.vertex_count):
            raise SceneError(f"{where}.indices must lie in [0, {mesh.vertex_count - 1}]")
        mask[idx] = True
    if "above" in spec:
        mask |= mesh.vertices[:, 1] > float(spec["above"])
    if "below" in spec:
        mask |= mesh.vertices[:, 1] < float(spec["below"])
    if spec.get("boundary", False):
        he = np.sort(half_edges(mesh.faces), axis=1)
        edges, counts = np.unique(he, axis=0, return_counts=True)
        mask[edges[counts == 1].ravel()] = True
    if not mask.any():
        raise SceneError(f"{where} selects no vertex")
    return np.flatnonzero(mask)


def _motion(spec, where):
    if spec is None:
        return None
    _check_keys(spec, MOTION_KEYS, where)
    kind = spec.get("type")
    if kind == "rotation":
        pivot = spec.get("pivot")
        return MotionRotation(
            _vec(_required(spec, "angular_velocity", where), f"{where}.angular_velocity"),
            None if pivot is None else _vec(pivot, f"{where}.pivot"),
        )
    if kind == "translation":
        return MotionTranslation(_vec(_required(spec, "velocity", where), f"{where}.velocity"))
    if kind == "oscillation":
        return MotionOscillation(
            _vec(_required(spec, "amplitude", where), f"{where}.amplitude"),
            float(_required(spec, "frequency", where)),
        )
    raise SceneError(f"{where}.type must be rotation, translation or oscillation, got {kind!r}")


def _rotation(spec, where) -> np.ndarray | None:
    """[axis_x, axis_y, axis_z, angle_degrees] -> (3, 3), or None."""
    if spec is None:
        return None
    v = _vec(spec, where, 4)
    return rotation_about(v[:3], np.radians(v[3]))


def _dt(value) -> float | str:
    """simulation.dt: seconds, or "auto" (chosen from the stability estimate)."""
    if value == "auto":
        return "auto"
    try:
        dt = float(value)
    except (TypeError, ValueError):
        raise SceneError(f'simulation.dt must be seconds or "auto", got {value!r}') from None
    if not (np.isfinite(dt) and dt > 0):
        raise SceneError(f"simulation.dt must be > 0 seconds, got {value!r}")
    return dt


def _tolerance(value) -> float:
    """simulation.implicit_tolerance: the implicit schemes' relative CG residual, in (0, 1)."""
    try:
        tolerance = float(value)
    except (TypeError, ValueError):
        tolerance = np.nan
    if not (np.isfinite(tolerance) and 0 < tolerance < 1):
        raise SceneError(f"simulation.implicit_tolerance must lie in (0, 1), got {value!r}")
    return tolerance


@dataclass
class Scene:
    """A loaded scene: the model and how to run and draw it."""

    name: str
    description: str
    data: dict
    """The scene table after overrides (what the JSON summary records)."""
    model: Model
    integrator: str
    dt: float | str
    """Time step [s], or "auto"."""
    duration: float
    render: RenderSettings
    body_names: list[str]
    implicit_tolerance: float = 1e-6
    """``implicit_euler`` and ``bdf2``: the CG solve's relative residual (``Simulator``)."""


def build_scene(name: str, data: dict, base: Path | None = None) -> Scene:
    """Check ``data`` (a parsed scene table) and build its model."""
    _check_keys(data, TOP_KEYS, "")
    sim = data.get("simulation", {})
    _check_keys(sim, SIMULATION_KEYS, "simulation")
    gravity = _vec(sim.get("gravity", [0.0, -9.81, 0.0]), "simulation.gravity")
    builder = ModelBuilder(gravity=gravity)

    contact = data.get("contact", {})
    _check_keys(contact, CONTACT_KEYS, "contact")
    if contact:
        builder.set_soft_contact(
            contact.get("mode", "surface"),
            restitution=contact.get("restitution", 0.5),
            friction=contact.get("friction", 0.1),
            margin=contact.get("margin"),
        )

    bodies = data.get("bodies", [])
    if not isinstance(bodies, list) or not bodies:
        raise SceneError("a scene needs at least one [[bodies]] entry")
    names, colors, meshes = [], [], []
    for b, spec in enumerate(bodies):
        where = f"bodies.{b}"
        _check_keys(spec, BODY_KEYS, where)
        kind = spec.get("kind", "soft")
        if kind not in ("soft", "cloth"):
            raise SceneError(f"{where}.kind must be 'soft' or 'cloth', got {kind!r}")
        mesh = _mesh(_required(spec, "mesh", where), f"{where}.mesh", base)
        if "scale" in spec:
            mesh = mesh.scaled(spec["scale"])
        rot = _rotation(spec.get("rotation"), f"{where}.rotation")
        if rot is not None:
            mesh = mesh.rotated(rot)
        mesh = mesh.translated(_vec(spec.get("position", [0, 0, 0]), f"{where}.position"))
        common = dict(
            mass=_required(spec, "mass", where),
            stiffness=_required(spec, "stiffness", where),
            damping=spec.get("damping", 0.0),
            pinned=_pins(spec.get("pin"), mesh, f"{where}.pin"),
            bend_stiffness=spec.get("bend_stiffness", 0.0),
            bend_damping=spec.get("bend_damping", 0.0),
            mass_distribution=spec.get("mass_distribution", "uniform"),
            velocity=spec.get("velocity", (0.0, 0.0, 0.0)),
        )
        if kind == "cloth":
            for key in ("gas", "volume_method", "contact_shape", "monte_carlo_samples", "seed"):
                if key in spec:
                    raise SceneError(f"{where}.{key} does not apply to a cloth")
            builder.add_cloth(
                mesh,
                pressure=_gas(spec.get("pressure", 0.0), f"{where}.pressure", cloth=True),
                **common,
            )
        else:
            if "pressure" in spec:
                raise SceneError(f"{where}.pressure applies to a cloth; a soft body has gas")
            builder.add_soft_body(
                mesh,
                gas=_gas(_required(spec, "gas", where), f"{where}.gas", cloth=False),
                volume_method=spec.get("volume_method", "exact"),
                contact_shape=spec.get("contact_shape", "bounding_ellipsoid"),
                monte_carlo_samples=spec.get("monte_carlo_samples", 4096),
                seed=spec.get("seed", 0),
                **common,
            )
        names.append(str(spec.get("name", f"body {b}")))
        colors.append(str(spec.get("color", PALETTE[b % len(PALETTE)])))
        meshes.append(mesh)

    for a, spec in enumerate(data.get("attachments", [])):
        where = f"attachments.{a}"
        _check_keys(spec, ATTACHMENT_KEYS, where)
        body = int(_required(spec, "body", where))
        if not 0 <= body < len(meshes):
            raise SceneError(f"{where}.body must be a body index in [0, {len(meshes) - 1}]")
        vertex = spec.get("vertex", "top")
        if vertex == "top":
            vertex = int(np.argmax(meshes[body].vertices[:, 1]))
        builder.add_attachment(
            builder.body_particles(body)[int(vertex)],
            _vec(_required(spec, "anchor", where), f"{where}.anchor"),
            stiffness=_required(spec, "stiffness", where),
            damping=spec.get("damping", 0.0),
            rest_length=spec.get("rest_length", 0.0),
        )

    for c, spec in enumerate(data.get("colliders", [])):
        where = f"colliders.{c}"
        _check_keys(spec, COLLIDER_KEYS, where)
        kind = spec.get("type")
        common = dict(
            restitution=spec.get("restitution", 0.5),
            friction=spec.get("friction", 0.1),
            motion=_motion(spec.get("motion"), f"{where}.motion"),
        )
        if kind == "plane":
            col = ColliderPlane(
                point=_vec(spec.get("point", [0, 0, 0]), f"{where}.point"),
                normal=_vec(spec.get("normal", [0, 1, 0]), f"{where}.normal"),
                **common,
            )
        elif kind == "box":
            col = ColliderBox(
                center=_vec(spec.get("center", [0, 0, 0]), f"{where}.center"),
                half_extents=_vec(_required(spec, "half_extents", where), f"{where}.half_extents"),
                rotation=_rotation(spec.get("rotation"), f"{where}.rotation"),
                container=bool(spec.get("container", False)),
                **common,
            )
        elif kind == "sphere":
            col = ColliderSphere(
                center=_vec(spec.get("center", [0, 0, 0]), f"{where}.center"),
                radius=float(_required(spec, "radius", where)),
                **common,
            )
        else:
            raise SceneError(f"{where}.type must be plane, box or sphere, got {kind!r}")
        try:
            builder.add_collider(col)
        except ValueError as exc:
            raise SceneError(f"{where}: {exc}") from None

    model = builder.finalize()

    rnd = data.get("render", {})
    _check_keys(rnd, RENDER_KEYS, "render")
    camera = Camera(
        eye=tuple(_vec(rnd.get("camera", [0.0, 1.5, 6.0]), "render.camera")),
        target=tuple(_vec(rnd.get("target", [0.0, 0.5, 0.0]), "render.target")),
        fov=float(rnd.get("fov", 40.0)),
    )
    render = RenderSettings(
        width=rnd.get("width", 640),
        height=rnd.get("height", 480),
        fps=rnd.get("fps", 30.0),
        camera=camera,
        style=rnd.get("style", "solid"),
        velocity_vectors=bool(rnd.get("velocity_vectors", False)),
        velocity_scale=float(rnd.get("velocity_scale", 0.05)),
        bounding_objects=bool(rnd.get("bounding_objects", False)),
        ground_size=float(rnd.get("ground_size", 8.0)),
        body_colors=tuple(colors),
    )
    duration = float(sim.get("duration", 5.0))
    if not (np.isfinite(duration) and duration > 0):
        raise SceneError(f"simulation.duration must be > 0 seconds, got {duration!r}")
    return Scene(
        name=str(data.get("name", name)),
        description=str(data.get("description", "")),
        data=data,
        model=model,
        integrator=str(sim.get("integrator", "midpoint")),
        dt=_dt(sim.get("dt", 1e-3)),
        duration=duration,
        render=render,
        body_names=names,
        implicit_tolerance=_tolerance(sim.get("implicit_tolerance", 1e-6)),
    )


def load_scene(name_or_path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> Scene:
    """Load a built-in scene by name, or a scene file, with ``key=value`` overrides."""
    name, text, base = scene_text(name_or_path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{name}: not valid TOML ({exc})") from None
    data = apply_overrides(data, list(overrides))
    try:
        return build_scene(name, data, base)
    except SceneError:
        raise
    except (ValueError, TypeError) as exc:
        raise SceneError(f"{name}: {exc}") from None
