"""Compose a picture of a model's state: ground, colliders, bodies, and overlays."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from softbody.collision.colliders import ColliderKind
from softbody.collision.mesh_collider import collider_mesh
from softbody.mesh.generators import icosphere
from softbody.mesh.topology import unique_edges
from softbody.render.raster import Camera, clear, downsample, draw_lines, draw_triangles
from softbody.sim.model import Model
from softbody.sim.state import State

#: Body colours, cycled (Tableau 10).
PALETTE = (
    "#4e79a7",
    "#f28e2b",
    "#e15759",
    "#76b7b2",
    "#59a14f",
    "#edc948",
    "#b07aa1",
    "#ff9da7",
    "#9c755f",
    "#bab0ac",
)
LIGHT = np.array([0.35, 0.85, 0.45]) / np.linalg.norm([0.35, 0.85, 0.45])
BOX_EDGES = np.array(
    [[0, 1], [2, 3], [4, 5], [6, 7], [0, 2], [1, 3], [4, 6], [5, 7], [0, 4], [1, 5], [2, 6], [3, 7]]
)
BOX_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)


def hex_rgb(color: str) -> np.ndarray:
    """'#rrggbb' -> (3,) floats in [0, 1]."""
    c = color.lstrip("#")
    if len(c) != 6:
        raise ValueError(f"colour must be '#rrggbb', got {color!r}")
    return np.array([int(c[k : k + 2], 16) for k in (0, 2, 4)], float) / 255.0


#: Widest and tallest image the renderer draws [px] (``render.width``, ``render.height``).
MAX_IMAGE_SIDE = 4096


@dataclass(frozen=True)
class RenderSettings:
    """How frames look. Sizes in pixels, ``fps`` frames per simulated second."""

    width: int = 640
    height: int = 480
    fps: float = 30.0
    camera: Camera = field(default_factory=Camera)
    style: str = "solid"
    """``"solid"``, ``"wireframe"`` or ``"both"`` (solid with edges)."""
    velocity_vectors: bool = False
    """Draw each vertex's velocity (paper, Figure 7)."""
    velocity_scale: float = 0.05
    """Seconds of motion each velocity vector shows [s]."""
    bounding_objects: bool = False
    """Draw each body's bounding box, sphere and ellipsoid (paper, Figure 5)."""
    body_colors: tuple[str, ...] = PALETTE
    supersample: int = 2
    ground_size: float = 8.0
    """Side of the drawn part of each ground plane [m]."""
    usd_start_frame: float = 0.0
    """Time code of the first frame in a USD export (frame k at ``usd_start_frame + k``)."""

    def __post_init__(self):
        if self.style not in ("solid", "wireframe", "both"):
            raise ValueError(
                f"render style must be 'solid', 'wireframe' or 'both', got {self.style!r}"
            )
        for name in ("width", "height"):
            v = getattr(self, name)
            if int(v) != v or not 16 <= v <= MAX_IMAGE_SIDE:
                raise ValueError(
                    f"render {name} must be an integer in [16, {MAX_IMAGE_SIDE}], got {v!r}"
                )
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"render fps must be > 0, got {self.fps!r}")
        if not (np.isfinite(self.ground_size) and self.ground_size > 0):
            raise ValueError(
                f"render ground_size must be finite and > 0 [m], got {self.ground_size!r}"
            )
        if not (np.isfinite(self.usd_start_frame) and abs(self.usd_start_frame) <= 1e15):
            raise ValueError(
                f"render usd_start_frame must be a finite time code, got {self.usd_start_frame!r}"
            )
        for c in self.body_colors:
            hex_rgb(c)


def _shade(vertices: np.ndarray, faces: np.ndarray, color: np.ndarray, two_sided: bool):
    """Per-vertex colours (V, 3): ambient + Lambert from area-weighted vertex normals."""
    n = np.cross(
        vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]
    )
    vn = np.zeros_like(vertices)
    for k in range(3):
        for c in range(3):
            vn[:, c] += np.bincount(faces[:, k], weights=n[:, c], minlength=len(vertices))
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
    lam = vn @ LIGHT
    lam = np.abs(lam) if two_sided else np.maximum(lam, 0.0)
    return color * (0.32 + 0.68 * lam)[:, None]


