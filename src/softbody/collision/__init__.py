"""Collisions: rigid colliders with prescribed motions, and soft body against soft body."""

from softbody.collision.colliders import (
    ColliderBox,
    ColliderKind,
    ColliderMesh,
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
    "ColliderMesh",
    "ColliderPlane",
    "ColliderSphere",
    "MotionOscillation",
    "MotionRotation",
    "MotionTranslation",
    "SoftContactMode",
    "rotation_about",
]
