"""A small z-buffered software rasteriser: triangles and lines into an RGB image (the loops
are the compiled core's, ``core/render/raster.cpp``).

Headless on any machine, no GPU, display or system libraries. Depth is compared as 1/z
(camera distance), which interpolates linearly in screen space, so occlusion is right
per pixel: a ball standing on the ground is drawn in front of the ground behind it.
Colours are interpolated per vertex (Gouraud shading).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from softbody import _core


@dataclass(frozen=True)
class Camera:
    """Perspective camera looking from ``eye`` at ``target`` [m], vertical ``fov`` [deg]."""

    eye: tuple[float, float, float] = (0.0, 1.5, 6.0)
    target: tuple[float, float, float] = (0.0, 0.5, 0.0)
    fov: float = 40.0
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)

    def basis(self) -> np.ndarray:
        """Rows: right, up, forward unit vectors (3, 3)."""
        f = np.asarray(self.target, float) - np.asarray(self.eye, float)
        if not np.linalg.norm(f) > 0:
            raise ValueError(
                f"the camera's eye and target are both at {tuple(self.eye)}: it sees no "
                "direction (move the eye or the target)"
            )
        f /= np.linalg.norm(f)
        r = np.cross(f, self.up)
        if np.linalg.norm(r) < 1e-9:
            r = np.cross(f, (0.0, 0.0, 1.0))
        r /= np.linalg.norm(r)
        return np.stack([r, np.cross(r, f), f])

    def project(self, points: np.ndarray, width: int, height: int) -> np.ndarray:
        """Screen x, y [px] and camera depth z [m] of points (N, 3), as (N, 3)."""
        b = self.basis()
        c = (np.asarray(points, float) - np.asarray(self.eye, float)) @ b.T
        focal = 0.5 * height / np.tan(np.radians(self.fov) / 2)
        z = c[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            sx = 0.5 * width + focal * c[:, 0] / z
            sy = 0.5 * height - focal * c[:, 1] / z
        return np.stack([sx, sy, z], axis=1)


def _input(a, dtype=np.float64) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=dtype)


def _buffer(a, name: str, dtype=np.float64) -> np.ndarray:
    """An output array the loops write into: it must already be C-contiguous, writable and
    of ``dtype`` (a converted copy would take the drawing and be thrown away)."""
    if not (
        isinstance(a, np.ndarray)
        and a.dtype == dtype
        and a.flags.c_contiguous
        and a.flags.writeable
    ):
        raise ValueError(f"{name} must be a writable C-contiguous {np.dtype(dtype)} array")
    return a


def clear(image: np.ndarray, zbuffer: np.ndarray, top, bottom) -> None:
    """Fill ``image`` (H, W, 3) with a vertical gradient ``top`` -> ``bottom`` (3,) and
    reset ``zbuffer`` (H, W) (it stores 1/depth; 0 is infinitely far)."""
    _core.raster_clear(
        _buffer(image, "image"), _buffer(zbuffer, "zbuffer"), _input(top), _input(bottom)
    )


def draw_triangles(screen, faces, colors, near: float, image, zbuffer) -> None:
    """Rasterise triangles with depth test and per-vertex colour.

    screen (V, 3): x, y [px] and camera depth [m]; faces (F, 3); colors (V, 3) in [0, 1];
    triangles with a vertex nearer than ``near`` [m] are skipped (no clipping). Depth is
    compared as 1/z, which interpolates linearly in screen space; colours are weighted
    perspective-correctly.
    """
    _core.raster_triangles(
        _input(screen), _input(faces, np.int64), _input(colors), float(near),
        _buffer(image, "image"), _buffer(zbuffer, "zbuffer"),
    )  # fmt: skip


def draw_lines(screen_a, screen_b, colors, width: int, near: float, depth_bias: float,
               image, zbuffer) -> None:  # fmt: skip
    """Rasterise line segments with depth test.

    screen_a, screen_b (L, 3): end points as x, y [px] and depth [m]; colors (L, 3);
    width [px]; a line pixel is drawn if it is no farther than the surface there, with
    ``depth_bias`` (relative) so that edges drawn over their own faces stay visible.
    """
    _core.raster_lines(
        _input(screen_a), _input(screen_b), _input(colors), int(width), float(near),
        float(depth_bias), _buffer(image, "image"), _buffer(zbuffer, "zbuffer"),
    )  # fmt: skip


def downsample(image: np.ndarray, factor: int, out: np.ndarray) -> None:
    """Average ``factor`` x ``factor`` blocks of ``image`` (H, W, 3) into ``out`` (uint8)."""
    _core.raster_downsample(_buffer(image, "image"), int(factor), _buffer(out, "out", np.uint8))
