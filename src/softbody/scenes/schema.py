"""The scene file's schema: every key's type, unit, default and bounds, in one place.

A scene TOML (after ``--set`` overrides) is validated by :func:`validate_scene` before
anything is built: pydantic checks the types and bounds, :func:`check_sizes` then refuses
meshes, sample sets and images too large for this machine's memory (the estimate comes
from the keys alone, nothing is allocated). Errors become one line naming the dotted key
(:func:`format_error`). :func:`scene_json_schema` is the same schema as JSON Schema, for
editors and the documentation (``softbody scenes --schema``).

Numbers are strict: a quoted ``"1.0"`` or ``true`` is not a number, NaN and infinities are
refused. Counts (subdivisions, rings, ...) accept whole floats such as ``1e3``, as TOML
writes them, so that the size guard, not a type error, says why 1e3 is too many.
"""

from __future__ import annotations

import math
from importlib import resources
from itertools import pairwise
from typing import Annotated, Any, ClassVar, Literal

from pydantic import (
    AfterValidator,
    AllowInfNan,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    Strict,
    Tag,
    ValidationError,
    WithJsonSchema,
    model_validator,
)
from pydantic_core import PydanticCustomError

from softbody import limits
from softbody.integrators import Integrator
from softbody.render.frame import MAX_IMAGE_SIDE
from softbody.volume import VolumeMethod

#: Shortest time step [s]: a nanosecond is far below any soft body's stable step; a
#: smaller one is a typo (``dt = 1e-12``). How many steps a run may take is checked where
#: its length is known (``softbody.scenes.plan.plan_frames``, with ``--max-steps``).
MIN_DT = 1e-9
#: Renderer memory per output pixel [bytes]: a 2x2 supersampled float64 colour and depth
#: buffer (4 x 32 B) plus the 8-bit frame and the encoder's copy, rounded up.
BYTES_PER_PIXEL = 160
#: Monte Carlo volume memory per sample line [bytes]: two float64 coordinates, held by the
#: builder and again by the model.
BYTES_PER_SAMPLE = 32
#: Most Monte Carlo sample lines per body: every volume evaluation (each step) tests every
#: line against every triangle, so more would stall a run rather than sharpen it.
MAX_MONTE_CARLO_SAMPLES = 10**6

INTEGRATORS = tuple(m.name.lower() for m in Integrator)


def _builtin_meshes() -> tuple[str, ...]:
    folder = resources.files("softbody.scenes") / "meshes"
    return tuple(sorted(e.name[:-4] for e in folder.iterdir() if e.name.endswith(".obj")))


BUILTIN_MESHES = _builtin_meshes()


# -- value types -------------------------------------------------------------------------
def _error(kind: str, message: str, **ctx: Any) -> PydanticCustomError:
    return PydanticCustomError(kind, message, ctx or None)


def _integral(value: Any) -> Any:
    """Counts: an int, or a float with no fraction (TOML's ``1e3``); never a bool or string."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _error("int_type", "must be an integer")
    if isinstance(value, float):
        if not math.isfinite(value) or value != int(value):
            raise _error("int_type", "must be an integer")
        return int(value)
    return value


def _vector(n: int):
    def check(value: Any) -> Any:
        if not isinstance(value, list | tuple) or len(value) != n:
            raise _error("vector", f"must be a list of {n} numbers")
        return value

    return BeforeValidator(check)


#: A finite real number (an int is accepted; a bool or a string is not).
Real = Annotated[float, Strict(), AllowInfNan(False)]
Count = Annotated[int, BeforeValidator(_integral)]
Vec3 = Annotated[tuple[Real, Real, Real], _vector(3)]
Vec2 = Annotated[tuple[Real, Real], _vector(2)]
Flag = Annotated[bool, Strict()]
Text = Annotated[str, Strict()]


def _label(value: Any) -> Any:
    """A number where a label goes (``name = 2024``) reads as its text, as it always did."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return str(value)
    return value


#: A name or description: text, or a number taken as its text.
Label = Annotated[str, BeforeValidator(_label), Strict()]


def _rotation(value: Any) -> Any:
    """A rotation's axis must not be zero unless its angle is (a zero axis turns nothing,
    so a non-zero angle about it is a mistake)."""
    if value[3] != 0 and not any(value[:3]):
        raise _error("rotation", "the axis (its first 3 numbers) must not be zero")
    return value


#: ``[axis_x, axis_y, axis_z, angle_degrees]``: a rotation by the angle about the axis.
Rotation = Annotated[
    tuple[Real, Real, Real, Real],
    _vector(4),
    AfterValidator(_rotation),
    Field(description="[axis x, axis y, axis z, angle in degrees]; the axis not zero"),
]


def _positive(field: str, value: tuple[float, ...]) -> None:
    if any(v <= 0 for v in value):
        raise _error("field", "every entry must be > 0", field=field)


def _color(value: Any) -> Any:
    text = value.lstrip("#") if isinstance(value, str) else ""
    if len(text) != 6 or any(c not in "0123456789abcdefABCDEF" for c in text):
        raise _error("color", "must be a colour '#rrggbb'")
    return value


def _canonical(enum) -> Any:
    """A validator mapping the names ``enum.parse`` accepts (``"verlet"``, ``"RK4"``,
    ``"bounding-sphere"``) to the canonical one; anything else is left for the Literal
    to refuse with the list of names."""

    def canonical(value: Any) -> Any:
        if isinstance(value, str):
            try:
                return enum.parse(value).name.lower()
            except ValueError:
                pass
        return value

    return canonical


def _dt(value: Any) -> Any:
    if value == "auto":
        return value
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _error("dt", 'must be seconds or "auto"')
    if not (math.isfinite(value) and value >= MIN_DT):
        raise _error("dt", f'must be finite seconds >= {MIN_DT:g} or "auto"')
    return float(value)


def _vertex(value: Any) -> Any:
    if value == "top":
        return value
    return _integral(value)


def _scale(value: Any) -> Any:
    values = list(value) if isinstance(value, list | tuple) and len(value) == 3 else [value]
    for v in values:
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise _error("scale", "must be a number or 3 numbers")
        if not (math.isfinite(v) and v > 0):
            raise _error("scale", "must be finite and > 0 (or 3 such numbers)")
    return float(value) if len(values) == 1 else tuple(float(v) for v in values)


