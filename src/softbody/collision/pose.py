"""Collider poses over time: prescribed motions, or targets given through Control."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _rotate_about(ax, ay, az, angle, out):
    """Rodrigues rotation matrix for unit axis (ax, ay, az) and ``angle`` [rad] into out (3, 3)."""
    s, c = np.sin(angle), np.cos(angle)
    t = 1.0 - c
    out[0, 0] = c + ax * ax * t
    out[0, 1] = ax * ay * t - az * s
    out[0, 2] = ax * az * t + ay * s
    out[1, 0] = ay * ax * t + az * s
    out[1, 1] = c + ay * ay * t
    out[1, 2] = ay * az * t - ax * s
    out[2, 0] = az * ax * t - ay * s
    out[2, 1] = az * ay * t + ax * s
    out[2, 2] = c + az * az * t


@njit(cache=True)
def eval_collider_poses(
    collider_motion,
    collider_center,
    collider_rotation,
    collider_motion_vector,
    collider_motion_pivot,
    collider_motion_frequency,
    collider_target,
    target_fraction,
    target_duration,
    t,
    collider_q_start,
    collider_q,
    collider_rot,
    collider_v,
    collider_w,
    rot,
):
    """Pose and velocity of every collider at time ``t`` [s].

    Prescribed motions start from the model's pose (``collider_center`` (C, 3),
    ``collider_rotation`` (C, 3, 3)) at t = 0. A collider with a finite
    ``collider_target`` (C, 3) instead moves in a straight line from ``collider_q_start``
    to the target over ``target_duration`` [s]; ``target_fraction`` of it has passed.
    Outputs: centre collider_q (C, 3) [m], rotation collider_rot (C, 3, 3), centre
    velocity collider_v (C, 3) [m/s], angular velocity collider_w (C, 3) [rad/s].
    rot is (3, 3) scratch.
    """
    for c in range(collider_motion.shape[0]):
        for k in range(3):
            collider_w[c, k] = 0.0
            collider_v[c, k] = 0.0
        if np.isfinite(collider_target[c, 0]):
            for k in range(3):
                d = collider_target[c, k] - collider_q_start[c, k]
                collider_q[c, k] = collider_q_start[c, k] + target_fraction * d
                collider_v[c, k] = d / target_duration
            continue
        motion = collider_motion[c]
        if motion == 0:
            for k in range(3):
                collider_q[c, k] = collider_center[c, k]
            collider_rot[c] = collider_rotation[c]
        elif motion == 1:
            wx, wy, wz = (
                collider_motion_vector[c, 0],
                collider_motion_vector[c, 1],
                collider_motion_vector[c, 2],
            )
            rate = np.sqrt(wx * wx + wy * wy + wz * wz)
            if rate > 0.0:
                _rotate_about(wx / rate, wy / rate, wz / rate, rate * t, rot)
            else:
                _rotate_about(1.0, 0.0, 0.0, 0.0, rot)
            p = collider_motion_pivot[c]
            for i in range(3):
                acc = 0.0
                for j in range(3):
                    acc += rot[i, j] * (collider_center[c, j] - p[j])
                    s = 0.0
                    for k in range(3):
                        s += rot[i, k] * collider_rotation[c, k, j]
                    collider_rot[c, i, j] = s
                collider_q[c, i] = p[i] + acc
            collider_w[c, 0], collider_w[c, 1], collider_w[c, 2] = wx, wy, wz
            rx = collider_q[c, 0] - p[0]
            ry = collider_q[c, 1] - p[1]
            rz = collider_q[c, 2] - p[2]
            collider_v[c, 0] = wy * rz - wz * ry
            collider_v[c, 1] = wz * rx - wx * rz
            collider_v[c, 2] = wx * ry - wy * rx
        elif motion == 2:
            for k in range(3):
                collider_q[c, k] = collider_center[c, k] + collider_motion_vector[c, k] * t
                collider_v[c, k] = collider_motion_vector[c, k]
            collider_rot[c] = collider_rotation[c]
        else:
            omega = 2.0 * np.pi * collider_motion_frequency[c]
            for k in range(3):
                a = collider_motion_vector[c, k]
                collider_q[c, k] = collider_center[c, k] + a * np.sin(omega * t)
                collider_v[c, k] = a * omega * np.cos(omega * t)
            collider_rot[c] = collider_rotation[c]