def _ellipse_segments(center, axes, count=48):
    """Three principal ellipses of an axis-aligned ellipsoid, as (3 count, 2, 3) segments."""
    t = np.linspace(0, 2 * np.pi, count + 1)
    segs = []
    for i, j in ((0, 1), (1, 2), (0, 2)):
        p = np.zeros((count + 1, 3))
        p[:, i] = axes[i] * np.cos(t)
        p[:, j] = axes[j] * np.sin(t)
        p += center
        segs.append(np.stack([p[:-1], p[1:]], axis=1))
    return np.concatenate(segs)


def bounding_segments(v: np.ndarray):
    """Wireframes of the paper's bounding objects of points v (N, 3), as segment arrays
    (K, 2, 3): the axis-aligned box, the sphere and the ellipsoid (as in softbody.volume:
    centred on the box, the ellipsoid with the box's aspect ratio)."""
    lo, hi = v.min(axis=0), v.max(axis=0)
    c = 0.5 * (lo + hi)
    half = np.maximum(0.5 * (hi - lo), 1e-12)
    r = np.linalg.norm(v - c, axis=1).max()
    scale = np.sqrt((((v - c) / half) ** 2).sum(axis=1).max())
    return (
        c + (BOX_CORNERS * half)[BOX_EDGES],
        _ellipse_segments(c, np.array([r, r, r])),
        _ellipse_segments(c, scale * half),
    )