TimeStep = Annotated[
    Any,
    BeforeValidator(_dt),
    WithJsonSchema(
        {
            "anyOf": [
                {"type": "number", "minimum": MIN_DT},
                {"const": "auto"},
            ]
        }
    ),
]
Vertex = Annotated[
    Any,
    BeforeValidator(_vertex),
    WithJsonSchema({"anyOf": [{"type": "integer", "minimum": 0}, {"const": "top"}]}),
]
Scale = Annotated[
    Any,
    BeforeValidator(_scale),
    WithJsonSchema(
        {
            "anyOf": [
                {"type": "number", "exclusiveMinimum": 0},
                {
                    "type": "array",
                    "items": {"type": "number", "exclusiveMinimum": 0},
                    "minItems": 3,
                    "maxItems": 3,
                },
            ]
        }
    ),
]
Color = Annotated[Text, BeforeValidator(_color), Field(pattern=r"^#?[0-9a-fA-F]{6}$")]


def _tagged(key: str, default: str | None = None, number: str | None = None):
    """A discriminator reading ``key`` (``default`` when absent); a bare number selects the
    ``number`` variant. Tags read ``key=value`` so that :func:`format_error` can drop them
    from error locations and name the key."""

    def tag(value: Any) -> str | None:
        if isinstance(value, dict):
            chosen = value.get(key, default)
            return None if chosen is None else f"{key}={chosen}"
        if number and isinstance(value, int | float) and not isinstance(value, bool):
            return f"={number}"
        return None

    tag.__name__ = key
    return Discriminator(tag)


def _mesh_tag(value: Any) -> str | None:
    if not isinstance(value, dict):
        return None
    given = [k for k in ("shape", "file", "builtin") if k in value]
    if len(given) != 1:
        return None
    return f"shape={value['shape']}" if given == ["shape"] else f"{given[0]}="


_mesh_tag.__name__ = "shape"


# -- tables ------------------------------------------------------------------------------
class Table(BaseModel):
    """A TOML table: unknown keys are errors that list the valid ones."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data: Any) -> Any:
        if isinstance(data, dict):
            unknown = sorted(str(k) for k in data if k not in cls.model_fields)
            if unknown:
                raise _error(
                    "unknown_key",
                    "unknown key {key} (valid: {valid})",
                    key=unknown[0],
                    valid=", ".join(sorted(cls.model_fields)),
                )
        return data


class Simulation(Table):
    """``[simulation]``: integrator, time step and duration."""

    integrator: Annotated[
        Literal[INTEGRATORS],  # type: ignore[valid-type]
        BeforeValidator(_canonical(Integrator)),
    ] = Field(
        "midpoint", description="time integrator (`--integrator` overrides it)"
    )
    dt: TimeStep = Field(
        1e-3, description='time step [s], >= 1e-9, or "auto" (chosen from the stability estimate)'
    )
    duration: Real = Field(5.0, gt=0, le=86400, description="simulated time [s]")
    gravity: Vec3 = Field((0.0, -9.81, 0.0), description="gravitational acceleration [m/s^2]")
    implicit_tolerance: Real = Field(
        1e-6,
        gt=0,
        lt=1,
        description="implicit_euler and bdf2: relative residual of the CG solve [1]",
    )


class Contact(Table):
    """``[contact]``: how soft bodies touch each other."""

    mode: Literal["none", "bounding", "surface"] = Field(
        "surface",
        description="bounding: vertices against the other body's bounding object (the "
        "paper); surface: against its triangles; none: bodies pass through",
    )
    restitution: Real = Field(0.5, ge=0, le=1, description="normal speed kept [1]")
    friction: Real = Field(0.1, ge=0, le=1, description="tangential speed removed [1]")
    margin: Real | None = Field(
        None,
        gt=0,
        description="surface contact search distance [m] (default: half the median edge "
        "length); with a thickness, how far the broad phase grows boxes, >= thickness "
        "(default: the thickness)",
    )
    self_contact: Flag = Field(
        False,
        description="surface mode: bodies collide with themselves too (vertex-triangle and "
        "edge-edge pairs, with a thickness)",
    )
    thickness: Real | None = Field(
        None,
        gt=0,
        description="surface mode: distance kept between two sheets [m] (default with "
        "self_contact: 0.2 times the median edge length)",
    )

    @model_validator(mode="after")
    def _surface_only(self) -> Contact:
        if (self.self_contact or self.thickness is not None) and self.mode != "surface":
            name = "self_contact" if self.self_contact else "thickness"
            raise _error("field", "needs contact.mode 'surface', not '{mode}'", field=name,
                         mode=self.mode)  # fmt: skip
        if self.thickness is not None and self.margin is not None and self.margin < self.thickness:
            raise _error("field", "must be >= contact.thickness", field="margin")
        return self


class Air(Table):
    """``[air]``: the air bodies with a ``drag_coefficient`` move through."""

    density: Real = Field(
        1.2, ge=0, le=1e4, description="air density [kg/m^3] (0: no drag anywhere)"
    )
    wind: Vec3 = Field((0.0, 0.0, 0.0), description="wind velocity [m/s]")


class Render(Table):
    """``[render]``: the video and images."""

    width: Count = Field(640, ge=16, le=MAX_IMAGE_SIDE, description="image width [px]")
    height: Count = Field(480, ge=16, le=MAX_IMAGE_SIDE, description="image height [px]")
    fps: Real = Field(30.0, ge=0.01, le=1000, description="frames per simulated second [1/s]")
    camera: Vec3 = Field((0.0, 1.5, 6.0), description="camera position [m]")
    target: Vec3 = Field((0.0, 0.5, 0.0), description="point the camera looks at [m]")
    fov: Real = Field(40.0, gt=0, lt=180, description="vertical field of view [deg]")
    style: Literal["solid", "wireframe", "both"] = "solid"
    velocity_vectors: Flag = Field(False, description="draw vertex velocities (Figure 7)")
    velocity_scale: Real = Field(
        0.05, ge=0, le=1e6, description="seconds of motion a velocity vector shows [s]"
    )
    bounding_objects: Flag = Field(False, description="draw bounding objects (Figure 5)")
    ground_size: Real = Field(8.0, gt=0, le=1e6, description="side of the drawn ground [m]")
    usd_start_frame: Real = Field(
        0.0,
        ge=-1e15,
        le=1e15,
        description="time code of the first frame of the USD export (--usd), e.g. 1001",
    )

    @model_validator(mode="after")
    def _camera(self) -> Render:
        if self.camera == self.target:
            raise _error(
                "field",
                "must differ from render.target (the camera looks from camera to target; "
                "at the target it sees no direction and draws blank frames)",
                field="camera",
            )
        return self


# meshes: one variant per generator, plus a file or a built-in mesh
class _MeshBase(Table):
    reorder: Flag = Field(False, description="renumber vertices along a space-filling curve")


class Icosphere(_MeshBase):
    """Geodesic sphere: 10 * 4**subdivisions + 2 vertices."""

    shape: Literal["icosphere"]
    subdivisions: Count = Field(2, ge=0, description="1-to-4 triangle splits (2: 162 vertices)")
    radius: Real = Field(1.0, gt=0, description="radius [m]")


class UvSphere(_MeshBase):
    """Latitude-longitude sphere: (rings - 1) * segments + 2 vertices."""

    shape: Literal["uv_sphere"]
    rings: Count = Field(16, ge=2, description="latitude bands")
    segments: Count = Field(32, ge=3, description="longitude segments")
    radius: Real = Field(1.0, gt=0, description="radius [m]")


class Box(_MeshBase):
    """Box; each side a grid of 2**subdivisions squares per edge."""

    shape: Literal["box"]
    extents: Vec3 = Field((1.0, 1.0, 1.0), description="side lengths along x, y, z [m], each > 0")
    subdivisions: Count = Field(0, ge=0, description="grid refinement level")

    @model_validator(mode="after")
    def _extents(self) -> Box:
        _positive("extents", self.extents)
        return self


class Capsule(_MeshBase):
    """Capsule along y: a cylinder capped by two hemispheres."""

    shape: Literal["capsule"]
    radius: Real = Field(0.5, gt=0, description="radius [m]")
    length: Real = Field(1.0, gt=0, description="length of the cylindrical part [m]")
    rings: Count = Field(8, ge=2, description="latitude bands per hemisphere")
    segments: Count = Field(16, ge=3, description="segments around the axis")


class Cylinder(_MeshBase):
    """Closed cylinder along y with flat caps."""

    shape: Literal["cylinder"]
    radius: Real = Field(0.5, gt=0, description="radius [m]")
    height: Real = Field(1.0, gt=0, description="height [m]")
    segments: Count = Field(32, ge=3, description="sides")


class Rectangle(_MeshBase):
    """Open rectangle in the xy plane (a cloth)."""

    shape: Literal["rectangle"]
    size: Vec2 = Field((1.0, 1.0), description="width and height [m], each > 0")
    resolution: Annotated[tuple[Count, Count], _vector(2)] = Field(
        (16, 16), description="squares along x and y, each >= 1"
    )

    @model_validator(mode="after")
    def _sizes(self) -> Rectangle:
        _positive("size", self.size)
        if min(self.resolution) < 1:
            raise _error("field", "every entry must be >= 1", field="resolution")
        return self


class MeshFile(_MeshBase):
    """A mesh file (OBJ, PLY, STL, OFF, GLB), relative to the scene file's folder."""

    file: Text = Field(min_length=1, max_length=4096, description="path of the mesh file")


