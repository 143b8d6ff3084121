"""Scenes are data: a TOML file describing bodies, colliders, contacts, integration and
rendering, loaded into a :class:`~softbody.ModelBuilder`.

Every key is checked against :mod:`softbody.scenes.schema` (types, units, defaults and
bounds; ``softbody scenes --schema`` prints it as JSON Schema) before anything is built:
an unknown or misspelt key is an error that lists the valid ones, and every error is one
line naming the dotted key. Overrides use dotted paths (``simulation.dt=0.001``,
``bodies.0.gas.nrt=50``). Any built-in scene is an example (``softbody scenes --show NAME``).
"""

from __future__ import annotations

import copy
import os
import re
import tomllib
from dataclasses import dataclass
from importlib import resources
from itertools import islice
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from softbody import limits
from softbody.bending import Bending
from softbody.collision.colliders import (
    ColliderBox,
    ColliderMesh,
    ColliderPlane,
    ColliderSphere,
    MotionOscillation,
    MotionRotation,
    MotionTranslation,
    rotation_about,
)
from softbody.errors import SizeLimitError
from softbody.gas import Gas
from softbody.membrane import Membrane
from softbody.mesh import generators
from softbody.mesh.io import file_problem, load_mesh
from softbody.mesh.topology import half_edges
from softbody.mesh.tri_mesh import TriMesh
from softbody.render.frame import PALETTE, RenderSettings
from softbody.render.raster import Camera
from softbody.scenes import schema
from softbody.sim.builder import ModelBuilder
from softbody.sim.model import Model


class SceneError(ValueError):
    """A scene file or override is wrong; the message says where and why."""


#: Range of a built model's derived quantities (particle masses [kg], initial energies
#: [J]) in which their squares and reciprocals are normal float64 numbers (about 1e-308 to
#: 1e308): outside it a run overflows to infinity, or LAPACK's stability estimate fails
#: on a denormal mass.
SAFE_MAGNITUDE = (1e-150, 1e150)


#: Deepest nesting a scene or sweep file may have: key components in one dotted key
#: (``a.b.c`` is 3) and arrays or inline tables inside each other; a scene needs a few.
#: Python's TOML parser takes memory quadratic in a dotted key's length (a 50,000-part
#: key in a 100 KB file took over 8 GB) and recurses into nested arrays.
MAX_TOML_NESTING = 64

# strings and comments, whose dots and brackets are text, not structure
_TOML_TEXT = re.compile(
    r'"""[\s\S]*?"""|\'\'\'[\s\S]*?\'\'\'|"(?:[^"\\\n]|\\.)*"|\'[^\'\n]*\'|#[^\n]*'
)
# MAX_TOML_NESTING + 1 key parts joined by dots (a float's "1.5" is two)
_TOML_DEEP_KEY = re.compile(
    r"(?<![\w-])(?:[\w-]++|\"\")(?:[ \t]*\.[ \t]*(?:[\w-]++|\"\"))"
    + f"{{{MAX_TOML_NESTING}}}"
)


def parse_toml(text: str, label: str) -> dict:
    """``text`` parsed as TOML; ``label`` (the file) names it in errors. A UTF-8 byte
    order mark at the start is dropped (editors on Windows write one), and nesting deeper
    than :data:`MAX_TOML_NESTING` is refused before the parser sees it.

    Raises :class:`SceneError` with one line naming ``label``.
    """
    text = text.removeprefix("\ufeff")
    check_toml_nesting(text, label)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{label}: not valid TOML ({exc})") from None


