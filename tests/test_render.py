"""The renderer: per-pixel occlusion (z-buffer), not painter's ordering of whole objects."""

from __future__ import annotations

import numpy as np

import softbody as sb
from softbody.render.frame import FrameRenderer, RenderSettings, hex_rgb
from softbody.render.raster import Camera


def picture(ball_z: float) -> np.ndarray:
    """A red ball at depth ball_z in front of or behind a solid grey box, camera on +z."""
    builder = sb.ModelBuilder(gravity=(0, 0, 0))
    builder.add_soft_body(
        sb.icosphere(3, radius=0.3, center=(0, 0, ball_z)),
        mass=1.0,
        stiffness=1.0,
        damping=0.0,
        gas=1.0,
    )
    builder.add_collider(sb.ColliderBox(center=(0.0, 0.0, 0.0), half_extents=(0.6, 0.6, 0.1)))
    model = builder.finalize()
    settings = RenderSettings(
        width=160,
        height=120,
        camera=Camera(eye=(0, 0, 4), target=(0, 0, 0)),
        body_colors=("#ff0000",),
    )
    return FrameRenderer(model, settings).render(model.state())


def is_red(pixel) -> bool:
    r, g, b = (int(c) for c in pixel)
    return r > 60 and r > 2 * g and r > 2 * b


def test_nearer_surface_hides_farther_one():
    """Ball in front of the box: the centre pixel is the ball's red. Ball behind the box:
    the box hides it, though the ball is drawn after the box (a painter's order would
    show it)."""
    front = picture(0.6)
    behind = picture(-0.6)
    assert is_red(front[60, 80])
    assert not is_red(behind[60, 80])
    assert not np.any([is_red(p) for p in behind.reshape(-1, 3)])


def test_ball_on_ground_is_in_front_of_ground():
    """mplot3d's failure case (STACK-NOTES): a ball standing on a ground plane is drawn
    over the ground behind it, and the ground in front of its base is not hidden."""
    builder = sb.ModelBuilder()
    builder.add_soft_body(
        sb.icosphere(3, radius=0.5, center=(0, 0.5, 0)),
        mass=1.0,
        stiffness=1.0,
        damping=0.0,
        gas=1.0,
    )
    builder.add_collider(sb.ColliderPlane())
    model = builder.finalize()
    settings = RenderSettings(
        width=160,
        height=120,
        body_colors=("#ff0000",),
        camera=Camera(eye=(0, 1.5, 4), target=(0, 0.5, 0)),
    )
    image = FrameRenderer(model, settings).render(model.state())
    cam = settings.camera
    centre = cam.project(np.array([[0.0, 0.5, 0.0]]), 160, 120)[0]
    assert is_red(image[int(centre[1]), int(centre[0])])
    ahead = cam.project(np.array([[0.0, 0.0, 1.2]]), 160, 120)[0]  # ground in front
    assert not is_red(image[int(ahead[1]), int(ahead[0])])
    assert hex_rgb("#ff0000").tolist() == [1.0, 0.0, 0.0]


def test_rasteriser_refuses_bad_arrays_and_draws_nothing_for_non_finite_points():
    """The compiled loops never read or write outside their arrays: a face index past the
    points or a mismatched buffer is a ValueError; NaN or infinite points (a blown-up
    body) draw nothing, nor does a line to a point far off the image; a triangle reaching
    far off the image draws only its part on it, and a normal triangle draws."""
    import pytest

    from softbody.render.raster import clear, draw_lines, draw_triangles

    image, z = np.zeros((40, 50, 3)), np.zeros((40, 50))
    clear(image, z, np.zeros(3), np.zeros(3))
    colors = np.ones((3, 3))
    with pytest.raises(ValueError, match="faces holds 3"):
        draw_triangles(np.ones((3, 3)), np.array([[0, 1, 3]]), colors, 1e-3, image, z)
    with pytest.raises(ValueError, match="zbuffer must have shape"):
        draw_triangles(np.ones((3, 3)), np.array([[0, 1, 2]]), colors, 1e-3, image, z[:10])
    with pytest.raises(ValueError, match="zbuffer must be a writable C-contiguous"):
        draw_triangles(np.ones((3, 3)), np.array([[0, 1, 2]]), colors, 1e-3, image, z[:, :10])
    for bad in (np.nan, np.inf, 1e300):
        screen = np.array([[bad, 5.0, 1.0], [30.0, 5.0, 1.0], [5.0, 30.0, 1.0]])
        draw_lines(screen[:1], screen[1:2], colors[:1], 2, 1e-3, 0.0, image, z)
        if bad != 1e300:
            draw_triangles(screen, np.array([[0, 1, 2]]), colors, 1e-3, image, z)
        assert not image.any() and not z.any()
    far = np.array([[1e300, 5.0, 1.0], [30.0, 5.0, 1.0], [5.0, 30.0, 1.0]])
    draw_triangles(far, np.array([[0, 1, 2]]), colors, 1e-3, image, z)
    assert 0 < (z > 0).sum() < z.size
    clear(image, z, np.zeros(3), np.zeros(3))
    screen = np.array([[5.0, 5.0, 1.0], [30.0, 5.0, 1.0], [5.0, 30.0, 1.0]])
    draw_triangles(screen, np.array([[0, 1, 2]]), colors, 1e-3, image, z)
    # the right triangle of legs 25 px covers about 25^2 / 2 pixel centres
    assert abs(int((z > 0).sum()) - 312) < 30