class MeshBuiltin(_MeshBase):
    """A mesh shipped with softbody."""

    builtin: Literal[BUILTIN_MESHES] = Field(description="built-in mesh name")  # type: ignore[valid-type]


Mesh = Annotated[
    Annotated[Icosphere, Tag("shape=icosphere")]
    | Annotated[UvSphere, Tag("shape=uv_sphere")]
    | Annotated[Box, Tag("shape=box")]
    | Annotated[Capsule, Tag("shape=capsule")]
    | Annotated[Cylinder, Tag("shape=cylinder")]
    | Annotated[Rectangle, Tag("shape=rectangle")]
    | Annotated[MeshFile, Tag("file=")]
    | Annotated[MeshBuiltin, Tag("builtin=")],
    Discriminator(_mesh_tag),
]

Schedule = Annotated[
    list[Vec2],
    Field(
        min_length=1,
        description="piecewise-linear value over time: [[time s, value], ...], times "
        "increasing, values >= 0",
    ),
]


class _GasBase(Table):
    ambient_pressure: Real = Field(0.0, ge=0, description="pressure outside the body [Pa]")

    @model_validator(mode="after")
    def _schedule(self) -> _GasBase:
        schedule = getattr(self, "schedule", None)
        if schedule:
            if any(b[0] <= a[0] for a, b in pairwise(schedule)):
                raise _error("field", "times must increase strictly", field="schedule")
            if any(v < 0 for _, v in schedule):
                raise _error("field", "values must be >= 0", field="schedule")
        return self


class Isothermal(_GasBase):
    """P = nRT / V (the paper's model): give nrt, or moles and temperature."""

    law: Literal["isothermal"] = "isothermal"
    nrt: Real | None = Field(None, ge=0, description="amount times temperature, nRT [J]")
    moles: Real | None = Field(None, ge=0, description="amount of gas [mol] (instead of nrt)")
    temperature: Real = Field(293.15, gt=0, description="temperature [K] (with moles)")
    schedule: Schedule | None = None

    @model_validator(mode="after")
    def _amount(self) -> Isothermal:
        if (self.nrt is None) == (self.moles is None):
            raise _error("field", "give exactly one of nrt or moles", field="nrt")
        if self.moles is not None and self.schedule is not None:
            raise _error("field", "a schedule needs nrt, not moles", field="schedule")
        return self


class FixedPressure(_GasBase):
    """Gas held at a pressure whatever the volume (a cloth's wind)."""

    law: Literal["fixed_pressure"] = "fixed_pressure"
    pressure: Real = Field(ge=0, description="pressure P0 [Pa]")
    schedule: Schedule | None = None


