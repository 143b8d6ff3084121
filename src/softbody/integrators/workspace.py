"""Scratch arrays for one model, allocated once so that steps allocate nothing."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from softbody.partition import build_partition, pack_partition


class Workspace(NamedTuple):
    """Scratch for the step kernels; N particles, B bodies."""

    f: np.ndarray  # (N, 3) force accumulator [N]
    q0: np.ndarray  # (N, 3) positions at the start of the step [m]
    v0: np.ndarray  # (N, 3) velocities at the start of the step [m/s]
    qs: np.ndarray  # (N, 3) stage positions
    vs: np.ndarray  # (N, 3) stage velocities
    acc_q: np.ndarray  # (N, 3) RK4 weighted sum of position slopes
    acc_v: np.ndarray  # (N, 3) RK4 weighted sum of velocity slopes
    volume_gradient: np.ndarray  # (N, 3) dV/dx of each particle's body [m^2]
    body_volume: np.ndarray  # (B,) [m^3]
    body_pressure: np.ndarray  # (B,) [Pa]
    body_lo: np.ndarray  # (B, 3) [m]
    body_hi: np.ndarray  # (B, 3) [m]
    body_velocity: np.ndarray  # (B, 3) mass-weighted mean velocity [m/s]
    body_mass: np.ndarray  # (B,) mass of all its particles, pinned ones too [kg]
    body_center: np.ndarray  # (B, 3) bounding-object centres [m]
    body_axes: np.ndarray  # (B, 3) bounding-object semi-axes [m]
    body_dv: np.ndarray  # (B, 3) velocity change from soft contacts [m/s]
    collider_q_start: np.ndarray  # (C, 3) collider centres at the start of the call [m]
    collider_v: np.ndarray  # (C, 3) collider centre velocities [m/s]
    collider_w: np.ndarray  # (C, 3) collider angular velocities [rad/s]
    scratch: np.ndarray  # (3, 3) small temporaries
    hash_start: np.ndarray  # (H + 1,) spatial hash of triangles (surface contacts)
    hash_count: np.ndarray  # (H,)
    hash_entries: np.ndarray  # (E,)
    spring_u: np.ndarray  # (S, 3) implicit Euler: spring directions
    spring_a: np.ndarray  # (S,) axial stiffness [N/m]
    spring_b: np.ndarray  # (S,) transverse (geometric) stiffness [N/m]
    body_dpdv: np.ndarray  # (B,) dP/dV [Pa/m^3]
    body_pnet: np.ndarray  # (B,) P - P_ambient [Pa]
    cg_diag: np.ndarray  # (N,) Jacobi preconditioner [kg]
    cg_r: np.ndarray  # (N, 3) conjugate-gradient residual
    cg_z: np.ndarray  # (N, 3) preconditioned residual
    cg_p: np.ndarray  # (N, 3) search direction
    cg_ap: np.ndarray  # (N, 3) system matrix times search direction
    cg_x: np.ndarray  # (N, 3) velocity change being solved for [m/s]
    cg_stats: np.ndarray  # (3,) implicit steps, their CG iterations in all, the most in one
    q_prev: np.ndarray  # (N, 3) BDF2: positions at the start of the previous step [m]
    v_prev: np.ndarray  # (N, 3) BDF2: velocities at the start of the previous step [m/s]
    contacts_acted: np.ndarray  # (1,) BDF2: 1 when the last step's contacts acted
    q_end: np.ndarray  # (N, 3) BDF2: positions the last run ended with [m]
    v_end: np.ndarray  # (N, 3) BDF2: velocities the last run ended with [m/s]
    chunk_index: np.ndarray  # opt-in threads: the packed ``Partition``'s integers; [0] is
    # the chunk count (1: the serial kernels run)
    chunk_value: np.ndarray  # and its reals (``softbody.partition.pack_partition``)

    @classmethod
    def for_model(cls, model, hash_capacity: int | None = None, chunk_count: int = 1) -> Workspace:
        """Allocate scratch sized for ``model``; ``chunk_count`` > 1 cuts the particles
        into that many chunks for threaded kernels (``softbody.partition``)."""
        n, b, c = model.particle_count, model.body_count, model.collider_count
        if model.soft_contact_mode == 2:
            table = 1 << max(4, int(np.ceil(np.log2(2 * max(model.tri_count, 1)))))
            capacity = 8 * model.tri_count if hash_capacity is None else hash_capacity
        else:
            table, capacity = 1, 0
        return cls(
            *(np.zeros((n, 3)) for _ in range(8)),
            np.zeros(b),
            np.zeros(b),
            np.zeros((b, 3)),
            np.zeros((b, 3)),
            np.zeros((b, 3)),
            np.zeros(b),
            np.zeros((b, 3)),
            np.zeros((b, 3)),
            np.zeros((b, 3)),
            np.zeros((c, 3)),
            np.zeros((c, 3)),
            np.zeros((c, 3)),
            np.zeros((3, 3)),
            np.zeros(table + 1, dtype=np.int64),
            np.zeros(table, dtype=np.int64),
            np.zeros(capacity, dtype=np.int64),
            np.zeros((model.spring_count, 3)),
            np.zeros(model.spring_count),
            np.zeros(model.spring_count),
            np.zeros(b),
            np.zeros(b),
            np.zeros(n),
            *(np.zeros((n, 3)) for _ in range(5)),
            np.zeros(3, dtype=np.int64),
            np.zeros((n, 3)),
            np.zeros((n, 3)),
            np.zeros(1, dtype=np.int64),
            np.zeros((n, 3)),
            np.zeros((n, 3)),
            *pack_partition(build_partition(model, chunk_count)),
        )