class FrameRenderer:
    """Draws frames of one model. Buffers are allocated once and reused."""

    def __init__(
        self, model: Model, settings: RenderSettings, *, open_bodies: np.ndarray | None = None
    ):
        self.model = model
        self.settings = settings
        s = settings.supersample
        self._hi = np.zeros((settings.height * s, settings.width * s, 3))
        self._z = np.zeros((settings.height * s, settings.width * s))
        self._out = np.zeros((settings.height, settings.width, 3), dtype=np.uint8)
        self._colors = [
            hex_rgb(settings.body_colors[b % len(settings.body_colors)])
            for b in range(model.body_count)
        ]
        self._open = (
            np.zeros(model.body_count, bool)
            if open_bodies is None
            else np.asarray(open_bodies, bool)
        )
        self._edges = [
            unique_edges(model.tri_indices[t0:t1]) - p0
            for (t0, t1), (p0, _) in zip(
                model.body_tri_range, model.body_particle_range, strict=True
            )
        ]
        self._sphere = icosphere(3)

    # -- primitives per frame ------------------------------------------------------------
    def _ground(self, center, rot):
        """Checkerboard quads of a plane collider, as (vertices, faces, colours)."""
        size = self.settings.ground_size
        n = 16
        tile = size / n
        ex, ez = rot[:, 0], rot[:, 2]
        verts, faces, cols = [], [], []
        for a in range(n):
            for b in range(n):
                u0, w0 = -size / 2 + a * tile, -size / 2 + b * tile
                quad = [
                    center + ex * u + ez * w
                    for u, w in ((u0, w0), (u0 + tile, w0), (u0 + tile, w0 + tile), (u0, w0 + tile))
                ]
                base = len(verts)
                verts += quad
                faces += [[base, base + 2, base + 1], [base, base + 3, base + 2]]
                shade = 0.82 if (a + b) % 2 else 0.70
                cols += [[shade, shade, shade * 0.97]] * 4
        return np.array(verts), np.array(faces), np.array(cols)

    def render(self, state: State) -> np.ndarray:
        """The frame for ``state`` as an (H, W, 3) uint8 image."""
        st = self.settings
        model = self.model
        s = st.supersample
        w, h = st.width * s, st.height * s
        cam = st.camera
        clear(self._hi, self._z, np.array([0.93, 0.95, 0.98]), np.array([0.78, 0.82, 0.88]))
        near = 1e-3
        lines_a, lines_b, line_colors = [], [], []

        def add_mesh(vertices, faces, colors):
            screen = cam.project(vertices, w, h)
            draw_triangles(screen, faces.astype(np.int64), colors, near, self._hi, self._z)

        def add_lines(segments, color):
            if len(segments) == 0:
                return
            lines_a.append(segments[:, 0])
            lines_b.append(segments[:, 1])
            line_colors.append(np.broadcast_to(color, (len(segments), 3)))

        for c in range(model.collider_count):
            kind = int(model.collider_kind[c])
            center, rot = state.collider_q[c], state.collider_rotation[c]
            size = model.collider_size[c]
            if kind == ColliderKind.PLANE:
                # the drawn patch is centred under the camera's target
                normal = rot[:, 1]
                offset = np.asarray(cam.target, float) - center
                add_mesh(*self._ground(center + offset - (offset @ normal) * normal, rot))
            elif kind == ColliderKind.SPHERE:
                v = center + size[0] * self._sphere.vertices
                add_mesh(
                    v,
                    self._sphere.faces,
                    _shade(v, self._sphere.faces, np.array([0.55, 0.55, 0.58]), False),
                )
            elif kind == ColliderKind.MESH:
                local, tris = collider_mesh(model, c)
                v = (center + local @ rot.T)[tris].reshape(-1, 3)  # flat: corners apart
                flat = np.arange(len(v)).reshape(-1, 3)
                add_mesh(v, flat, _shade(v, flat, np.array([0.6, 0.6, 0.62]), False))
            else:
                corners = center + (BOX_CORNERS * size) @ rot.T
                add_lines(corners[BOX_EDGES], np.array([0.25, 0.27, 0.3]))
                if kind == ColliderKind.BOX:
                    faces = np.array(
                        [
                            [0, 1, 3],
                            [0, 3, 2],
                            [4, 6, 7],
                            [4, 7, 5],
                            [0, 4, 5],
                            [0, 5, 1],
                            [2, 3, 7],
                            [2, 7, 6],
                            [0, 2, 6],
                            [0, 6, 4],
                            [1, 5, 7],
                            [1, 7, 3],
                        ]
                    )
                    col = np.array([0.6, 0.6, 0.62])
                    for f in faces:  # flat shading: one colour per face
                        n = np.cross(corners[f[1]] - corners[f[0]], corners[f[2]] - corners[f[0]])
                        n /= np.linalg.norm(n)
                        lam = max(abs(float(n @ LIGHT)), 0.0)
                        add_mesh(
                            corners[f],
                            np.array([[0, 1, 2]]),
                            np.tile(col * (0.32 + 0.68 * lam), (3, 1)),
                        )

        q = state.particle_q
        for b, (p0, p1) in enumerate(model.body_particle_range):
            t0, t1 = model.body_tri_range[b]
            faces = model.tri_indices[t0:t1] - p0
            v = q[p0:p1]
            color = self._colors[b]
            if st.style in ("solid", "both"):
                add_mesh(v, faces, _shade(v, faces, color, bool(self._open[b])))
            if st.style in ("wireframe", "both"):
                edge_color = color * 0.45 if st.style == "both" else color * 0.8
                add_lines(v[self._edges[b]], edge_color)
            if st.velocity_vectors:
                vel = state.particle_qd[p0:p1]
                add_lines(
                    np.stack([v, v + st.velocity_scale * vel], axis=1), np.array([0.85, 0.1, 0.1])
                )
            if st.bounding_objects:
                box, sphere, ellipsoid = bounding_segments(v)
                add_lines(box, np.array([0.2, 0.35, 0.85]))
                add_lines(sphere, np.array([0.2, 0.65, 0.3]))
                add_lines(ellipsoid, np.array([0.85, 0.25, 0.2]))

        if lines_a:
            a = cam.project(np.concatenate(lines_a), w, h)
            b = cam.project(np.concatenate(lines_b), w, h)
            draw_lines(
                a,
                b,
                np.ascontiguousarray(np.concatenate(line_colors)),
                s,
                near,
                2e-3,
                self._hi,
                self._z,
            )
        downsample(self._hi, s, self._out)
        return self._out.copy()