class Adiabatic(_GasBase):
    """P V**gamma constant, P(V_ref) = nRT / V_ref."""

    law: Literal["adiabatic"] = "adiabatic"
    nrt: Real = Field(ge=0, description="nRT at the reference volume [J]")
    gamma: Real = Field(1.4, gt=1, le=10, description="heat capacity ratio [1]")
    reference_volume: Real | None = Field(
        None, gt=0, description="volume where P = nRT / V [m^3] (default: the rest volume)"
    )
    schedule: Schedule | None = None


class Ideal(_GasBase):
    """An ideal gas whose amount and temperature are state (``Gas.ideal``): P = n R T / V,
    with n and T changed by the scene's vents, orifices, inflators and leaks."""

    law: Literal["ideal"]
    moles: Real = Field(ge=0, description="amount of gas at the initial shape [mol]")
    temperature: Real = Field(293.15, gt=0, description="temperature at the initial shape [K]")
    process: Literal["isothermal", "adiabatic"] = Field(
        "isothermal",
        description="isothermal: T stays (fast heat exchange); adiabatic: no heat exchange, "
        "the first law of the open system sets T",
    )
    molar_mass: Real = Field(
        0.028965, gt=0, le=1, description="molar mass of the gas [kg/mol] (air: 0.028965)"
    )
    gamma: Real = Field(1.4, gt=1, le=10, description="heat capacity ratio c_p / c_v [1]")
    ambient_temperature: Real = Field(
        293.15, gt=0, description="temperature of the air outside [K] (what flows in)"
    )


NonNegative = Annotated[Real, Field(ge=0)]
Gas = Annotated[
    Annotated[NonNegative, Tag("=number")]
    | Annotated[Isothermal, Tag("law=isothermal")]
    | Annotated[FixedPressure, Tag("law=fixed_pressure")]
    | Annotated[Adiabatic, Tag("law=adiabatic")]
    | Annotated[Ideal, Tag("law=ideal")],
    _tagged("law", default="isothermal", number="number"),
    Field(description="the gas inside: a table, or a number meaning isothermal nRT [J]"),
]
ClothPressure = Annotated[
    Annotated[Real, Tag("=number")] | Annotated[FixedPressure, Tag("law=fixed_pressure")],
    _tagged("law", default="fixed_pressure", number="number"),
    Field(description="pressure across the cloth [Pa] (a number, or a fixed_pressure table)"),
]


class Pin(Table):
    """Vertices held in place: the union of every selection given."""

    indices: list[Annotated[Count, Field(ge=0)]] | None = Field(
        None, description="mesh vertex indices"
    )
    above: Real | None = Field(None, description="vertices with y above this [m]")
    below: Real | None = Field(None, description="vertices with y below this [m]")
    boundary: Flag = Field(False, description="the mesh's open boundary")


class MaterialBending(Table):
    """Material bending of the skin (``softbody.Bending``): the discrete-shell energy on
    every interior edge. Give the bending stiffness D, or the material it comes from
    (D = E H^3 / (12 (1 - nu^2)))."""

    stiffness: Real | None = Field(None, gt=0, description="bending stiffness D [N m]")
    youngs_modulus: Real | None = Field(
        None, gt=0, description="Young's modulus E [Pa] (with poisson_ratio and thickness)"
    )
    poisson_ratio: Real | None = Field(
        None, gt=-1, le=0.5, description="Poisson ratio nu [1], in (-1, 0.5]"
    )
    thickness: Real | None = Field(None, gt=0, description="thickness H [m]")
    rest_shape: Literal["mesh", "flat"] = Field(
        "mesh", description="angles that cost nothing: the mesh's own, or flat (0)"
    )

    @model_validator(mode="after")
    def _one_way(self) -> MaterialBending:
        material = (self.youngs_modulus, self.poisson_ratio, self.thickness)
        if self.stiffness is not None:
            if any(v is not None for v in material):
                raise _error(
                    "field",
                    "give stiffness, or youngs_modulus, poisson_ratio and thickness, not both",
                    field="stiffness",
                )
        elif any(v is None for v in material):
            raise _error(
                "field",
                "give stiffness, or all of youngs_modulus, poisson_ratio and thickness",
                field="stiffness",
            )
        return self


class FaceSide(Table):
    """The faces whose centre lies on one side of a plane normal to an axis, in the
    scene's coordinates (after the body's scale, rotation and position)."""

    axis: Literal["x", "y", "z"] = Field(description="the plane's normal axis")
    above: Real | None = Field(None, description="faces with a centre above this [m]")
    below: Real | None = Field(None, description="faces with a centre below this [m]")

    @model_validator(mode="after")
    def _one_side(self) -> FaceSide:
        if (self.above is None) == (self.below is None):
            raise _error("field", "give one of above or below", field="above")
        return self


def _faces_tag(value: Any) -> str | None:
    """Face indices, or a table selecting a side (tags of the key=value form, which error
    locations leave out)."""
    if isinstance(value, dict):
        return "faces=table"
    if isinstance(value, list | tuple):
        return "faces=list"
    return None


FaceSelection = Annotated[
    Annotated[list[Annotated[Count, Field(ge=0)]], Tag("faces=list")]
    | Annotated[FaceSide, Tag("faces=table")],
    Discriminator(_faces_tag),
]


class _MembraneBase(Table):
    thickness: Real = Field(gt=0, le=1e3, description="rest thickness H [m]")
    damping: Real = Field(
        0.0, ge=0, le=1e6, description="strain-rate damping time beta [s] (0: none)"
    )
    faces: FaceSelection | None = Field(
        None,
        description="the mesh faces this layer covers: indices, or a table selecting the "
        "faces on one side of a plane (axis and above or below); default every face",
    )


class NeoHookean(_MembraneBase):
    """Incompressible neo-Hookean sheet (rubber): W = mu / 2 (I1 - 3)."""

    model: Literal["neo_hookean"]
    shear_modulus: Real = Field(ge=0, description="shear modulus mu [Pa]")


class MooneyRivlin(_MembraneBase):
    """Incompressible Mooney-Rivlin sheet: W = c10 (I1 - 3) + c01 (I2 - 3)."""

    model: Literal["mooney_rivlin"]
    c10: Real = Field(ge=0, description="first coefficient [Pa]")
    c01: Real = Field(ge=0, description="second coefficient [Pa]")


