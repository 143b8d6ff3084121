"""Scenes: built-in TOML scene files (the paper's figures), their schema and loader."""

from softbody.scenes.loader import (
    Scene,
    SceneError,
    apply_overrides,
    build_scene,
    builtin_scene_text,
    list_scenes,
    load_scene,
    scene_text,
    validate,
)
from softbody.scenes.schema import SceneSpec, scene_json_schema

__all__ = [
    "Scene",
    "SceneError",
    "SceneSpec",
    "apply_overrides",
    "build_scene",
    "builtin_scene_text",
    "list_scenes",
    "load_scene",
    "scene_json_schema",
    "scene_text",
    "validate",
]
