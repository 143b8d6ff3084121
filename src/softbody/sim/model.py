"""The immutable model: topology and parameters, fixed after ``ModelBuilder.finalize``."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from softbody.gas import GasLaw
from softbody.volume import VolumeMethod


class ModelData(NamedTuple):
    """The arrays the compiled kernels read, in one bundle (one dispatch per call)."""

    particle_mass: np.ndarray
    particle_inv_mass: np.ndarray
    gravity: np.ndarray
    spring_indices: np.ndarray
    spring_rest_length: np.ndarray
    spring_stiffness: np.ndarray
    spring_damping: np.ndarray
    spring_body: np.ndarray
    attachment_particle: np.ndarray
    attachment_rest_length: np.ndarray
    attachment_stiffness: np.ndarray
    attachment_damping: np.ndarray
    tri_indices: np.ndarray
    body_particle_range: np.ndarray
    body_tri_range: np.ndarray
    body_volume_method: np.ndarray
    body_mc_range: np.ndarray
    mc_samples: np.ndarray
    body_gas_law: np.ndarray
    body_gas_value: np.ndarray
    body_gas_gamma: np.ndarray
    body_gas_reference_volume: np.ndarray
    body_ambient_pressure: np.ndarray
    body_schedule_range: np.ndarray
    schedule_time: np.ndarray
    schedule_value: np.ndarray
    body_rest_volume: np.ndarray
    pin_particle: np.ndarray
    particle_body: np.ndarray
    tri_body: np.ndarray
    body_closed: np.ndarray
    body_contact_shape: np.ndarray
    soft_contact_mode: int
    soft_contact_restitution: float
    soft_contact_friction: float
    contact_margin: float
    contact_cell_size: float
    collider_kind: np.ndarray
    collider_center: np.ndarray
    collider_rotation: np.ndarray
    collider_size: np.ndarray
    collider_restitution: np.ndarray
    collider_friction: np.ndarray
    collider_motion: np.ndarray
    collider_motion_vector: np.ndarray
    collider_motion_pivot: np.ndarray
    collider_motion_frequency: np.ndarray
    body_drag_coefficient: np.ndarray
    air_density: float
    wind: np.ndarray


@dataclass(frozen=True, eq=False)
class Model:
    """Particles, springs, triangles, bodies and their gas, pins. All arrays are read-only.

    Build one with :class:`softbody.ModelBuilder`. Units are SI. N particles, S springs,
    A attachments, T triangles, B bodies, P pinned particles.
    """

    gravity: np.ndarray
    """Gravitational acceleration [m/s^2], shape (3,)."""
    particle_q: np.ndarray
    """Initial particle positions [m], shape (N, 3)."""
    particle_qd: np.ndarray
    """Initial particle velocities [m/s], shape (N, 3)."""
    particle_mass: np.ndarray
    """Particle masses [kg], shape (N,)."""
    particle_inv_mass: np.ndarray
    """Inverse masses [1/kg], shape (N,); 0 for pinned particles."""
    particle_body: np.ndarray
    """Body of each particle, shape (N,); -1 for free particles."""
    spring_indices: np.ndarray
    """Particle pair of each spring, shape (S, 2)."""
    spring_rest_length: np.ndarray
    """Spring rest lengths [m], shape (S,)."""
    spring_stiffness: np.ndarray
    """Spring stiffnesses [N/m], shape (S,)."""
    spring_damping: np.ndarray
    """Spring damping coefficients [N s/m], shape (S,)."""
    spring_body: np.ndarray
    """Body of each spring, shape (S,); -1 for springs between free particles."""
    attachment_particle: np.ndarray
    """Particle tied by each attachment spring, shape (A,)."""
    attachment_anchor: np.ndarray
    """Default anchor points [m], shape (A, 3); ``Control.attachment_anchor`` moves them."""
    attachment_rest_length: np.ndarray
    """Attachment rest lengths [m], shape (A,)."""
    attachment_stiffness: np.ndarray
    """Attachment stiffnesses [N/m], shape (A,)."""
    attachment_damping: np.ndarray
    """Attachment damping coefficients [N s/m], shape (A,)."""
    tri_indices: np.ndarray
    """Particle indices of each surface triangle, outward-wound, shape (T, 3)."""
    body_particle_range: np.ndarray
    """[begin, end) particle indices of each body, shape (B, 2)."""
    body_tri_range: np.ndarray
    """[begin, end) triangle indices of each body, shape (B, 2)."""
    body_mass: np.ndarray
    """Total mass of each body [kg], shape (B,)."""
    body_volume_method: np.ndarray
    """``VolumeMethod`` of each body, shape (B,)."""
    body_mc_range: np.ndarray
    """[begin, end) rows of ``mc_samples`` used by each Monte Carlo body, shape (B, 2)."""
    mc_samples: np.ndarray
    """Seeded sample points in [0, 1)^2 for Monte Carlo volumes, shape (M, 2)."""
    body_gas_law: np.ndarray
    """``GasLaw`` of each body, shape (B,)."""
    body_gas_value: np.ndarray
    """Driving gas value: nRT [J] (isothermal, adiabatic) or P0 [Pa] (fixed), shape (B,)."""
    body_gas_gamma: np.ndarray
    """Adiabatic exponent, shape (B,)."""
    body_gas_reference_volume: np.ndarray
    """Volume at which an adiabatic gas has P = nRT / V [m^3], shape (B,)."""
    body_ambient_pressure: np.ndarray
    """Pressure outside each body [Pa], shape (B,)."""
    body_schedule_range: np.ndarray
    """[begin, end) rows of the gas schedule of each body (empty: none), shape (B, 2)."""
    schedule_time: np.ndarray
    """Gas schedule times [s], shape (K,)."""
    schedule_value: np.ndarray
    """Gas schedule values (nRT [J] or P0 [Pa]), shape (K,)."""
    body_rest_volume: np.ndarray
    """Volume of each body at its initial positions by its own method [m^3], shape (B,)."""
    pin_particle: np.ndarray
    """Pinned (kinematic) particles, shape (P,); ``Control.pin_target`` moves them."""
    tri_body: np.ndarray
    """Body of each triangle, shape (T,)."""
    body_closed: np.ndarray
    """1 for a closed body holding gas, 0 for an open surface (cloth), shape (B,)."""
    body_contact_shape: np.ndarray
    """Bounding object of each body for ``bounding`` soft contacts: 1 box, 2 sphere,
    3 ellipsoid (``VolumeMethod`` numbering), shape (B,)."""
    soft_contact_mode: int
    """Soft-soft contacts: 0 none, 1 bounding objects (the paper), 2 surfaces."""
    soft_contact_restitution: float
    """Restitution of soft-soft contacts, in [0, 1]."""
    soft_contact_friction: float
    """Fraction of tangential relative speed removed by a soft-soft contact, in [0, 1]."""
    contact_margin: float
    """Distance [m] within which surface contacts look for the nearest triangle."""
    contact_cell_size: float
    """Grid cell [m] of the spatial hash for surface contacts."""
    collider_kind: np.ndarray
    """``ColliderKind`` of each rigid collider, shape (C,)."""
    collider_center: np.ndarray
    """Collider centres at t = 0 [m] (a plane: a point on it), shape (C, 3)."""
    collider_rotation: np.ndarray
    """Collider orientations at t = 0, shape (C, 3, 3) (a plane's normal is column 1)."""
    collider_size: np.ndarray
    """Box half-extents or sphere radius (repeated) [m], shape (C, 3)."""
    collider_restitution: np.ndarray
    """Restitution of each collider, shape (C,)."""
    collider_friction: np.ndarray
    """Fraction of tangential speed each collider removes at contact, shape (C,)."""
    collider_motion: np.ndarray
    """``MotionKind`` of each collider, shape (C,)."""
    collider_motion_vector: np.ndarray
    """Angular velocity [rad/s], velocity [m/s] or amplitude [m] of the motion, (C, 3)."""
    collider_motion_pivot: np.ndarray
    """Pivot of rotating colliders [m], shape (C, 3)."""
    collider_motion_frequency: np.ndarray
    """Frequency of oscillating colliders [Hz], shape (C,)."""
    body_drag_coefficient: np.ndarray
    """Aerodynamic drag coefficient C_d [1] of each body's faces, >= 0, shape (B,); 0
    leaves the body out of the drag term (``core/terms/drag.hpp``)."""
    air_density: float
    """Density rho of the air the bodies move through [kg/m^3], >= 0."""
    wind: np.ndarray
    """Velocity of the air [m/s], shape (3,); ``Control.wind`` overrides it per call."""
    data: ModelData = field(init=False, repr=False)
    """The same arrays bundled for the compiled kernels."""

    def __post_init__(self):
        for name in self.__dataclass_fields__:
            value = getattr(self, name, None)
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
        data = ModelData(**{name: getattr(self, name) for name in ModelData._fields})
        object.__setattr__(self, "data", data)

    # -- counts --------------------------------------------------------------------------
    @property
    def particle_count(self) -> int:
        """Number of particles N."""
        return int(self.particle_q.shape[0])

    @property
    def spring_count(self) -> int:
        """Number of springs S (edges, bending and user springs)."""
        return int(self.spring_indices.shape[0])

    @property
    def attachment_count(self) -> int:
        """Number of attachment springs A."""
        return int(self.attachment_particle.shape[0])

    @property
    def tri_count(self) -> int:
        """Number of surface triangles T."""
        return int(self.tri_indices.shape[0])

    @property
    def body_count(self) -> int:
        """Number of soft bodies B."""
        return int(self.body_particle_range.shape[0])

    @property
    def collider_count(self) -> int:
        """Number of rigid colliders C."""
        return int(self.collider_kind.shape[0])

    @property
    def pin_count(self) -> int:
        """Number of pinned particles P."""
        return int(self.pin_particle.shape[0])

    @property
    def has_drag(self) -> bool:
        """Whether any face feels air drag: some body has C_d > 0 in air of density > 0."""
        return bool(self.air_density > 0 and np.any(self.body_drag_coefficient > 0))

    def body_gas_law_of(self, body: int) -> GasLaw:
        """The gas law of ``body``."""
        return GasLaw(int(self.body_gas_law[body]))

    def body_volume_method_of(self, body: int) -> VolumeMethod:
        """The volume method of ``body``."""
        return VolumeMethod(int(self.body_volume_method[body]))

    # -- factories -----------------------------------------------------------------------
    def state(self):
        """A new :class:`State` at the initial positions and velocities, time 0."""
        from softbody.sim.state import State

        return State(
            self.particle_q.copy(),
            self.particle_qd.copy(),
            collider_q=self.collider_center.copy(),
            collider_rotation=self.collider_rotation.copy(),
            body_gas_override=np.full(self.body_count, np.nan),
        )

    def control(self):
        """A :class:`Control` that changes nothing: model gas, no forces, anchors in place."""
        from softbody.sim.control import Control

        return Control.neutral(self)

    def __repr__(self) -> str:
        return (
            f"Model(particle_count={self.particle_count}, spring_count={self.spring_count}, "
            f"tri_count={self.tri_count}, body_count={self.body_count}, "
            f"attachment_count={self.attachment_count}, pin_count={self.pin_count}, "
            f"collider_count={self.collider_count})"
        )
