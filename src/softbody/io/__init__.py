"""Exports: per-frame mesh sequences (OBJ, PLY) and USD point caches."""

from softbody.io.sequence import write_mesh_frame
from softbody.io.usd import write_usd

__all__ = ["write_mesh_frame", "write_usd"]
