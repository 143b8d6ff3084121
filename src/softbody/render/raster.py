"""A small z-buffered software rasteriser (Numba): triangles and lines into an RGB image.

Headless on any machine, no GPU, display or system libraries. Depth is compared as 1/z
(camera distance), which interpolates linearly in screen space, so occlusion is right
per pixel: a ball standing on the ground is drawn in front of the ground behind it.
Colours are interpolated per vertex (Gouraud shading).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit


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


@njit(cache=True)
def clear(image, zbuffer, top, bottom):
    """Fill ``image`` (H, W, 3) with a vertical gradient ``top`` -> ``bottom`` (3,) and
    reset ``zbuffer`` (H, W) (it stores 1/depth; 0 is infinitely far)."""
    h = image.shape[0]
    for y in range(h):
        w = y / max(h - 1, 1)
        for x in range(image.shape[1]):
            zbuffer[y, x] = 0.0
            for k in range(3):
                image[y, x, k] = top[k] * (1.0 - w) + bottom[k] * w


@njit(cache=True)
def draw_triangles(screen, faces, colors, near, image, zbuffer):
    """Rasterise triangles with depth test and per-vertex colour.

    screen (V, 3): x, y [px] and camera depth [m]; faces (F, 3); colors (V, 3) in [0, 1];
    triangles with a vertex nearer than ``near`` [m] are skipped (no clipping).
    """
    h, w = zbuffer.shape
    for t in range(faces.shape[0]):
        i, j, k = faces[t, 0], faces[t, 1], faces[t, 2]
        z0, z1, z2 = screen[i, 2], screen[j, 2], screen[k, 2]
        if z0 < near or z1 < near or z2 < near:
            continue
        x0, y0 = screen[i, 0], screen[i, 1]
        x1, y1 = screen[j, 0], screen[j, 1]
        x2, y2 = screen[k, 0], screen[k, 1]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if area == 0.0:
            continue
        xmin = max(int(np.floor(min(x0, x1, x2))), 0)
        xmax = min(int(np.ceil(max(x0, x1, x2))), w - 1)
        ymin = max(int(np.floor(min(y0, y1, y2))), 0)
        ymax = min(int(np.ceil(max(y0, y1, y2))), h - 1)
        inv_area = 1.0 / area
        iz0, iz1, iz2 = 1.0 / z0, 1.0 / z1, 1.0 / z2
        for py in range(ymin, ymax + 1):
            cy = py + 0.5
            for px in range(xmin, xmax + 1):
                cx = px + 0.5
                b0 = ((x1 - cx) * (y2 - cy) - (x2 - cx) * (y1 - cy)) * inv_area
                b1 = ((x2 - cx) * (y0 - cy) - (x0 - cx) * (y2 - cy)) * inv_area
                b2 = 1.0 - b0 - b1
                if b0 < 0.0 or b1 < 0.0 or b2 < 0.0:
                    continue
                iz = b0 * iz0 + b1 * iz1 + b2 * iz2
                if iz <= zbuffer[py, px]:
                    continue
                zbuffer[py, px] = iz
                # perspective-correct colour weights
                w0, w1, w2 = b0 * iz0 / iz, b1 * iz1 / iz, b2 * iz2 / iz
                for c in range(3):
                    image[py, px, c] = w0 * colors[i, c] + w1 * colors[j, c] + w2 * colors[k, c]


@njit(cache=True)
def draw_lines(screen_a, screen_b, colors, width, near, depth_bias, image, zbuffer):
    """Rasterise line segments with depth test.

    screen_a, screen_b (L, 3): end points as x, y [px] and depth [m]; colors (L, 3);
    width [px]; a line pixel is drawn if it is no farther than the surface there, with
    ``depth_bias`` (relative) so that edges drawn over their own faces stay visible.
    """
    h, w = zbuffer.shape
    half = width // 2
    for s in range(screen_a.shape[0]):
        za, zb = screen_a[s, 2], screen_b[s, 2]
        if za < near or zb < near:
            continue
        xa, ya, xb, yb = screen_a[s, 0], screen_a[s, 1], screen_b[s, 0], screen_b[s, 1]
        n = int(max(abs(xb - xa), abs(yb - ya))) + 1
        if n > 4 * (w + h):
            continue  # absurdly long: an end point is near the camera plane
        iza, izb = 1.0 / za, 1.0 / zb
        for k in range(n + 1):
            u = k / n
            x = int(xa + u * (xb - xa))
            y = int(ya + u * (yb - ya))
            iz = iza + u * (izb - iza)
            for dy in range(-half, width - half):
                for dx in range(-half, width - half):
                    px, py = x + dx, y + dy
                    if px < 0 or py < 0 or px >= w or py >= h:
                        continue
                    if iz * (1.0 + depth_bias) < zbuffer[py, px]:
                        continue
                    zbuffer[py, px] = max(zbuffer[py, px], iz)
                    for c in range(3):
                        image[py, px, c] = colors[s, c]


@njit(cache=True)
def downsample(image, factor, out):
    """Average ``factor`` x ``factor`` blocks of ``image`` (H, W, 3) into ``out`` (uint8)."""
    for y in range(out.shape[0]):
        for x in range(out.shape[1]):
            for c in range(3):
                acc = 0.0
                for dy in range(factor):
                    for dx in range(factor):
                        acc += image[y * factor + dy, x * factor + dx, c]
                v = acc / (factor * factor) * 255.0 + 0.5
                out[y, x, c] = np.uint8(min(max(v, 0.0), 255.0))