def check_toml_nesting(text: str, label: str) -> None:
    """Refuse TOML ``text`` whose dotted keys have more than :data:`MAX_TOML_NESTING`
    parts or whose arrays and inline tables nest deeper (:class:`SceneError` naming
    ``label`` and the line), in time linear in its length."""

    def blank(match: re.Match) -> str:
        # a string keeps its place as a quoted key part, and its lines
        found = match.group()
        return ("" if found[0] == "#" else '""') + "\n" * found.count("\n")

    bare = _TOML_TEXT.sub(blank, text)
    deep = _TOML_DEEP_KEY.search(bare)
    where = None
    if deep is not None:
        where = deep.start()
        what = f"a dotted key of more than {MAX_TOML_NESTING} parts"
    else:
        brackets = re.sub(r"[^\[\]{}]+", "", bare)  # short: a scene has a few hundred
        codes = np.frombuffer(brackets.encode("ascii"), dtype=np.uint8)
        depth = np.cumsum(np.isin(codes, (91, 123)).astype(np.int64) - np.isin(codes, (93, 125)))
        if depth.size and depth.max() > MAX_TOML_NESTING:
            k = int(np.argmax(depth > MAX_TOML_NESTING))
            where = next(islice(re.finditer(r"[\[\]{}]", bare), k, None)).start()
            what = f"arrays or tables nested more than {MAX_TOML_NESTING} deep"
    if where is not None:
        line = bare.count("\n", 0, where) + 1
        raise SceneError(f"{label}: line {line}: {what} (a scene needs a few)")


# -- built-in scenes ---------------------------------------------------------------------
def _scene_dir():
    return resources.files("softbody.scenes")


def list_scenes() -> dict[str, str]:
    """Built-in scene names and their one-line descriptions."""
    out = {}
    for entry in sorted(_scene_dir().iterdir(), key=lambda p: p.name):
        if entry.name.endswith(".toml"):
            data = tomllib.loads(entry.read_text(encoding="utf-8"))
            out[entry.name[:-5]] = data.get("description", "")
    return out


def builtin_scene_text(name: str) -> str:
    """The TOML text of the built-in scene ``name``; any other name (a path included) is
    refused, so that ``softbody scenes --show`` prints scenes and nothing else."""
    scenes = list_scenes()
    if name not in scenes:
        raise SceneError(f"unknown scene {str(name)[:200]!r}; built-in scenes: {', '.join(scenes)}")
    return (_scene_dir() / f"{name}.toml").read_text(encoding="utf-8")


def _read_scene_file(p: Path) -> str:
    """A scene file's text, refused by size before it is read and named in every error."""
    try:
        with p.open("rb") as f:
            size = os.fstat(f.fileno()).st_size
            limits.check_file_size(str(p), size, factor=4, maximum=limits.MAX_SCENE_FILE_BYTES)
            # st_size is 0 for /proc files and pipes: read at most one byte past the limit
            raw = f.read(limits.MAX_SCENE_FILE_BYTES + 1)
    except OSError as exc:
        raise SceneError(f"{p}: cannot read the scene file ({exc.strerror or exc})") from None
    limits.check_file_size(str(p), len(raw), factor=4, maximum=limits.MAX_SCENE_FILE_BYTES)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(
            f"{p}: not a scene file (TOML is UTF-8 text; byte {exc.start} is not)"
        ) from None
    if "\x00" in text:
        raise SceneError(f"{p}: not a scene file (it holds NUL bytes: a binary file?)")
    return text