class StVK(_MembraneBase):
    """St Venant-Kirchhoff sheet in plane stress (fabric, film)."""

    model: Literal["stvk"]
    youngs_modulus: Real = Field(ge=0, description="Young's modulus E [Pa]")
    poisson_ratio: Real = Field(gt=-1, lt=0.5, description="Poisson ratio nu [1]")


MembraneLayer = Annotated[
    Annotated[NeoHookean, Tag("model=neo_hookean")]
    | Annotated[MooneyRivlin, Tag("model=mooney_rivlin")]
    | Annotated[StVK, Tag("model=stvk")],
    _tagged("model"),
]
def _layers_tag(value: Any) -> str | None:
    """One membrane table, or an array of them (tags of the key=value form, which error
    locations leave out)."""
    if isinstance(value, dict):
        return "membrane=table"
    if isinstance(value, list | tuple):
        return "membrane=layers"
    return None


MembraneSpec = Annotated[
    Annotated[MembraneLayer, Tag("membrane=table")]
    | Annotated[list[MembraneLayer], Tag("membrane=layers")],
    Discriminator(_layers_tag),
    Field(
        description="the skin as a membrane material (softbody.Membrane): a table with "
        "model = 'neo_hookean', 'mooney_rivlin' or 'stvk' and its parameters, or an array "
        "of such tables, layers whose energies add (each on its faces, default all)"
    ),
]


class _BodyBase(Table):
    #: Keys passed as they are to ModelBuilder.add_soft_body / add_cloth, under the same
    #: names (a new builder argument of a body is one field here and its name in this list)
    BUILDER_ARGUMENTS: ClassVar[tuple[str, ...]] = (
        "mass", "stiffness", "damping", "bend_stiffness", "bend_damping",
        "mass_distribution", "velocity", "drag_coefficient", "density",
    )  # fmt: skip

    name: Label | None = Field(None, max_length=200, description="label (default: body N)")
    mesh: Mesh
    position: Vec3 = Field((0.0, 0.0, 0.0), description="translation [m]")
    rotation: Rotation | None = None
    scale: Scale | None = Field(None, description="scale factor: one number or per axis [1]")
    mass: Real | None = Field(None, gt=0, description="total mass [kg] (or density)")
    density: Real | None = Field(
        None, gt=0, description="membrane density [kg/m^3]: mass = density x thickness x area"
    )
    stiffness: Real | None = Field(
        None, ge=0, description="edge spring stiffness [N/m] (optional with a membrane)"
    )
    membrane: MembraneSpec | None = None
    damping: Real = Field(0.0, ge=0, description="edge spring damping [N s/m]")
    bend_stiffness: Real = Field(0.0, ge=0, description="bending spring stiffness [N/m]")
    bend_damping: Real = Field(0.0, ge=0, description="bending spring damping [N s/m]")
    bending: MaterialBending | None = Field(
        None, description="material bending (D [N m], or E, nu and H); none by default"
    )
    velocity: Vec3 = Field((0.0, 0.0, 0.0), description="initial velocity [m/s]")
    pin: Pin | None = None
    color: Color | None = Field(None, description="colour '#rrggbb' (default: the palette)")
    mass_distribution: Literal["uniform", "area"] = Field(
        "uniform", description="equal particle masses, or by each vertex's area share"
    )
    drag_coefficient: Real = Field(
        0.0,
        ge=0,
        le=1e3,
        description="quadratic air drag coefficient C_d of every face [1] (0: none; "
        "every integrator)",
    )

    @model_validator(mode="after")
    def _mass_and_skin(self) -> _BodyBase:
        if (self.mass is None) == (self.density is None):
            raise _error("field", "give exactly one of mass or density", field="mass")
        if self.density is not None and self.membrane is None:
            raise _error("field", "density needs a membrane", field="density")
        if self.stiffness is None and self.membrane is None:
            raise _error("field", "give stiffness, a membrane or both", field="stiffness")
        if self.stiffness is None and self.damping > 0:
            raise _error("field", "damps the edge springs: give stiffness too (a membrane "
                         "has its own damping)", field="damping")  # fmt: skip
        return self


class SoftBody(_BodyBase):
    """A closed mesh filled with gas."""

    kind: Literal["soft"] = "soft"
    gas: Gas
    volume_method: Annotated[
        Literal["exact", "bounding_box", "bounding_sphere", "bounding_ellipsoid", "monte_carlo"],
        BeforeValidator(_canonical(VolumeMethod)),
    ] = "exact"
    contact_shape: Literal["bounding_ellipsoid", "bounding_sphere", "bounding_box"] = (
        "bounding_ellipsoid"
    )
    monte_carlo_samples: Count = Field(
        4096, ge=1, description="sample lines per Monte Carlo volume estimate"
    )
    seed: Count = Field(0, ge=0, le=2**63 - 1, description="seed of the Monte Carlo lines")


class Cloth(_BodyBase):
    """An open surface with a pressure difference across it (wind)."""

    kind: Literal["cloth"]
    pressure: ClothPressure = 0.0


Body = Annotated[
    Annotated[SoftBody, Tag("kind=soft")] | Annotated[Cloth, Tag("kind=cloth")],
    _tagged("kind", default="soft"),
]


class Attachment(Table):
    """A damped spring from a body's vertex to a fixed point."""

    body: Count = Field(ge=0, description="body index")
    vertex: Vertex = Field("top", description='mesh vertex index, or "top" (highest vertex)')
    anchor: Vec3 = Field(description="fixed end [m]")
    stiffness: Real = Field(gt=0, description="spring stiffness [N/m]")
    damping: Real = Field(0.0, ge=0, description="spring damping [N s/m]")
    rest_length: Real = Field(0.0, ge=0, description="rest length [m]")


class Rotating(Table):
    """Constant spin about a pivot."""

    type: Literal["rotation"]
    angular_velocity: Vec3 = Field(description="angular velocity [rad/s]")
    pivot: Vec3 | None = Field(None, description="pivot [m] (default: the centre)")


class Translating(Table):
    """Constant velocity."""

    type: Literal["translation"]
    velocity: Vec3 = Field(description="velocity [m/s]")


class Oscillating(Table):
    """Centre + amplitude sin(2 pi frequency t)."""

    type: Literal["oscillation"]
    amplitude: Vec3 = Field(description="amplitude [m]")
    frequency: Real = Field(ge=0, le=1e6, description="frequency [Hz]")


