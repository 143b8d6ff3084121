"""Scenes: built-in TOML scene files (the paper's figures) and their loader."""

from softbody.scenes.loader import (
    Scene,
    SceneError,
    apply_overrides,
    build_scene,
    list_scenes,
    load_scene,
    scene_text,
)

__all__ = [
    "Scene",
    "SceneError",
    "apply_overrides",
    "build_scene",
    "list_scenes",
    "load_scene",
    "scene_text",
]