def scene_text(name_or_path: str | Path) -> tuple[str, str, Path | None]:
    """(name, TOML text, folder relative meshes are read from) of a built-in scene or a file."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        problem = file_problem(p)
        if problem is not None:
            what = "no such scene file" if problem == "no such file" else problem
            raise SceneError(f"{p}: {what}")
        return p.stem, _read_scene_file(p), p.parent
    if str(name_or_path) not in list_scenes():
        names = ", ".join(list_scenes())
        raise SceneError(
            f"unknown scene {str(name_or_path)[:200]!r}; built-in scenes: {names} "
            "(or give a path to a .toml file)"
        )
    return str(name_or_path), builtin_scene_text(str(name_or_path)), None


# -- overrides ---------------------------------------------------------------------------
def parse_override(text: str) -> tuple[list[str], Any]:
    """'a.b.0.c=value' -> (['a', 'b', '0', 'c'], value); the value is read as TOML
    (numbers, booleans, arrays, quoted strings) or else taken as a bare string."""
    if "=" not in text:
        raise SceneError(f"override {text[:200]!r} must look like key=value")
    key, value = text.split("=", 1)
    path = [k for k in key.strip().split(".") if k]
    if not path:
        raise SceneError(f"override {text[:200]!r} has an empty key")
    check_toml_nesting(value, f"override {key.strip()[:200]!r}")
    try:
        parsed = tomllib.loads(f"v = {value.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        parsed = value.strip()
    return path, parsed


def apply_overrides(data: dict, overrides: list[str]) -> dict:
    """A copy of scene ``data`` with dotted-path overrides applied (keys are checked when
    the scene is validated)."""
    out = copy.deepcopy(data)
    for text in overrides:
        path, value = parse_override(text)
        set_path(out, path, value, text)
    return out


def set_path(data: dict, path: list[str], value: Any, text: str | None = None) -> None:
    """Set ``value`` at the dotted ``path`` (``["bodies", "0", "gas", "nrt"]``) of scene
    ``data`` in place, making missing tables; ``text`` names the override in errors
    (default: the dotted path). A list index must exist; the key itself is checked when
    the scene is validated."""
    text = ".".join(path) if text is None else text
    shown = text if len(text) <= 200 else text[:197] + "..."
    node: Any = data
    for depth, key in enumerate(path):
        where = ".".join(path[: depth + 1])
        last = depth == len(path) - 1
        if isinstance(node, list):
            if not key.isdigit() or int(key) >= len(node):
                raise SceneError(
                    f"override {shown!r}: {where} is not an index of the {len(node)} entries"
                )
            if last:
                node[int(key)] = value
            else:
                node = node[int(key)]
        elif isinstance(node, dict):
            if last:
                node[key] = value
            else:
                node = node.setdefault(key, {})
        else:
            parent = ".".join(path[:depth])
            raise SceneError(f"override {shown!r}: {parent} is a value, not a table")


# -- building ------------------------------------------------------------------------------
def _mesh(spec: schema.BaseModel, where: str, base: Path | None) -> TriMesh:
    if isinstance(spec, schema.MeshFile):
        path = Path(spec.file)
        if not path.is_absolute() and base is not None:
            path = base / path
        mesh = load_mesh(path)
    elif isinstance(spec, schema.MeshBuiltin):
        with resources.as_file(_scene_dir() / "meshes" / f"{spec.builtin}.obj") as p:
            mesh = load_mesh(p)
    else:
        args = spec.model_dump(exclude={"shape", "reorder"})
        makers = {
            schema.Icosphere: generators.icosphere,
            schema.UvSphere: generators.uv_sphere,
            schema.Box: generators.box,
            schema.Capsule: generators.capsule,
            schema.Cylinder: generators.cylinder,
            schema.Rectangle: generators.rectangle,
        }
        mesh = makers[type(spec)](**args)
    return mesh.reordered() if spec.reorder else mesh


def _collider_mesh(spec: schema.MeshCollider, base: Path | None) -> TriMesh | Path:
    """A mesh collider's mesh: a file's path (relative to the scene's folder; ColliderMesh
    reads and checks it, naming it), or the generated or built-in mesh."""
    file = spec.file if spec.file is not None else getattr(spec.mesh, "file", None)
    if file is not None:
        path = Path(file)
        return base / path if not path.is_absolute() and base is not None else path
    return _mesh(spec.mesh, "mesh", base)


def _bending(spec: schema.MaterialBending | None) -> Bending | None:
    """A body's ``bending`` table as a :class:`softbody.Bending` (None: none)."""
    if spec is None:
        return None
    if spec.stiffness is not None:
        return Bending(spec.stiffness, rest_shape=spec.rest_shape)
    return Bending.from_material(
        spec.youngs_modulus, spec.poisson_ratio, spec.thickness, rest_shape=spec.rest_shape
    )