Motion = Annotated[
    Annotated[Rotating, Tag("type=rotation")]
    | Annotated[Translating, Tag("type=translation")]
    | Annotated[Oscillating, Tag("type=oscillation")],
    _tagged("type"),
]


class _ColliderBase(Table):
    restitution: Real = Field(0.5, ge=0, le=1, description="normal speed kept [1]")
    friction: Real = Field(0.1, ge=0, le=1, description="tangential speed removed [1]")
    motion: Motion | None = None


class Plane(_ColliderBase):
    """Infinite plane; particles stay on the side the normal points to."""

    type: Literal["plane"]
    point: Vec3 = Field((0.0, 0.0, 0.0), description="a point of the plane [m]")
    normal: Vec3 = Field((0.0, 1.0, 0.0), description="normal (not zero) [1]")

    @model_validator(mode="after")
    def _normal(self) -> Plane:
        if not any(self.normal):
            raise _error("field", "must not be zero", field="normal")
        return self


class BoxCollider(_ColliderBase):
    """Box: solid, or a container that keeps particles inside."""

    type: Literal["box"]
    center: Vec3 = Field((0.0, 0.0, 0.0), description="centre [m]")
    half_extents: Vec3 = Field(description="half side lengths [m], each > 0")
    rotation: Rotation | None = None
    container: Flag = Field(False, description="keep particles inside")

    @model_validator(mode="after")
    def _extents(self) -> BoxCollider:
        _positive("half_extents", self.half_extents)
        return self


class Sphere(_ColliderBase):
    """Solid sphere."""

    type: Literal["sphere"]
    center: Vec3 = Field((0.0, 0.0, 0.0), description="centre [m]")
    radius: Real = Field(gt=0, description="radius [m]")


class MeshCollider(_ColliderBase):
    """Solid closed triangle mesh: a mesh file, or a generated shape table like the bodies'
    ``mesh``. It must be one closed surface that does not cross itself."""

    type: Literal["mesh"]
    file: Text | None = Field(
        None,
        min_length=1,
        max_length=4096,
        description="path of the mesh file, relative to the scene file's folder",
    )
    mesh: Mesh | None = Field(None, description="a generated, built-in or file mesh table")
    center: Vec3 | None = Field(
        None, description="where the mesh's bounding-box centre goes [m] (default: as given)"
    )
    rotation: Rotation | None = None
    margin: Real | None = Field(
        None,
        gt=0,
        le=1e6,
        description="how far outside the surface caught vertices are put [m] "
        "(default: 1e-4 of the mesh's bounding-box diagonal)",
    )
    sharp_angle: Real = Field(
        30.0,
        ge=0,
        le=180,
        description="convex edges whose faces' normals are more than this apart [deg] meet "
        "the soft edges edge to edge; every bent edge and face keeps soft edges and "
        "triangles out too (180: the edge contacts off, vertices only)",
    )

    @model_validator(mode="after")
    def _one_mesh(self) -> MeshCollider:
        if (self.file is None) == (self.mesh is None):
            raise _error("field", "give exactly one of file or mesh", field="file")
        return self


Collider = Annotated[
    Annotated[Plane, Tag("type=plane")]
    | Annotated[BoxCollider, Tag("type=box")]
    | Annotated[Sphere, Tag("type=sphere")]
    | Annotated[MeshCollider, Tag("type=mesh")],
    _tagged("type"),
]


# gas that flows: vents, orifices, inflators, leaks (``ModelBuilder.add_vent`` and so on)
def _body_ref(value: Any) -> Any:
    """A body named by its index (an integer) or its ``name`` (a string)."""
    if isinstance(value, str):
        if not value:
            raise _error("body", "must be a body index or a body's name")
        return value
    return _integral(value)


BodyRef = Annotated[
    Any,
    BeforeValidator(_body_ref),
    WithJsonSchema({"anyOf": [{"type": "integer", "minimum": 0}, {"type": "string"}]}),
]


class Vent(Table):
    """``[[vents]]``: an orifice from a body to the air outside it."""

    body: BodyRef = Field(description="body index or name")
    area: Real = Field(ge=0, le=1e6, description="open area [m^2]")
    discharge_coefficient: Real = Field(0.62, gt=0, le=1, description="C_d [1]")
    opening_pressure: Real | None = Field(
        None,
        description="gauge pressure P - P_ambient at which it opens and stays open [Pa] "
        "(with neither this nor opening_time: open from the start)",
    )
    opening_time: Real | None = Field(
        None, ge=0, description="time at which it opens and stays open [s]"
    )


class Orifice(Table):
    """``[[orifices]]``: an orifice between two bodies (chambers), flowing both ways."""

    body_a: BodyRef = Field(description="body index or name")
    body_b: BodyRef = Field(description="body index or name (another body)")
    area: Real = Field(ge=0, le=1e6, description="open area [m^2]")
    discharge_coefficient: Real = Field(0.62, gt=0, le=1, description="C_d [1]")


