"""``ModelBuilder``: collect particles, springs and soft bodies, then ``finalize`` a Model."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import ArrayLike

from softbody import _core, limits
from softbody.bending import Bending, dihedral_angles, hinge_stiffness
from softbody.collision.colliders import Collider, SoftContactMode, collider_arrays
from softbody.errors import MeshError
from softbody.gas import Gas, GasLaw
from softbody.membrane import Membrane
from softbody.mesh.topology import bending_pairs, hinges, unique_edges, vertex_areas
from softbody.mesh.tri_mesh import TriMesh
from softbody.mesh.validate import validate_mesh_report
from softbody.sim.model import Model
from softbody.sim.state import kernel_input
from softbody.volume import VolumeMethod

if TYPE_CHECKING:
    import trimesh


def _number(name: str, value, *, minimum: float | None = 0.0, strict: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(x):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if minimum is not None and (x < minimum or (strict and x == minimum)):
        raise ValueError(f"{name} must be {'>' if strict else '>='} {minimum:g}, got {value!r}")
    return x


def _edge_owners(tri: np.ndarray) -> np.ndarray:
    """(T, 3) int64: 1 where triangle t is the first (in triangle, then corner order) to
    have the edge from its corner k to corner k + 1, so that every edge has one owner."""
    edges = np.stack([tri, np.roll(tri, -1, axis=1)], axis=2).reshape(-1, 2)
    owner = np.zeros(len(edges), dtype=np.int64)
    if len(edges):
        _, first = np.unique(np.sort(edges, axis=1), axis=0, return_index=True)
        owner[first] = 1
    return owner.reshape(-1, 3)


def _vec3(name: str, value) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return v


def _sample_count(value) -> int:
    """``monte_carlo_samples`` as a whole number >= 1 (refusing 2.5, inf, NaN and text)."""
    try:  # int(inf) raises OverflowError, int(nan) ValueError
        n = int(value)
        ok = n == value and n >= 1
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise ValueError(f"monte_carlo_samples must be an integer >= 1, got {value!r}")
    return n


#: Density of air at sea level and 20 C [kg/m^3], the builder's default.
DEFAULT_AIR_DENSITY = 1.2
#: Default surface-contact thickness with self-contact, a fraction of the median edge length
DEFAULT_THICKNESS_FRACTION = 0.2


@dataclass
class _Body:
    particle_begin: int
    particle_end: int
    faces: np.ndarray  # (F, 3) global particle indices
    mass: float
    gas: Gas
    volume_method: VolumeMethod
    mc_samples: np.ndarray  # (S, 2)
    contact_shape: VolumeMethod
    closed: bool
    drag_coefficient: float = 0.0
    corner_source: np.ndarray | None = None  # (F, 3) input-mesh vertex of each corner
    membranes: tuple = ()  # (Membrane, (F_k,) local face indices) per layer


#: What ``membrane=`` takes: one Membrane on every face, or layers (Membrane, faces or None).
MembraneSpec = Membrane | Sequence[tuple[Membrane, Sequence[int] | np.ndarray | None]] | None


def _membrane_layers(spec, face_count: int, collapsed: int) -> list[tuple[Membrane, np.ndarray]]:
    """``membrane=`` as (Membrane, local face indices (F_k,) int64) per layer."""
    if spec is None:
        return []
    if isinstance(spec, Membrane):
        spec = [(spec, None)]
    try:
        if isinstance(spec, str | bytes):
            raise TypeError
        items = list(spec)
    except TypeError:
        raise TypeError(
            "membrane must be a softbody.Membrane or a list of (Membrane, faces or None), "
            f"got {type(spec).__name__}"
        ) from None
    layers = []
    for k, item in enumerate(items):
        if not (isinstance(item, tuple | list) and len(item) == 2
                and isinstance(item[0], Membrane)):  # fmt: skip
            raise TypeError(f"membrane layer {k} must be a (Membrane, faces or None) pair")
        material, faces = item
        if faces is None:
            idx = np.arange(face_count, dtype=np.int64)
        else:
            if collapsed:
                raise ValueError(
                    f"membrane layer {k}: welding dropped {collapsed} collapsed triangles, so "
                    "face indices would not match the mesh's; weld the mesh first"
                )
            a = np.asarray(faces)
            if a.size and not np.issubdtype(a.dtype, np.integer):
                raise ValueError(f"membrane layer {k}: faces must be integer face indices")
            idx = np.unique(a.astype(np.int64).reshape(-1))
            if idx.size and (idx[0] < 0 or idx[-1] >= face_count):
                raise ValueError(
                    f"membrane layer {k}: face indices must lie in [0, {face_count - 1}]"
                )
        layers.append((material, idx))
    return layers


def membrane_rest_frames(q: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A0 (T,) [m^2], Dm^-1 (T, 2, 2) [1/m]) of triangles tri (T, 3) at positions q
    (N, 3): Dm = [[|e1|, e2 . u], [0, e2 . v]], the edges e1 = x1 - x0, e2 = x2 - x0 in the
    frame u = e1 / |e1|, v = n x u of the triangle's plane. A triangle of zero area is a
    ValueError."""
    x = q[tri]
    e1, e2 = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]
    normal = np.cross(e1, e2)
    twice = np.linalg.norm(normal, axis=1)
    if np.any(~(twice > 0)):
        bad = int(np.flatnonzero(~(twice > 0))[0])
        raise ValueError(f"membrane triangle {bad} has zero area: no rest frame")
    l1 = np.linalg.norm(e1, axis=1)
    u = e1 / l1[:, None]
    v = np.cross(normal / twice[:, None], u)
    dm = np.zeros((len(tri), 2, 2))
    dm[:, 0, 0] = l1
    dm[:, 0, 1] = np.einsum("ij,ij->i", e2, u)
    dm[:, 1, 1] = np.einsum("ij,ij->i", e2, v)
    inv = np.zeros_like(dm)
    inv[:, 0, 0] = 1.0 / dm[:, 0, 0]
    inv[:, 1, 1] = 1.0 / dm[:, 1, 1]
    inv[:, 0, 1] = -dm[:, 0, 1] / (dm[:, 0, 0] * dm[:, 1, 1])
    return 0.5 * twice, inv


