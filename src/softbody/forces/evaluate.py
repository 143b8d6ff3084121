"""The total force on every particle: the list of physics terms, in the paper's order."""

from __future__ import annotations

from numba import njit

from softbody.forces.external import eval_external_forces, eval_grab_force
from softbody.forces.gravity import eval_gravity
from softbody.forces.pressure import eval_pressure_forces
from softbody.forces.springs import (
    eval_attachment_forces,
    eval_spring_forces,
    eval_spring_forces_threaded,
)
from softbody.gas import eval_model_pressure
from softbody.partition import spring_chunks
from softbody.volume import eval_model_volume


@njit(cache=True)
def _spring_forces_on_threads(m, q, qd, w, f):
    """``eval_spring_forces_threaded`` on the workspace's packed partition."""
    start, indices, rest, stiffness, damping = spring_chunks(
        w.chunk_index, w.chunk_value, m.spring_indices.shape[0]
    )
    eval_spring_forces_threaded(q, qd, start, indices, rest, stiffness, damping, f)


@njit(cache=True)
def eval_forces(m, c, t, q, qd, w, f):
    """All forces at time ``t`` [s] for positions ``q`` and velocities ``qd`` (N, 3).

    m : ModelData, c : ControlData, w : Workspace (its body_volume, body_pressure,
    volume_gradient, body_lo/hi are refreshed as a side product); f : (N, 3) output [N].
    """
    # weight, m g (initialises the accumulator)
    eval_gravity(m.particle_mass, m.gravity, f)
    # damped Hooke springs: mesh edges, bending springs, user springs (on threads when the
    # workspace is cut into chunks)
    if w.chunk_index[0] > 1:
        _spring_forces_on_threads(m, q, qd, w, f)
    else:
        eval_spring_forces(
            q, qd, m.spring_indices, m.spring_rest_length, m.spring_stiffness, m.spring_damping, f
        )
    # springs to fixed points (the paper's hanging ball)
    eval_attachment_forces(
        q,
        qd,
        m.attachment_particle,
        c.attachment_anchor,
        m.attachment_rest_length,
        m.attachment_stiffness,
        m.attachment_damping,
        f,
    )
    eval_body_forces(m, c, t, q, qd, w, f)


@njit(cache=True)
def eval_body_forces(m, c, t, q, qd, w, f):
    """The terms of :func:`eval_forces` after gravity, springs and attachments, added
    into ``f`` (N, 3) [N]: external and grab forces, and the gas pressure (refreshing
    w.body_volume, w.body_pressure, w.volume_gradient). Projective dynamics takes the
    springs and attachments into its matrix and these as forces."""
    # per-step external forces from Control
    eval_external_forces(c.particle_f, f)
    # a grabbed particle pulled toward a target (interactive use)
    eval_grab_force(q, qd, c.grab_particle, c.grab_target, c.grab_stiffness, c.grab_damping, f)
    # body volumes and their gradients dV/dx (area-weighted vertex normals)
    eval_model_volume(m, q, w)
    # gas law: P(V, nRT(t))
    eval_model_pressure(m, t, c.gas_override, w)
    # pressure force (P - P_ambient) A n / 3 per face corner = (P - P_ambient) dV/dx
    eval_pressure_forces(
        m.body_particle_range, w.body_pressure, m.body_ambient_pressure, w.volume_gradient, f
    )