def _is_real(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _mass_flow(value: Any) -> Any:
    """A mass flow [kg/s] >= 0, or a table of [time s, kg/s] rows, times increasing
    strictly, flows >= 0 (one error naming what is wrong, not one per union member)."""
    if _is_real(value):
        if not math.isfinite(value):
            raise _error("mass_flow", "must be finite")
        if value < 0:
            raise _error("mass_flow", "must be >= 0 [kg/s]")
        return float(value)
    if not isinstance(value, list) or not value:
        raise _error("mass_flow", "must be a number [kg/s] or a table [[time s, kg/s], ...]")
    rows = []
    for row in value:
        if not (isinstance(row, list | tuple) and len(row) == 2 and all(map(_is_real, row))):
            raise _error("mass_flow", "every row must be [time s, kg/s], two numbers")
        if not all(math.isfinite(v) for v in row):
            raise _error("mass_flow", "must hold finite numbers")
        rows.append((float(row[0]), float(row[1])))
    if any(b[0] <= a[0] for a, b in pairwise(rows)):
        raise _error("mass_flow", "times must increase strictly")
    if any(v < 0 for _, v in rows):
        raise _error("mass_flow", "mass flows must be >= 0 [kg/s]")
    return rows


MassFlow = Annotated[
    Any,
    BeforeValidator(_mass_flow),
    WithJsonSchema(
        {
            "anyOf": [
                {"type": "number", "minimum": 0},
                {
                    "type": "array",
                    "minItems": 1,
                    "items": {"type": "array", "items": {"type": "number"}, "minItems": 2,
                              "maxItems": 2},
                },
            ]
        }
    ),
]


class Inflator(Table):
    """``[[inflators]]``: gas of the body's species delivered into it."""

    body: BodyRef = Field(description="body index or name")
    mass_flow: MassFlow = Field(
        description="mass flow [kg/s], or a piecewise-linear table [[time s, kg/s], ...], "
        "times increasing, flows >= 0 (held before the first and after the last row)"
    )
    temperature: Real = Field(gt=0, le=1e5, description="temperature of the gas delivered [K]")


class Leak(Table):
    """``[[leaks]]``: fabric leakage, a mass flow c A |P - P_ambient| through the body's
    current area A."""

    body: BodyRef = Field(description="body index or name")
    coefficient: Real = Field(ge=0, le=1e6, description="c [kg/(s m^2 Pa)]")


def body_index(bodies: list, ref: int | str) -> int | str:
    """The index of the body ``ref`` names among ``bodies`` (an index, or a body's
    ``name``; a body without one is ``"body N"``), or the reason it names none (a str)."""
    if isinstance(ref, int):
        if not 0 <= ref < len(bodies):
            return f"must be a body index in [0, {len(bodies) - 1}] or a body's name"
        return ref
    names = [b.name if b.name is not None else f"body {k}" for k, b in enumerate(bodies)]
    found = [k for k, n in enumerate(names) if n == ref]
    if not found:
        shown = ", ".join(repr(n) for n in names[:10]) + (", ..." if len(names) > 10 else "")
        return f"no body is named {ref[:100]!r} (names: {shown})"
    if len(found) > 1:
        return f"{len(found)} bodies are named {ref[:100]!r}: give an index"
    return found[0]


class SceneSpec(Table):
    """A whole scene file."""

    name: Label | None = Field(
        None, max_length=200, description="output file stem (default: the file's name)"
    )
    description: Label = Field("", max_length=10_000, description="one line for the scene list")
    simulation: Simulation = Simulation()
    contact: Contact | None = Field(None, description="soft-soft contact (default: surface)")
    air: Air = Air()
    render: Render = Render()
    bodies: list[Body] = Field(min_length=1, description="[[bodies]]: at least one")
    attachments: list[Attachment] = []
    colliders: list[Collider] = []
    vents: list[Vent] = Field([], description="[[vents]]: orifices to the outside air")
    orifices: list[Orifice] = Field([], description="[[orifices]]: orifices between bodies")
    inflators: list[Inflator] = Field([], description="[[inflators]]: gas delivered into bodies")
    leaks: list[Leak] = Field([], description="[[leaks]]: fabric leakage of bodies")

    @model_validator(mode="after")
    def _cross_checks(self) -> SceneSpec:
        for a, attachment in enumerate(self.attachments):
            if attachment.body >= len(self.bodies):
                raise _error(
                    "field",
                    f"must be a body index in [0, {len(self.bodies) - 1}]",
                    field=f"attachments.{a}.body",
                )
        for table in ("vents", "orifices", "inflators", "leaks"):
            for k, entry in enumerate(getattr(self, table)):
                keys = ("body_a", "body_b") if table == "orifices" else ("body",)
                found = []
                for key in keys:
                    index = body_index(self.bodies, getattr(entry, key))
                    if isinstance(index, str):
                        raise _error("field", index, field=f"{table}.{k}.{key}")
                    if isinstance(self.bodies[index], Cloth):
                        raise _error(
                            "field",
                            f"body {index} is a cloth: an open surface holds no gas",
                            field=f"{table}.{k}.{key}",
                        )
                    found.append(index)
                if len(found) == 2 and found[0] == found[1]:
                    raise _error(
                        "field",
                        f"must be another body than body_a (both are body {found[0]})",
                        field=f"{table}.{k}.body_b",
                    )
        return self

    def flow_bodies(self, table: str, k: int) -> list[int]:
        """The body indices entry ``k`` of ``table`` (``"vents"``, ``"orifices"``,
        ``"inflators"``, ``"leaks"``) names (checked by the cross-checks)."""
        entry = getattr(self, table)[k]
        keys = ("body_a", "body_b") if table == "orifices" else ("body",)
        return [int(body_index(self.bodies, getattr(entry, key))) for key in keys]


# -- size guards -------------------------------------------------------------------------
def _mesh_count(mesh: BaseModel) -> tuple[float, float]:
    """(vertices, faces) a generator variant will make, from its keys alone (floats, so that
    absurd counts stay finite)."""
    if isinstance(mesh, Icosphere):
        n = 4.0 ** min(mesh.subdivisions, 200)
        return 10 * n + 2, 20 * n
    if isinstance(mesh, UvSphere):
        rings, segments = float(mesh.rings), float(mesh.segments)
        return (rings - 1) * segments + 2, 2 * (rings - 1) * segments
    if isinstance(mesh, Box):
        n = 2.0 ** min(mesh.subdivisions, 200)
        return 6 * (n + 1) ** 2, 12 * n**2
    if isinstance(mesh, Capsule):
        around, along = float(mesh.segments), 2.0 * mesh.rings
        return around * (along + 1) + 2, 2 * around * (along + 1)
    if isinstance(mesh, Cylinder):
        return 2.0 * mesh.segments + 2, 4.0 * mesh.segments
    if isinstance(mesh, Rectangle):
        nx, ny = (float(v) for v in mesh.resolution)
        return (nx + 1) * (ny + 1), 2 * nx * ny
    return 0.0, 0.0  # a file: its size is guarded when it is read


def _guard_mesh(key: str, vertices: float, faces: float) -> None:
    if vertices < 1e15:
        limits.check_mesh_size(key, vertices, faces)
    else:  # an absurd count: say so in short rather than with 40 digits
        estimate = limits.BYTES_PER_PARTICLE * vertices + limits.BYTES_PER_FACE * faces
        limits.check_memory(key, estimate, f"a mesh of {vertices:.3g} vertices")


def check_sizes(spec: SceneSpec) -> None:
    """Refuse a scene whose meshes, Monte Carlo samples or images would not fit in memory
    (:mod:`softbody.limits`), naming the key; nothing is allocated.

    Raises :class:`~softbody.errors.SizeLimitError`.
    """
    total_vertices = total_faces = 0.0
    for b, body in enumerate(spec.bodies):
        where = f"bodies.{b}"
        vertices, faces = _mesh_count(body.mesh)
        # name the count that makes the mesh large (the largest of those the shape has)
        counts = {
            k: max(v) if isinstance(v, tuple) else v
            for k, v in body.mesh
            if k in ("subdivisions", "rings", "segments", "resolution")
        }
        size_key = max(counts, key=counts.get) if counts else "shape"
        _guard_mesh(f"{where}.mesh.{size_key}", vertices, faces)
        total_vertices += vertices
        total_faces += faces
        if isinstance(body, SoftBody):
            # guarded whatever the volume method: a value that cannot fit is a mistake
            key = f"{where}.monte_carlo_samples"
            n = float(body.monte_carlo_samples)
            limits.check_memory(key, BYTES_PER_SAMPLE * n, f"{n:,.0f} sample lines")
            if n > MAX_MONTE_CARLO_SAMPLES:
                raise limits.SizeLimitError(
                    f"{key}: must be at most {MAX_MONTE_CARLO_SAMPLES:,} (every step tests "
                    f"each line against every triangle), got {body.monte_carlo_samples}"
                )
    _guard_mesh("bodies", total_vertices, total_faces)
    for c, col in enumerate(spec.colliders):
        if isinstance(col, MeshCollider) and col.mesh is not None:
            counts = {
                k: max(v) if isinstance(v, tuple) else v
                for k, v in col.mesh
                if k in ("subdivisions", "rings", "segments", "resolution")
            }
            size_key = max(counts, key=counts.get) if counts else "shape"
            _guard_mesh(f"colliders.{c}.mesh.{size_key}", *_mesh_count(col.mesh))
    r = spec.render
    limits.check_memory(
        "render.width", BYTES_PER_PIXEL * r.width * r.height, f"{r.width} x {r.height} frames"
    )


# -- errors ------------------------------------------------------------------------------
def _show(value: Any) -> str:
    if isinstance(value, dict):
        return "a table"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _number(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


_REASONS = {
    "finite_number": "must be finite",
    "float_type": "must be a number",
    "float_parsing": "must be a number",
    "int_type": "must be an integer",
    "int_parsing": "must be an integer",
    "int_from_float": "must be an integer",
    "bool_type": "must be true or false",
    "bool_parsing": "must be true or false",
    "string_type": "must be a string",
    "list_type": "must be a list",
    "tuple_type": "must be a list",
    "model_type": "must be a table",
    "model_attributes_type": "must be a table",
    "dict_type": "must be a table",
}


def _one(error: dict) -> str:
    """One pydantic error as ``dotted.key: reason, got value``."""
    parts = [str(p) for p in error["loc"] if not (isinstance(p, str) and "=" in p)]
    where = ".".join(parts)
    kind, ctx, value = error["type"], error.get("ctx") or {}, error.get("input")
    prefix = f"{where}." if where else ""
    if kind == "unknown_key":
        return f"unknown scene key {prefix}{ctx['key']} (valid: {ctx['valid']})"
    if kind == "field":
        return f"{prefix}{ctx['field']}: {error['msg']}"
    if kind == "missing":
        return f"{where}: required, not given"
    if kind == "union_tag_invalid":
        key, _, tag = ctx["tag"].partition("=")
        valid = [t.strip("'").partition("=")[2] for t in ctx["expected_tags"].split(", ")]
        valid = [
            v
            for v, t in zip(valid, ctx["expected_tags"].split(", "), strict=True)
            if t.strip("'").startswith(f"{key}=") and v
        ]
        return f"{prefix}{key}: unknown value {tag!r} (valid: {', '.join(valid)})"
    if kind == "union_tag_not_found":
        key = ctx.get("discriminator", "").removesuffix("()")
        if not isinstance(value, dict):
            what = "a number or a table" if key == "law" else "a table"
            return f"{where}: must be {what}, got {_show(value)}"
        if key == "shape":
            return f"{where}: needs exactly one of shape, file or builtin"
        return f"{prefix}{key}: required, not given"
    bounds = {
        "greater_than": ">",
        "greater_than_equal": ">=",
        "less_than": "<",
        "less_than_equal": "<=",
    }
    if kind in bounds:
        bound = next(iter(ctx.values()))
        reason = f"must be {bounds[kind]} {_number(bound)}"
    elif kind == "literal_error":
        reason = f"must be one of {ctx['expected']}"
    elif kind == "too_short":
        reason = (
            "must not be empty"
            if ctx["min_length"] == 1
            else (f"must have at least {ctx['min_length']} entries")
        )
    elif kind == "too_long":
        reason = f"must have at most {ctx['max_length']} entries"
    elif kind == "string_too_short":
        reason = "must not be empty"
    elif kind == "string_too_long":
        reason = f"must be at most {ctx['max_length']} characters"
    elif kind in _REASONS:
        reason = _REASONS[kind]
    else:
        reason = error["msg"].removeprefix("Value error, ")
    return f"{where}: {reason}, got {_show(value)}"


def format_error(exc: ValidationError) -> str:
    """The first problem of a ValidationError as one line; a count of the rest."""
    errors = exc.errors(include_url=False)
    line = _one(errors[0])
    if len(errors) > 1:
        line += f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})"
    return line.replace("\n", " ")


def validate_scene(data: dict) -> SceneSpec:
    """Check a parsed scene table (after overrides) against the schema and the size guards.

    Raises ValueError subclasses only: ``SceneError`` (from the loader, which wraps the
    ValidationError with :func:`format_error`) or
    :class:`~softbody.errors.SizeLimitError`.
    """
    spec = SceneSpec.model_validate(data)
    check_sizes(spec)
    return spec


def scene_json_schema() -> dict:
    """The scene file's JSON Schema (draft 2020-12): types, units in the descriptions,
    defaults and bounds, for editors and the documentation."""
    schema = SceneSpec.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "softbody scene"
    return schema