def _gas(spec, *, cloth: bool) -> Gas:
    """A validated gas (a number or one of the law tables) as a :class:`Gas`."""
    if isinstance(spec, int | float):
        return Gas.fixed_pressure(spec) if cloth else Gas.isothermal(spec)
    common = {"ambient_pressure": spec.ambient_pressure}
    if isinstance(spec, schema.Isothermal):
        if spec.moles is not None:
            return Gas.ideal(spec.moles, spec.temperature, **common)
        return Gas.isothermal(spec.nrt, schedule=spec.schedule, **common)
    if isinstance(spec, schema.FixedPressure):
        return Gas.fixed_pressure(spec.pressure, schedule=spec.schedule, **common)
    if isinstance(spec, schema.Ideal):
        return Gas.ideal(
            spec.moles,
            spec.temperature,
            molar_mass=spec.molar_mass,
            gamma=spec.gamma,
            process=spec.process,
            ambient_temperature=spec.ambient_temperature,
            **common,
        )
    return Gas.adiabatic(
        spec.nrt,
        gamma=spec.gamma,
        reference_volume=spec.reference_volume,
        schedule=spec.schedule,
        **common,
    )


def _membrane(spec, mesh: TriMesh, where: str) -> list | None:
    """A validated ``membrane`` (a table or an array of them) as the builder's layers of
    (Membrane, faces or None)."""
    if spec is None:
        return None
    layers = []
    for k, layer in enumerate(spec if isinstance(spec, list) else [spec]):
        at = f"{where}.{k}" if isinstance(spec, list) else where
        common = {"damping": layer.damping}
        if isinstance(layer, schema.NeoHookean):
            material = Membrane.neo_hookean(layer.shear_modulus, layer.thickness, **common)
        elif isinstance(layer, schema.MooneyRivlin):
            material = Membrane.mooney_rivlin(layer.c10, layer.c01, layer.thickness, **common)
        else:
            material = Membrane.stvk(layer.youngs_modulus, layer.poisson_ratio,
                                     layer.thickness, **common)  # fmt: skip
        faces = layer.faces
        if isinstance(faces, schema.FaceSide):
            centres = mesh.vertices[mesh.faces].mean(axis=1)[:, "xyz".index(faces.axis)]
            side = centres > faces.above if faces.above is not None else centres < faces.below
            faces = np.flatnonzero(side)
            if faces.size == 0:
                raise SceneError(f"{at}.faces selects no face")
        elif faces is not None and faces and max(faces) >= mesh.face_count:
            raise SceneError(f"{at}.faces must lie in [0, {mesh.face_count - 1}]")
        layers.append((material, faces))
    return layers


def _pins(spec: schema.Pin | None, mesh: TriMesh, where: str) -> np.ndarray | None:
    if spec is None:
        return None
    mask = np.zeros(mesh.vertex_count, dtype=bool)
    if spec.indices is not None:
        idx = np.asarray(spec.indices, dtype=np.int64)
        if idx.size and idx.max() >= mesh.vertex_count:
            raise SceneError(f"{where}.indices must lie in [0, {mesh.vertex_count - 1}]")
        mask[idx] = True
    if spec.above is not None:
        mask |= mesh.vertices[:, 1] > spec.above
    if spec.below is not None:
        mask |= mesh.vertices[:, 1] < spec.below
    if spec.boundary:
        he = np.sort(half_edges(mesh.faces), axis=1)
        edges, counts = np.unique(he, axis=0, return_counts=True)
        mask[edges[counts == 1].ravel()] = True
    if not mask.any():
        raise SceneError(f"{where} selects no vertex")
    return np.flatnonzero(mask)


def _motion(spec):
    if isinstance(spec, schema.Rotating):
        pivot = None if spec.pivot is None else np.array(spec.pivot)
        return MotionRotation(np.array(spec.angular_velocity), pivot)
    if isinstance(spec, schema.Translating):
        return MotionTranslation(np.array(spec.velocity))
    if isinstance(spec, schema.Oscillating):
        return MotionOscillation(np.array(spec.amplitude), spec.frequency)
    return None


def _rotation(spec) -> np.ndarray | None:
    """[axis_x, axis_y, axis_z, angle_degrees] -> (3, 3), or None."""
    if spec is None:
        return None
    return rotation_about(spec[:3], np.radians(spec[3]))


