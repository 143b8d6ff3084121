"""Collisions: rigid colliders with prescribed motions, and soft body against soft body."""

from softbody.collision.colliders import (
    ColliderBox,
    ColliderKind,
    ColliderPlane,
    ColliderSphere,
    MotionOscillation,
    MotionRotation,
    MotionTranslation,
    SoftContactMode,
    rotation_about,
)

__all__ = [
    "ColliderBox",
    "ColliderKind",
    "ColliderPlane",
    "ColliderSphere",
    "MotionOscillation",
    "MotionRotation",
    "MotionTranslation",
    "SoftContactMode",
    "rotation_about",
]