class ModelBuilder:
    """Collects the pieces of a model. Everything is validated as it is added.

    Parameters
    ----------
    gravity : (3,) array of float
        Gravitational acceleration [m/s^2]; default -9.81 along y.

    The air the bodies move through (for face drag, :meth:`set_air`) is still sea-level
    air, 1.2 kg/m^3; it acts only on bodies given a ``drag_coefficient`` > 0.

    Examples
    --------
    >>> import softbody
    >>> builder = softbody.ModelBuilder()
    >>> ball = builder.add_soft_body(softbody.icosphere(2), mass=1.0, stiffness=500.0,
    ...                              damping=1.0, gas=softbody.Gas.isothermal(200.0))
    >>> model = builder.finalize()
    """

    def __init__(self, *, gravity: ArrayLike = (0.0, -9.81, 0.0)):
        self.gravity = _vec3("gravity", gravity)
        self._q: list[np.ndarray] = []
        self._qd: list[np.ndarray] = []
        self._mass: list[np.ndarray] = []
        self._pinned: list[np.ndarray] = []
        self._particle_body: list[np.ndarray] = []
        self._source: list[np.ndarray] = []
        self._particle_count = 0
        self._springs: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self._attachments: list[tuple[int, np.ndarray, float, float, float]] = []
        # per body with material bending: hinges (H, 4), rest angles, stiffnesses, body
        self._hinges: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self._bodies: list[_Body] = []
        self._colliders: list[Collider] = []
        self._soft_contact = ("none", 0.5, 0.1, None)
        self._self_contact = False
        self._thickness: float | None = None
        self.air_density = DEFAULT_AIR_DENSITY
        self.wind = np.zeros(3)
        self._vents: list[tuple[int, float, float, float, float]] = []
        self._orifices: list[tuple[int, int, float, float]] = []
        self._inflators: list[tuple[int, float, np.ndarray]] = []
        self._leaks: dict[int, float] = {}

    # -- sizes ---------------------------------------------------------------------------
    @property
    def particle_count(self) -> int:
        """Particles added so far."""
        return self._particle_count

    @property
    def body_count(self) -> int:
        """Soft bodies added so far."""
        return len(self._bodies)

    def body_particles(self, body: int) -> range:
        """Particle indices of ``body``'s vertices (vertex k is particle ``range[k]``)."""
        b = self._bodies[body]
        return range(b.particle_begin, b.particle_end)

    # -- particles and springs -----------------------------------------------------------
    def _append_particles(self, q, qd, mass, pinned, body, source=None):
        n = len(q)
        self._source.append(np.full(n, -1, dtype=np.int64) if source is None else source)
        self._q.append(q)
        self._qd.append(qd)
        self._mass.append(mass)
        self._pinned.append(pinned)
        self._particle_body.append(np.full(n, body, dtype=np.int64))
        begin = self._particle_count
        self._particle_count += n
        return begin

    def add_particle(
        self,
        position: ArrayLike,
        *,
        mass: float,
        velocity: ArrayLike = (0.0, 0.0, 0.0),
        pinned: bool = False,
    ) -> int:
        """Add one free particle; returns its index.

        position [m], mass [kg] (> 0), velocity [m/s]; a pinned particle does not respond
        to forces (it moves only through ``Control.pin_target``).
        """
        q = _vec3("position", position)[None]
        qd = _vec3("velocity", velocity)[None]
        m = _number("mass", mass, strict=True)
        return self._append_particles(q, qd, np.array([m]), np.array([bool(pinned)]), -1)

    def _check_particles(self, name: str, idx) -> np.ndarray:
        a = np.asarray(idx)
        if a.size and not np.issubdtype(a.dtype, np.integer):
            raise ValueError(f"{name} must be integer particle indices")
        a = a.astype(np.int64)
        if a.size and (a.min() < 0 or a.max() >= self._particle_count):
            raise ValueError(
                f"{name} must lie in [0, {self._particle_count - 1}], "
                f"got range [{a.min()}, {a.max()}]"
            )
        return a

    def add_spring(
        self,
        i: int,
        j: int,
        *,
        stiffness: float,
        damping: float = 0.0,
        rest_length: float | None = None,
    ) -> int:
        """Add a damped Hooke spring between particles ``i`` and ``j``; returns its index.

        stiffness [N/m] >= 0, damping [N s/m] >= 0; rest_length [m] defaults to the
        current distance.
        """
        pair = self._check_particles("spring particle", [i, j])
        if pair[0] == pair[1]:
            raise ValueError(f"a spring needs two different particles, got {i} twice")
        k = _number("stiffness", stiffness)
        c = _number("damping", damping)
        if rest_length is None:
            rest = np.array([np.nan])  # measured at finalize
        else:
            rest = np.array([_number("rest_length", rest_length)])
        self._springs.append((pair[None], rest, np.array([k]), np.array([c]), np.array([-1])))
        return sum(len(s[0]) for s in self._springs) - 1

    def add_attachment(
        self,
        particle: int,
        anchor: ArrayLike,
        *,
        stiffness: float,
        damping: float = 0.0,
        rest_length: float = 0.0,
    ) -> int:
        """Tie ``particle`` to the fixed point ``anchor`` [m] with a damped spring.

        stiffness [N/m] > 0, damping [N s/m] >= 0, rest_length [m] >= 0. Returns the
        attachment index (``Control.attachment_anchor`` moves its anchor).
        """
        (p,) = self._check_particles("attachment particle", [particle])
        self._attachments.append(
            (
                int(p),
                _vec3("anchor", anchor),
                _number("rest_length", rest_length),
                _number("stiffness", stiffness, strict=True),
                _number("damping", damping),
            )
        )
        return len(self._attachments) - 1

    # -- soft bodies ---------------------------------------------------------------------
    def add_soft_body(
        self,
        mesh: TriMesh | trimesh.Trimesh,
        *,
        mass: float | None = None,
        stiffness: float | None = None,
        damping: float = 0.0,
        gas: Gas | float,
        membrane: MembraneSpec = None,
        density: float | None = None,
        volume_method: str | VolumeMethod = "exact",
        pinned: Sequence[int] | np.ndarray | None = None,
        bend_stiffness: float = 0.0,
        bend_damping: float = 0.0,
        bending: Bending | None = None,
        mass_distribution: Literal["uniform", "area"] = "uniform",
        velocity: ArrayLike = (0.0, 0.0, 0.0),
        monte_carlo_samples: int = 4096,
        seed: int = 0,
        contact_shape: str = "bounding_ellipsoid",
        drag_coefficient: float = 0.0,
    ) -> int:
        """Add a closed mesh filled with gas as a soft body; returns the body index.

        Parameters
        ----------
        mesh : TriMesh or trimesh.Trimesh
            Closed surface: a :class:`TriMesh`, or a :class:`trimesh.Trimesh` (its
            ``vertices`` and ``faces`` are copied; anything else it carries, such as UVs or
            materials, is not). It is validated (welded, oriented; open or non-manifold
            meshes raise :class:`MeshError`). Vertex k of the validated mesh becomes
            particle ``body_particles(b)[k]``; ``Model.particle_source_vertex`` and
            ``Model.tri_source_vertex`` map particles and triangle corners back to this
            mesh's vertices (to put its UVs back, see the USD export);
            :func:`softbody.body_mesh` gives the body's surface at a state.
        mass : float
            Total mass [kg], > 0. Give it or ``density``, not both.
        stiffness, damping : float
            Hooke stiffness [N/m] and damping [N s/m] of the spring on every mesh edge.
            Required without a membrane; with one it may be left out (no edge springs),
            or given to add springs beside it.
        gas : Gas or float
            The gas inside; a number means an isothermal gas with that nRT [J].
        membrane : Membrane or list of (Membrane, faces or None), optional
            The skin as a membrane material (:class:`softbody.Membrane`, SI units): one
            Membrane on every face, or layers, each a Membrane on the faces listed
            (indices into the mesh's faces; None: every face). Layers on the same face
            add, as a strain-limiting layer bonded to a chamber's wall does.
        density : float, optional
            Mass density [kg/m^3] of the membrane: the total mass is density times each
            layer's thickness times its faces' rest area (then spread by
            ``mass_distribution``). Needs ``membrane``; excludes ``mass``.
        volume_method : str
            ``"exact"`` (default), ``"bounding_box"``, ``"bounding_sphere"``,
            ``"bounding_ellipsoid"`` or ``"monte_carlo"``.
        pinned : sequence of int, optional
            Mesh vertex indices held in place (kinematic).
        bend_stiffness, bend_damping : float
            Springs across each pair of adjacent triangles [N/m], [N s/m]; 0 adds none.
            Their resistance to bending depends on the mesh; ``bending`` is the material's.
        bending : Bending, optional
            Material bending of the skin: the discrete-shell energy on every interior
            edge, from a bending stiffness D [N m] (``Bending(D)`` or
            ``Bending.from_material(E, nu, H)``, :class:`softbody.Bending`); none by
            default.
        mass_distribution : {"uniform", "area"}
            Equal particle masses, or proportional to each vertex's share of the area.
        velocity : (3,) array of float
            Initial velocity of every particle [m/s].
        monte_carlo_samples : int
            Lines per Monte Carlo volume estimate (``volume_method="monte_carlo"``).
        seed : int
            Seed of the Monte Carlo sample lines, so runs repeat.
        contact_shape : str
            The body's bounding object for the paper's soft-soft contacts
            (``set_soft_contact("bounding")``): ``"bounding_ellipsoid"`` (default),
            ``"bounding_sphere"`` or ``"bounding_box"``.
        drag_coefficient : float
            C_d [1] >= 0 of the quadratic air drag on every face,
            -1/2 rho C_d A (v_rel . n) |v_rel . n| n with v_rel the face's velocity
            relative to the wind (:meth:`set_air`); 0 (default) means no drag. Every
            integrator steps it; implicit_euler and bdf2 take its force explicitly
            (``Simulator``).
        """
        if not isinstance(gas, Gas):
            gas = Gas.isothermal(_number("gas nRT", gas))
        return self._add_surface(
            mesh,
            closed=True,
            mass=mass,
            stiffness=stiffness,
            damping=damping,
            membrane=membrane,
            density=density,
            gas=gas,
            volume_method=volume_method,
            pinned=pinned,
            bend_stiffness=bend_stiffness,
            bend_damping=bend_damping,
            bending=bending,
            mass_distribution=mass_distribution,
            velocity=velocity,
            monte_carlo_samples=monte_carlo_samples,
            seed=seed,
            contact_shape=contact_shape,
            drag_coefficient=drag_coefficient,
        )

    def add_cloth(
        self,
        mesh: TriMesh | trimesh.Trimesh,
        *,
        mass: float | None = None,
        stiffness: float | None = None,
        damping: float = 0.0,
        pressure: Gas | float = 0.0,
        membrane: MembraneSpec = None,
        density: float | None = None,
        pinned: Sequence[int] | np.ndarray | None = None,
        bend_stiffness: float = 0.0,
        bend_damping: float = 0.0,
        bending: Bending | None = None,
        mass_distribution: Literal["uniform", "area"] = "uniform",
        velocity: ArrayLike = (0.0, 0.0, 0.0),
        drag_coefficient: float = 0.0,
    ) -> int:
        """Add an open surface (a cloth) with a pressure difference across it; returns the
        body index (the paper's starting point, Figures 2-3: wind on a cloth).

        ``pressure`` [Pa] pushes every face along its normal (the side the right-hand
        winding points to), as wind does; give ``Gas.fixed_pressure(p, schedule=...)`` for
        a gust that changes over time. The mesh may have a boundary but must otherwise be
        manifold and consistently wound. Other parameters as in :meth:`add_soft_body`
        (``membrane``: the cloth as a sheet of that material, e.g. ``Membrane.stvk``).
        """
        if not isinstance(pressure, Gas):
            pressure = Gas.fixed_pressure(_number("cloth pressure", pressure, minimum=None))
        if pressure.law != GasLaw.FIXED_PRESSURE:
            raise ValueError(
                "a cloth encloses no gas: its pressure must be a number or Gas.fixed_pressure(...)"
            )
        return self._add_surface(
            mesh,
            closed=False,
            mass=mass,
            stiffness=stiffness,
            damping=damping,
            membrane=membrane,
            density=density,
            gas=pressure,
            volume_method="exact",
            pinned=pinned,
            bend_stiffness=bend_stiffness,
            bend_damping=bend_damping,
            bending=bending,
            mass_distribution=mass_distribution,
            velocity=velocity,
            monte_carlo_samples=0,
            seed=0,
            contact_shape="bounding_box",
            drag_coefficient=drag_coefficient,
        )

    def _add_surface(
        self,
        mesh,
        *,
        closed,
        mass,
        stiffness,
        damping,
        membrane,
        density,
        gas,
        volume_method,
        pinned,
        bend_stiffness,
        bend_damping,
        bending,
        mass_distribution,
        velocity,
        monte_carlo_samples,
        seed,
        contact_shape,
        drag_coefficient,
    ) -> int:
        if isinstance(mesh, TriMesh):
            source = mesh
        elif hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
            source = TriMesh(np.asarray(mesh.vertices), np.asarray(mesh.faces))
        else:
            raise TypeError(
                f"mesh must be a softbody.TriMesh or a trimesh.Trimesh, got {type(mesh).__name__}"
            )
        body = len(self._bodies)
        # the whole model so far plus this body, before validating or copying anything
        particles = self._particle_count + source.vertex_count
        faces = sum(len(b.faces) for b in self._bodies) + source.face_count
        limits.check_memory(
            f"body {body} mesh",
            limits.BYTES_PER_PARTICLE * particles + limits.BYTES_PER_FACE * faces,
            f"a model of {particles:,} particles ({source.vertex_count:,} from this mesh)",
        )
        method = VolumeMethod.parse(volume_method)
        samples_n = 0
        if method == VolumeMethod.MONTE_CARLO:
            samples_n = _sample_count(monte_carlo_samples)
            limits.check_memory(
                f"body {body} monte_carlo_samples={samples_n}",
                limits.BYTES_PER_MC_SAMPLE * float(samples_n),
                f"{samples_n:,} Monte Carlo sample lines",
            )
        # warnings point at the user's add_soft_body / add_cloth call
        report = validate_mesh_report(source, name=f"body {body} mesh", closed=closed, stacklevel=4)
        mesh = report.mesh
        if mesh.vertex_count != source.vertex_count and pinned is not None:
            warnings.warn(
                f"body {body}: welding renumbered the mesh vertices; pinned indices refer "
                "to the welded mesh",
                stacklevel=2,
            )
        layers = _membrane_layers(membrane, mesh.face_count, report.collapsed_face_count)
        if stiffness is None and not layers:
            raise ValueError("stiffness is required for a body without a membrane")
        if (mass is None) == (density is None):
            raise ValueError(
                "give the body's mass or its density, not both"
                if mass is not None
                else "give the body's mass [kg] or its membrane's density [kg/m^3]"
            )
        if mass is not None:
            total_mass = _number("mass", mass, strict=True)
        else:
            if not layers:
                raise ValueError("density needs a membrane (its thickness gives the mass)")
            rho = _number("density", density, strict=True)
            area, _ = membrane_rest_frames(mesh.vertices, mesh.faces)
            total_mass = sum(rho * m.thickness * float(area[f].sum()) for m, f in layers)
            total_mass = _number("mass from density", total_mass, strict=True)
        springs = stiffness is not None
        k = _number("stiffness", stiffness) if springs else 0.0
        if not springs and _number("damping", damping) > 0:
            raise ValueError(
                "damping is the edge springs' [N s/m]: give stiffness too, or damp the "
                "membrane with its own damping (Membrane.neo_hookean(..., damping=beta))"
            )
        c = _number("damping", damping)
        kb = _number("bend_stiffness", bend_stiffness)
        cb = _number("bend_damping", bend_damping)
        cd = _number("drag_coefficient", drag_coefficient)
        if bending is not None and not isinstance(bending, Bending):
            raise ValueError(
                "bending must be a softbody.Bending (Bending(D) or Bending.from_material(E, nu, "
                f"H)), got {type(bending).__name__}"
            )
        shape = VolumeMethod.parse(contact_shape)
        if shape not in (
            VolumeMethod.BOUNDING_BOX,
            VolumeMethod.BOUNDING_SPHERE,
            VolumeMethod.BOUNDING_ELLIPSOID,
        ):
            raise ValueError(
                "contact_shape must be 'bounding_ellipsoid', 'bounding_sphere' "
                f"or 'bounding_box', got {contact_shape!r}"
            )
        v = mesh.vertex_count
        if mass_distribution == "uniform":
            m = np.full(v, total_mass / v)
        elif mass_distribution == "area":
            areas = vertex_areas(mesh.vertices, mesh.faces)
            m = total_mass * areas / areas.sum()
        else:
            raise ValueError(
                f"mass_distribution must be 'uniform' or 'area', got {mass_distribution!r}"
            )
        pin_mask = np.zeros(v, dtype=bool)
        if pinned is not None:
            p = np.asarray(pinned)
            if p.size and not np.issubdtype(p.dtype, np.integer):
                raise ValueError("pinned must be integer vertex indices")
            p = p.astype(np.int64).reshape(-1)
            if p.size and (p.min() < 0 or p.max() >= v):
                raise ValueError(f"pinned vertex indices must lie in [0, {v - 1}]")
            pin_mask[p] = True
        vel = np.broadcast_to(_vec3("velocity", velocity), (v, 3)).copy()
        samples = (
            np.random.default_rng(seed).random((samples_n, 2))
            if method == VolumeMethod.MONTE_CARLO
            else np.zeros((0, 2))
        )
        hinge_data = None if bending is None else self._hinge_data(mesh, bending)

        begin = self._append_particles(
            mesh.vertices.copy(), vel, m, pin_mask, body, report.vertex_source
        )
        edges = unique_edges(mesh.faces) + begin
        if springs:
            self._springs.append(
                (
                    edges,
                    np.full(len(edges), np.nan),
                    np.full(len(edges), k),
                    np.full(len(edges), c),
                    np.full(len(edges), body),
                )
            )
        if kb > 0:
            bend = bending_pairs(mesh.faces) + begin
            self._springs.append(
                (
                    bend,
                    np.full(len(bend), np.nan),
                    np.full(len(bend), kb),
                    np.full(len(bend), cb),
                    np.full(len(bend), body),
                )
            )
        if hinge_data is not None:
            h, rest, kh = hinge_data
            self._hinges.append((h + begin, rest, kh, np.full(len(h), body, dtype=np.int64)))
        self._bodies.append(
            _Body(
                begin,
                begin + v,
                mesh.faces + begin,
                total_mass,
                gas,
                method,
                samples,
                shape,
                closed,
                cd,
                report.corner_source,
                tuple(layers),
            )
        )
        return body

    @staticmethod
    def _hinge_data(mesh: TriMesh, bending: Bending) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The material bending hinges of a body's validated ``mesh`` (H, 4) (its
        vertex indices), their rest angles [rad] and stiffnesses [N m] (H,) at the mesh's
        positions (validation has refused triangles of zero area, so every k is finite)."""
        h = hinges(mesh.faces)
        k = hinge_stiffness(mesh.vertices, h, bending.stiffness)
        rest = (
            dihedral_angles(mesh.vertices, h) if bending.rest_shape == "mesh" else np.zeros(len(h))
        )
        return h, rest, k

    # -- contacts ------------------------------------------------------------------------
    def add_collider(self, collider: Collider) -> int:
        """Add a rigid collider (``ColliderPlane``, ``ColliderBox``, ``ColliderSphere``,
        ``ColliderMesh``);
        returns its index. Parameters are checked at ``finalize``."""
        collider_arrays([collider])  # validate now, so the error points at this call
        self._colliders.append(collider)
        return len(self._colliders) - 1

    def set_soft_contact(
        self,
        mode: Literal["none", "bounding", "surface"] = "surface",
        *,
        self_contact: bool = False,
        thickness: float | None = None,
        restitution: float = 0.5,
        friction: float = 0.1,
        margin: float | None = None,
    ) -> None:
        """How soft bodies collide with each other (and with themselves).

        ``"bounding"``: the paper's method, vertices against the other body's bounding
        object (each body's ``contact_shape``); ``"surface"``: vertices against the other
        body's triangles; ``"none"``: bodies pass through each other. restitution and
        friction lie in [0, 1] (friction: the fraction of the tangential relative speed a
        contact removes).

        Surface contacts with a thickness (``thickness`` given, or ``self_contact=True``):
        vertex-triangle and edge-edge pairs between bodies, and within each body when
        ``self_contact``, keep two sheets at least ``thickness`` h [m] apart (adjacent
        elements, sharing a vertex, excepted), and no edge passes through a triangle
        whatever the step (a bound on each step's motion, ``core/collision/thick.hpp``); a
        run whose surfaces cross at a step's start (an initial self-intersection) stops
        with ``Status.CROSSED``, naming the edge and triangle. h defaults to
        ``DEFAULT_THICKNESS_FRACTION`` (0.2) times the median edge length with
        self-contact; it must stay below the distance between a vertex and the nearest
        triangle not touching it at rest (about 0.8 edge lengths on regular meshes), or the
        mesh pushes itself apart. margin [m]: without a thickness, how far surface contacts
        look for the nearest triangle (default half the median edge length); with one, how
        far the broad phase grows boxes, >= h (default h).
        """
        if mode not in ("none", "bounding", "surface"):
            raise ValueError(
                f"soft contact mode must be 'none', 'bounding' or 'surface', got {mode!r}"
            )
        if not isinstance(self_contact, (bool, np.bool_)):
            raise ValueError(f"self_contact must be True or False, got {self_contact!r}")
        if (self_contact or thickness is not None) and mode != "surface":
            raise ValueError(
                f"self_contact and thickness need soft contact mode 'surface', got {mode!r}"
            )
        for name, value in (("restitution", restitution), ("friction", friction)):
            v = _number(f"soft contact {name}", value)
            if v > 1:
                raise ValueError(f"soft contact {name} must lie in [0, 1], got {value!r}")
        if thickness is not None:
            thickness = _number("soft contact thickness", thickness, strict=True)
        if margin is not None:
            margin = _number("soft contact margin", margin, strict=True)
            if thickness is not None and margin < thickness:
                raise ValueError(
                    f"soft contact margin must be >= the thickness {thickness:g} m, "
                    f"got {margin!r}"
                )
        self._soft_contact = (mode, float(restitution), float(friction), margin)
        self._self_contact = bool(self_contact)
        self._thickness = thickness

    def set_air(self, *, density: float = DEFAULT_AIR_DENSITY, wind: ArrayLike = (0.0, 0.0, 0.0)):
        """The air the bodies move through: density rho [kg/m^3] >= 0 and the wind, its
        velocity [m/s] (``Control.wind`` overrides it per call). Faces of bodies with a
        ``drag_coefficient`` > 0 feel quadratic drag relative to it; density 0 turns drag
        off everywhere."""
        self.air_density = _number("air density", density)
        self.wind = _vec3("wind", wind)

    # -- gas flows -----------------------------------------------------------------------
    def _gas_body(self, name: str, body) -> int:
        """``body`` as the index of a closed body whose gas can flow (an ideal gas, not a
        fixed pressure or a schedule), or a ValueError naming ``name``."""
        if isinstance(body, bool) or not isinstance(body, int | np.integer):
            raise ValueError(f"{name} must be a body index, got {body!r}")
        body = int(body)
        if not 0 <= body < len(self._bodies):
            raise ValueError(f"{name} {body} is not a body (the model has {len(self._bodies)})")
        b = self._bodies[body]
        if not b.closed:
            raise ValueError(f"{name} {body} is a cloth: an open surface holds no gas")
        if b.gas.law == GasLaw.FIXED_PRESSURE or b.gas.schedule is not None:
            raise ValueError(
                f"{name} {body} has a prescribed gas (a fixed pressure or a schedule): gas can "
                "flow only into and out of an ideal gas (Gas.ideal, isothermal or adiabatic)"
            )
        return body

    def add_vent(
        self,
        body: int,
        *,
        area: float,
        discharge_coefficient: float = 0.62,
        opening_pressure: float | None = None,
        opening_time: float | None = None,
    ) -> int:
        """An orifice from ``body`` to the air outside it (at its gas's ambient pressure and
        temperature); returns the vent's index.

        Gas leaves by the orifice law (choked or subsonic, ``core/terms/flows.hpp``) while
        the inside pressure is higher, and air comes in the same way while it is lower.
        ``area`` [m^2] is the open area, ``discharge_coefficient`` C_d in (0, 1]. The vent
        opens when the gauge pressure P - P_ambient first reaches ``opening_pressure``
        [Pa] or the time reaches ``opening_time`` [s], whichever comes first, and stays
        open; with neither it is open from the start. ``Control.vent_area`` sets its area
        per call (a valve).
        """
        body = self._gas_body("vent body", body)
        area = _number("vent area", area)
        cd = _number("vent discharge_coefficient", discharge_coefficient, strict=True)
        if cd > 1.0:
            raise ValueError(f"vent discharge_coefficient must lie in (0, 1], got {cd!r}")
        if opening_pressure is None and opening_time is None:
            pressure, time = np.inf, -np.inf
        else:
            pressure = (
                np.inf
                if opening_pressure is None
                else _number("vent opening_pressure", opening_pressure, minimum=None)
            )
            time = np.inf if opening_time is None else _number("vent opening_time", opening_time)
        self._vents.append((body, area, cd, pressure, time))
        return len(self._vents) - 1

    def add_orifice(
        self, body_a: int, body_b: int, *, area: float, discharge_coefficient: float = 0.62
    ) -> int:
        """An orifice between two bodies (chambers): gas flows both ways by the orifice law,
        from the higher pressure to the lower; returns its index. The two gases must be
        the same species (molar mass and gamma). ``area`` [m^2], ``discharge_coefficient``
        C_d in (0, 1]; ``Control.orifice_area`` sets the area per call (0 closes it)."""
        a = self._gas_body("orifice body_a", body_a)
        b = self._gas_body("orifice body_b", body_b)
        if a == b:
            raise ValueError(f"an orifice joins two different bodies, got body {a} twice")
        ga, gb = self._bodies[a].gas, self._bodies[b].gas
        if ga.molar_mass != gb.molar_mass or ga.gamma != gb.gamma:
            raise ValueError(
                f"orifice bodies {a} and {b} hold different gases (molar mass {ga.molar_mass:g} "
                f"and {gb.molar_mass:g} kg/mol, gamma {ga.gamma:g} and {gb.gamma:g}): an "
                "orifice joins chambers of one species"
            )
        area = _number("orifice area", area)
        cd = _number("orifice discharge_coefficient", discharge_coefficient, strict=True)
        if cd > 1.0:
            raise ValueError(f"orifice discharge_coefficient must lie in (0, 1], got {cd!r}")
        self._orifices.append((a, b, area, cd))
        return len(self._orifices) - 1

    def add_inflator(
        self,
        body: int,
        *,
        mass_flow: float | Sequence[tuple[float, float]],
        temperature: float,
    ) -> int:
        """Gas of the body's own species delivered into ``body``; returns its index.

        ``mass_flow`` is a constant [kg/s] or a piecewise-linear table of (time [s], mass
        flow [kg/s]) rows, held before the first and after the last row; the gas enters
        at ``temperature`` [K] (an adiabatic body heats or cools by its enthalpy).
        ``Control.inflator_mass_flow`` overrides the table per call.
        """
        body = self._gas_body("inflator body", body)
        temperature = _number("inflator temperature", temperature, strict=True)
        if isinstance(mass_flow, int | float | np.integer | np.floating) and not isinstance(
            mass_flow, bool
        ):
            table = np.array([[0.0, _number("inflator mass_flow", mass_flow)]])
        else:
            try:
                table = np.asarray(mass_flow, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(
                    "inflator mass_flow must be a number [kg/s] or (time, kg/s) rows"
                ) from None
            if table.ndim != 2 or table.shape[1] != 2 or len(table) == 0:
                raise ValueError("inflator mass_flow must be a non-empty list of (time, kg/s) rows")
            if not np.all(np.isfinite(table)):
                raise ValueError("inflator mass_flow holds NaN or infinite numbers")
            if np.any(np.diff(table[:, 0]) <= 0):
                raise ValueError("inflator mass_flow times must increase strictly")
            if np.any(table[:, 1] < 0):
                raise ValueError("inflator mass_flow values must be >= 0 [kg/s]")
        self._inflators.append((body, temperature, table))
        return len(self._inflators) - 1

    def add_leak(self, body: int, *, coefficient: float) -> None:
        """Fabric leakage of ``body``: a mass flow c A |P - P_ambient| [kg/s] through its
        current surface area A [m^2], out while the inside pressure is higher, in (at the
        ambient temperature) while it is lower; ``coefficient`` c [kg/(s m^2 Pa)] >= 0.
        Setting it again replaces it."""
        body = self._gas_body("leak body", body)
        self._leaks[body] = _number("leak coefficient", coefficient)

    # -- finalize ------------------------------------------------------------------------
    def finalize(self) -> Model:
        """Freeze everything into an immutable :class:`Model`."""
        if self._particle_count == 0:
            raise ValueError("the model is empty: add a soft body or particles first")
        q = np.vstack(self._q)
        qd = np.vstack(self._qd)
        mass = np.concatenate(self._mass)
        pinned = np.concatenate(self._pinned)
        inv_mass = np.where(pinned, 0.0, 1.0 / mass)
        particle_body = np.concatenate(self._particle_body)
        source_vertex = np.concatenate(self._source)

        if self._springs:
            idx = np.vstack([s[0] for s in self._springs]).astype(np.int64)
            rest = np.concatenate([s[1] for s in self._springs])
            k = np.concatenate([s[2] for s in self._springs])
            c = np.concatenate([s[3] for s in self._springs])
            spring_body = np.concatenate([s[4] for s in self._springs]).astype(np.int64)
        else:
            idx = np.zeros((0, 2), dtype=np.int64)
            rest = k = c = np.zeros(0)
            spring_body = np.zeros(0, dtype=np.int64)
        measured = np.linalg.norm(q[idx[:, 1]] - q[idx[:, 0]], axis=1)
        rest = np.where(np.isnan(rest), measured, rest)

        if self._hinges:
            hinge_idx = np.vstack([h[0] for h in self._hinges]).astype(np.int64)
            hinge_rest = np.concatenate([h[1] for h in self._hinges])
            hinge_k = np.concatenate([h[2] for h in self._hinges])
            hinge_body = np.concatenate([h[3] for h in self._hinges])
        else:
            hinge_idx = np.zeros((0, 4), dtype=np.int64)
            hinge_rest = hinge_k = np.zeros(0)
            hinge_body = np.zeros(0, dtype=np.int64)

        att = self._attachments
        att_particle = np.array([a[0] for a in att], dtype=np.int64)
        att_anchor = np.array([a[1] for a in att], dtype=np.float64).reshape(-1, 3)
        att_rest = np.array([a[2] for a in att], dtype=np.float64)
        att_k = np.array([a[3] for a in att], dtype=np.float64)
        att_c = np.array([a[4] for a in att], dtype=np.float64)

        bodies = self._bodies
        bcount = len(bodies)
        tri = (
            np.vstack([b.faces for b in bodies]).astype(np.int64)
            if bodies
            else np.zeros((0, 3), dtype=np.int64)
        )
        corner_source = (
            np.vstack([b.corner_source for b in bodies]).astype(np.int64)
            if bodies
            else np.zeros((0, 3), dtype=np.int64)
        )
        tri_counts = np.array([len(b.faces) for b in bodies], dtype=np.int64)
        tri_end = np.cumsum(tri_counts)
        body_tri_range = np.stack([tri_end - tri_counts, tri_end], axis=1).reshape(-1, 2)
        body_particle_range = np.array(
            [[b.particle_begin, b.particle_end] for b in bodies], dtype=np.int64
        ).reshape(-1, 2)
        mc_counts = np.array([len(b.mc_samples) for b in bodies], dtype=np.int64)
        mc_end = np.cumsum(mc_counts)
        body_mc_range = np.stack([mc_end - mc_counts, mc_end], axis=1).reshape(-1, 2)
        mc_samples = (
            np.vstack([b.mc_samples for b in bodies]) if bodies else np.zeros((0, 2))
        ).reshape(-1, 2)
        method = np.array([b.volume_method for b in bodies], dtype=np.int64)
        schedules = [np.asarray(b.gas.schedule or np.zeros((0, 2))).reshape(-1, 2) for b in bodies]
        sched_counts = np.array([len(s) for s in schedules], dtype=np.int64)
        sched_end = np.cumsum(sched_counts)
        body_schedule_range = np.stack([sched_end - sched_counts, sched_end], axis=1).reshape(-1, 2)
        sched = np.vstack(schedules) if schedules else np.zeros((0, 2))

        # rest volume by each body's own method, at the initial positions
        rest_volume = _core.body_volumes(
            np.ascontiguousarray(q, dtype=np.float64),
            kernel_input(tri, np.int64),
            kernel_input(body_particle_range, np.int64),
            kernel_input(body_tri_range, np.int64),
            kernel_input(method, np.int64),
            kernel_input(body_mc_range, np.int64),
            kernel_input(mc_samples),
        )
        for b in range(bcount):
            if bodies[b].closed and not rest_volume[b] > 0:
                raise MeshError(f"body {b} encloses no volume ({rest_volume[b]:.3g} m^3)")
        ref_volume = np.array(
            [
                b.gas.reference_volume if b.gas.reference_volume is not None else rest_volume[i]
                for i, b in enumerate(bodies)
            ],
            dtype=np.float64,
        )

        mode, contact_e, contact_mu, margin = self._soft_contact
        body_edges = idx[spring_body >= 0] if len(idx) else np.zeros((0, 2), dtype=np.int64)
        if not len(body_edges) and len(tri):  # membranes without springs: the mesh edges
            body_edges = unique_edges(tri)
        edge_length = (
            np.linalg.norm(q[body_edges[:, 1]] - q[body_edges[:, 0]], axis=1)
            if len(body_edges)
            else np.ones(1)
        )
        thickness = self._thickness
        if thickness is None and self._self_contact:
            thickness = DEFAULT_THICKNESS_FRACTION * float(np.median(edge_length))
        if thickness is not None and margin is not None and margin < thickness:
            raise ValueError(
                f"soft contact margin {margin:g} m is below the thickness {thickness:g} m"
            )
        if margin is None:
            margin = thickness if thickness is not None else 0.5 * float(np.median(edge_length))
        colliders = collider_arrays(self._colliders)
        vents = np.array(self._vents, dtype=np.float64).reshape(-1, 5)
        orifices = np.array(self._orifices, dtype=np.float64).reshape(-1, 4)
        tables = [t for _, _, t in self._inflators]
        table_counts = np.array([len(t) for t in tables], dtype=np.int64)
        table_end = np.cumsum(table_counts)
        table = np.vstack(tables) if tables else np.zeros((0, 2))
        leak = np.zeros(bcount)
        for body, coefficient in self._leaks.items():
            leak[body] = coefficient
        flow_paths = (
            np.bincount(vents[:, 0].astype(np.int64), minlength=bcount)
            + np.bincount(orifices[:, :2].astype(np.int64).ravel(), minlength=bcount)
            + (leak > 0)
        ).astype(np.int64)
        membranes = self._membrane_arrays(q, tri, body_tri_range)
        return Model(
            gravity=self.gravity.copy(),
            particle_q=q,
            particle_qd=qd,
            particle_mass=mass,
            particle_inv_mass=inv_mass,
            particle_body=particle_body,
            particle_source_vertex=source_vertex,
            tri_source_vertex=corner_source,
            spring_indices=idx,
            spring_rest_length=rest,
            spring_stiffness=k,
            spring_damping=c,
            spring_body=spring_body,
            attachment_particle=att_particle,
            attachment_anchor=att_anchor,
            attachment_rest_length=att_rest,
            attachment_stiffness=att_k,
            attachment_damping=att_c,
            tri_indices=tri,
            body_particle_range=body_particle_range,
            body_tri_range=body_tri_range,
            body_mass=np.array([b.mass for b in bodies], dtype=np.float64),
            body_volume_method=method,
            body_mc_range=body_mc_range,
            mc_samples=np.ascontiguousarray(mc_samples),
            body_gas_law=np.array([int(b.gas.law) for b in bodies], dtype=np.int64),
            body_gas_value=np.array([b.gas.value for b in bodies], dtype=np.float64),
            body_gas_gamma=np.array([b.gas.gamma for b in bodies], dtype=np.float64),
            body_gas_reference_volume=ref_volume,
            body_ambient_pressure=np.array(
                [b.gas.ambient_pressure for b in bodies], dtype=np.float64
            ),
            body_schedule_range=body_schedule_range,
            schedule_time=np.ascontiguousarray(sched[:, 0]),
            schedule_value=np.ascontiguousarray(sched[:, 1]),
            body_rest_volume=rest_volume,
            body_gas_molar_mass=np.array([b.gas.molar_mass for b in bodies], dtype=np.float64),
            body_gas_temperature=np.array([b.gas.temperature for b in bodies], dtype=np.float64),
            body_ambient_temperature=np.array(
                [b.gas.ambient_temperature for b in bodies], dtype=np.float64
            ),
            body_leak_coefficient=leak,
            body_flow_paths=flow_paths,
            vent_body=vents[:, 0].astype(np.int64),
            vent_area=np.ascontiguousarray(vents[:, 1]),
            vent_discharge_coefficient=np.ascontiguousarray(vents[:, 2]),
            vent_open_pressure=np.ascontiguousarray(vents[:, 3]),
            vent_open_time=np.ascontiguousarray(vents[:, 4]),
            orifice_bodies=np.ascontiguousarray(orifices[:, :2].astype(np.int64)),
            orifice_area=np.ascontiguousarray(orifices[:, 2]),
            orifice_discharge_coefficient=np.ascontiguousarray(orifices[:, 3]),
            inflator_body=np.array([b for b, _, _ in self._inflators], dtype=np.int64),
            inflator_temperature=np.array([t for _, t, _ in self._inflators], dtype=np.float64),
            inflator_range=np.stack([table_end - table_counts, table_end], axis=1).reshape(-1, 2),
            inflator_time=np.ascontiguousarray(table[:, 0]),
            inflator_mass_flow=np.ascontiguousarray(table[:, 1]),
            pin_particle=np.flatnonzero(pinned).astype(np.int64),
            tri_body=np.repeat(np.arange(bcount), tri_counts).astype(np.int64),
            body_closed=np.array([int(b.closed) for b in bodies], dtype=np.int64),
            body_contact_shape=np.array([int(b.contact_shape) for b in bodies], dtype=np.int64),
            soft_contact_mode=int(SoftContactMode[mode.upper()]),
            soft_contact_restitution=contact_e,
            soft_contact_friction=contact_mu,
            contact_margin=float(margin),
            contact_cell_size=float(edge_length.max() + 2.0 * margin),
            contact_thickness=float(thickness or 0.0),
            soft_self_contact=int(self._self_contact),
            tri_edge_owner=_edge_owners(tri),
            collider_kind=colliders.kind,
            collider_center=colliders.center,
            collider_rotation=colliders.rotation,
            collider_size=colliders.size,
            collider_restitution=colliders.restitution,
            collider_friction=colliders.friction,
            collider_motion=colliders.motion,
            collider_motion_vector=colliders.motion_vector,
            collider_motion_pivot=colliders.motion_pivot,
            collider_motion_frequency=colliders.motion_frequency,
            collider_mesh_range=colliders.mesh_range,
            collider_mesh_root=colliders.mesh_root,
            collider_mesh_margin=colliders.mesh_margin,
            collider_mesh_vertices=colliders.mesh_vertices,
            collider_mesh_triangles=colliders.mesh_triangles,
            collider_mesh_vertex_normals=colliders.mesh_vertex_normals,
            collider_mesh_edge_normals=colliders.mesh_edge_normals,
            collider_mesh_sharp_edges=colliders.mesh_sharp_edges,
            collider_mesh_node_sharp=colliders.mesh_node_sharp,
            collider_mesh_node_children=colliders.mesh_node_children,
            collider_mesh_node_tris=colliders.mesh_node_tris,
            collider_mesh_node_bounds=colliders.mesh_node_bounds,
            body_drag_coefficient=np.array([b.drag_coefficient for b in bodies], dtype=np.float64),
            air_density=float(self.air_density),
            wind=self.wind.copy(),
            bending_hinges=hinge_idx,
            bending_rest_angle=hinge_rest,
            bending_stiffness=hinge_k,
            bending_body=hinge_body,
            **membranes,
        )

    def _membrane_arrays(self, q, tri, body_tri_range) -> dict[str, np.ndarray]:
        """The membrane fields of the Model: one row per layer and face, bodies in order,
        each body's layers in order; rest areas and frames at the initial positions."""
        rows, material, params, thickness, damping, owner = [], [], [], [], [], []
        for b, body in enumerate(self._bodies):
            t0 = body_tri_range[b, 0]
            for m, faces in body.membranes:
                rows.append(faces + t0)
                n = len(faces)
                material.append(np.full(n, int(m.material), dtype=np.int64))
                params.append(np.broadcast_to(np.array(m.params, dtype=np.float64), (n, 2)))
                thickness.append(np.full(n, m.thickness))
                damping.append(np.full(n, m.damping))
                owner.append(np.full(n, b, dtype=np.int64))

        def cat(parts, shape, dtype):
            return np.ascontiguousarray(
                np.concatenate(parts) if parts else np.zeros(shape, dtype=dtype), dtype=dtype
            )

        which = cat(rows, (0,), np.int64)
        indices = np.ascontiguousarray(tri[which], dtype=np.int64).reshape(-1, 3)
        area, inverse = membrane_rest_frames(q, indices)
        return {
            "membrane_indices": indices,
            "membrane_material": cat(material, (0,), np.int64),
            "membrane_params": cat(params, (0, 2), np.float64).reshape(-1, 2),
            "membrane_thickness": cat(thickness, (0,), np.float64),
            "membrane_rest_area": np.ascontiguousarray(area),
            "membrane_rest_inverse": np.ascontiguousarray(inverse.reshape(-1, 2, 2)),
            "membrane_damping": cat(damping, (0,), np.float64),
            "membrane_body": cat(owner, (0,), np.int64),
        }