def _add_flows(spec: schema.SceneSpec, builder: ModelBuilder) -> None:
    """The scene's vents, orifices, inflators and leaks added to ``builder``; the
    builder's refusal (a body whose gas is prescribed, not an ideal gas) names the key."""
    for table in ("vents", "orifices", "inflators", "leaks"):
        for k, entry in enumerate(getattr(spec, table)):
            bodies = spec.flow_bodies(table, k)
            try:
                if table == "vents":
                    builder.add_vent(
                        bodies[0],
                        area=entry.area,
                        discharge_coefficient=entry.discharge_coefficient,
                        opening_pressure=entry.opening_pressure,
                        opening_time=entry.opening_time,
                    )
                elif table == "orifices":
                    builder.add_orifice(
                        *bodies, area=entry.area, discharge_coefficient=entry.discharge_coefficient
                    )
                elif table == "inflators":
                    builder.add_inflator(
                        bodies[0], mass_flow=entry.mass_flow, temperature=entry.temperature
                    )
                else:
                    builder.add_leak(bodies[0], coefficient=entry.coefficient)
            except ValueError as exc:
                raise SceneError(f"{table}.{k}: {exc}") from None


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


def _check_magnitudes(spec: schema.SceneSpec, model: Model) -> None:
    """Refuse a scene whose particle masses or initial energies lie outside
    :data:`SAFE_MAGNITUDE` (``mass = 1e308`` gives infinite energies, ``mass = 1e-308``
    denormal particle masses), naming the key, before anything runs."""
    from softbody.diagnostics import energies

    low, high = SAFE_MAGNITUDE
    for b in range(len(spec.bodies)):
        start, end = model.body_particle_range[b]
        m = model.particle_mass[start:end]
        if m.size and not (np.all(np.isfinite(m)) and m.min() >= low and m.max() <= high):
            each = m.max() if not m.max() <= high else m.min()
            raise SceneError(
                f"bodies.{b}.mass: {model.body_mass[b]:.3g} kg over {m.size:,} particles gives "
                f"{each:.3g} kg a particle, outside the {low:g} to {high:g} kg that float64 "
                "arithmetic handles"
            )
    with np.errstate(all="ignore"):
        e = energies(model, model.state())
    causes = {
        "kinetic": ("body_kinetic", "mass or velocity"),
        "gravitational": ("body_gravitational", "mass or position, or simulation.gravity"),
        "spring": ("body_spring", "stiffness, bend_stiffness or membrane"),
        "gas": ("body_gas", "gas"),
    }
    for kind, (field, keys) in causes.items():
        for b, value in enumerate(getattr(e, field)):
            if not (np.isfinite(value) and abs(value) <= high):
                raise SceneError(
                    f"bodies.{b}: the initial {kind} energy ({value:.3g} J) is beyond the "
                    f"{high:g} J float64 arithmetic handles: lower bodies.{b}.{keys}"
                )


def validate(data: Any) -> schema.SceneSpec:
    """``data`` (a parsed scene table) checked against :mod:`softbody.scenes.schema` and its
    size guards; raises :class:`SceneError` (one line naming the key) or
    :class:`~softbody.errors.SizeLimitError`."""
    try:
        return schema.validate_scene(data)
    except ValidationError as exc:
        raise SceneError(schema.format_error(exc)) from None


