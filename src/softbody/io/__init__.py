"""Exports: per-frame mesh sequences (OBJ, PLY) and USD caches of bodies and colliders."""

from softbody.io.sequence import write_mesh_frame
from softbody.io.usd import write_usd

__all__ = ["write_mesh_frame", "write_usd"]