def build_scene(name: str, data: dict, base: Path | None = None) -> Scene:
    """Check ``data`` (a parsed scene table) and build its model."""
    spec = validate(data)
    sim = spec.simulation
    builder = ModelBuilder(gravity=sim.gravity)
    if spec.contact is not None:
        c = spec.contact
        builder.set_soft_contact(
            c.mode,
            self_contact=c.self_contact,
            thickness=c.thickness,
            restitution=c.restitution,
            friction=c.friction,
            margin=c.margin,
        )
    builder.set_air(density=spec.air.density, wind=spec.air.wind)

    names, colors, meshes = [], [], []
    for b, body in enumerate(spec.bodies):
        where = f"bodies.{b}"
        mesh = _mesh(body.mesh, f"{where}.mesh", base)
        if body.scale is not None:
            mesh = mesh.scaled(body.scale)
        rot = _rotation(body.rotation)
        if rot is not None:
            mesh = mesh.rotated(rot)
        mesh = mesh.translated(np.array(body.position))
        common = {key: getattr(body, key) for key in body.BUILDER_ARGUMENTS}
        common["pinned"] = _pins(body.pin, mesh, f"{where}.pin")
        common["bending"] = _bending(body.bending)
        common["membrane"] = _membrane(body.membrane, mesh, f"{where}.membrane")
        if isinstance(body, schema.Cloth):
            builder.add_cloth(mesh, pressure=_gas(body.pressure, cloth=True), **common)
        else:
            builder.add_soft_body(
                mesh,
                gas=_gas(body.gas, cloth=False),
                volume_method=body.volume_method,
                contact_shape=body.contact_shape,
                monte_carlo_samples=body.monte_carlo_samples,
                seed=body.seed,
                **common,
            )
        names.append(body.name if body.name is not None else f"body {b}")
        colors.append(body.color if body.color is not None else PALETTE[b % len(PALETTE)])
        meshes.append(mesh)

    for a, spring in enumerate(spec.attachments):
        where = f"attachments.{a}"
        vertex_count = meshes[spring.body].vertex_count
        vertex = spring.vertex
        if vertex == "top":
            vertex = int(np.argmax(meshes[spring.body].vertices[:, 1]))
        elif vertex >= vertex_count:
            raise SceneError(f"{where}.vertex must lie in [0, {vertex_count - 1}], got {vertex}")
        builder.add_attachment(
            builder.body_particles(spring.body)[vertex],
            spring.anchor,
            stiffness=spring.stiffness,
            damping=spring.damping,
            rest_length=spring.rest_length,
        )

    _add_flows(spec, builder)

    for c, col in enumerate(spec.colliders):
        common = dict(
            restitution=col.restitution, friction=col.friction, motion=_motion(col.motion)
        )
        if isinstance(col, schema.Plane):
            made = ColliderPlane(point=col.point, normal=col.normal, **common)
        elif isinstance(col, schema.BoxCollider):
            made = ColliderBox(
                center=col.center,
                half_extents=col.half_extents,
                rotation=_rotation(col.rotation),
                container=col.container,
                **common,
            )
        try:
            if isinstance(col, schema.Sphere):
                made = ColliderSphere(center=col.center, radius=col.radius, **common)
            elif isinstance(col, schema.MeshCollider):
                made = ColliderMesh(
                    _collider_mesh(col, base),
                    center=col.center,
                    rotation=_rotation(col.rotation),
                    margin=col.margin,
                    sharp_angle=col.sharp_angle,
                    **common,
                )
            builder.add_collider(made)
        except ValueError as exc:
            raise SceneError(f"colliders.{c}: {exc}") from None

    with np.errstate(divide="ignore", over="ignore"):  # a denormal mass: refused below
        model = builder.finalize()
    _check_magnitudes(spec, model)
    r = spec.render
    render = RenderSettings(
        width=r.width,
        height=r.height,
        fps=r.fps,
        camera=Camera(eye=r.camera, target=r.target, fov=r.fov),
        style=r.style,
        velocity_vectors=r.velocity_vectors,
        velocity_scale=r.velocity_scale,
        bounding_objects=r.bounding_objects,
        ground_size=r.ground_size,
        usd_start_frame=r.usd_start_frame,
        body_colors=tuple(colors),
    )
    return Scene(
        name=spec.name if spec.name is not None else name,
        description=spec.description,
        data=data,
        model=model,
        integrator=sim.integrator,
        dt=sim.dt,
        duration=sim.duration,
        render=render,
        body_names=names,
        implicit_tolerance=sim.implicit_tolerance,
    )


def load_scene(name_or_path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> Scene:
    """Load a built-in scene by name, or a scene file, with ``key=value`` overrides.

    Every error is a ValueError with one line naming the file and the key:
    :class:`SceneError`, :class:`~softbody.errors.SizeLimitError` or
    :class:`~softbody.errors.MeshError`.
    """
    name, text, base = scene_text(name_or_path)
    label = name if base is None else str(name_or_path)
    data = parse_toml(text, label)
    data = apply_overrides(data, list(overrides))
    try:
        return build_scene(name, data, base)
    except (SceneError, SizeLimitError):
        raise
    except (ValueError, TypeError) as exc:
        raise SceneError(f"{label}: {exc}") from None
