"""Self-intersection search (issue 19 item 12): a closed mesh whose triangles cross each
other was accepted silently (or with "flipped inward-facing winding"); now it is found,
reported by ``softbody info`` and warned about on load."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

import softbody as sb
from softbody.errors import MeshWarning
from softbody.mesh.intersect import self_intersections, triangles_intersect

HAND = "src/softbody/scenes/meshes/hand.obj"
T = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # in the z = 0 plane


@pytest.mark.parametrize(
    ("other", "expected"),
    [
        # crossing: pierces T's interior through z = 0
        ([[0.2, 0.2, -1.0], [0.3, 0.2, 1.0], [0.2, 0.3, 1.0]], True),
        # touching: one vertex exactly on T's face, the rest above
        ([[0.2, 0.2, 0.0], [0.3, 0.2, 1.0], [0.2, 0.3, 1.0]], False),
        # touching edge to edge at T's hypotenuse, in another plane
        ([[0.5, 0.5, 0.0], [1.0, 1.0, 1.0], [1.0, 1.0, -1.0]], False),
        # parallel: the same triangle lifted by 0.1
        (T + np.array([0.0, 0.0, 0.1]), False),
        # coplanar, overlapping (shifted within the plane)
        (T + np.array([0.2, 0.2, 0.0]), True),
        # coplanar, contained (a small triangle inside T)
        (T * 0.1 + [0.2, 0.2, 0.0], True),
        # coplanar, disjoint (beyond the hypotenuse)
        (T * 0.3 + [0.8, 0.8, 0.0], False),
        # near miss: the plane of the other crosses T's plane outside T
        ([[2.0, 2.0, -1.0], [2.0, 3.0, 1.0], [3.0, 2.0, 1.0]], False),
    ],
    ids=[
        "crossing",
        "vertex-on-face",
        "edge-touch",
        "parallel",
        "coplanar-overlap",
        "coplanar-inside",
        "coplanar-apart",
        "near-miss",
    ],
)
def test_triangle_pair_test_on_hand_made_cases(other, expected):
    """The separating-axis test against cases whose answer is known by construction;
    touching (a shared point or segment with no overlap) counts as not crossing. Tested
    both ways round, and as segment-triangle where the answer is the same."""
    b = np.asarray(other, dtype=float)
    tol = 1e-9
    assert triangles_intersect(T[None], b[None], tol)[0] == expected
    assert triangles_intersect(b[None], T[None], tol)[0] == expected


def test_segment_against_triangle():
    """A segment is the degenerate triangle (a, b, b): piercing, beside, and lying in the
    plane across T (the coplanar in-plane axes decide the last two)."""
    seg = lambda a, b: np.array([[a, b, b]], dtype=float)  # noqa: E731
    assert triangles_intersect(seg([0.2, 0.2, -1], [0.2, 0.2, 1]), T[None], 1e-9)[0]
    assert not triangles_intersect(seg([2, 2, -1], [2, 2, 1]), T[None], 1e-9)[0]
    assert triangles_intersect(seg([-1, 0.3, 0], [2, 0.3, 0]), T[None], 1e-9)[0]
    assert not triangles_intersect(seg([-1, 2, 0], [2, 2, 0]), T[None], 1e-9)[0]


def _two_boxes() -> sb.TriMesh:
    a, b = sb.box(), sb.box(center=(0.5, 0.3, 0.2))
    return sb.TriMesh(np.vstack([a.vertices, b.vertices]), np.vstack([a.faces, b.faces + 8]))


def _pushed_sphere() -> sb.TriMesh:
    """The paper's ball with its top vertex pushed down through the bottom: its fan of six
    triangles now crosses the lower hemisphere, yet the mesh is closed and manifold."""
    m = sb.icosphere(2)
    v = m.vertices.copy()
    v[np.argmax(v[:, 1])] = [0.05, -1.3, 0.02]
    return sb.TriMesh(v, m.faces)


def test_two_overlapping_boxes_cross_in_twelve_pairs():
    """Two unit boxes offset by (0.5, 0.3, 0.2): every face of one crosses the other box's
    surface. Counted by brute force over all 276 pairs with the same pair test (no shared
    vertices between the boxes), which the grid broad phase must reproduce exactly."""
    m = _two_boxes()
    found = self_intersections(m.vertices, m.faces)
    c = m.vertices[m.faces]
    i, j = np.triu_indices(len(m.faces), 1)
    brute = triangles_intersect(c[i], c[j], 1e-9 * np.linalg.norm(np.ptp(m.vertices, 0)))
    assert len(found) == np.count_nonzero(brute) == 12
    assert {tuple(p) for p in found} == set(zip(i[brute], j[brute], strict=True))


def test_pushed_vertex_sphere_is_found_and_still_closed():
    """The pushed sphere passes every topological check (so the old code accepted it) but
    its fan crosses the far side: pairs found, none of them among the untouched faces."""
    m = _pushed_sphere()
    report = sb.inspect_mesh(m)
    assert report.problems == []
    assert report.self_intersection_count >= 6
    top = np.argmax(sb.icosphere(2).vertices[:, 1])
    fan = set(np.flatnonzero((m.faces == top).any(axis=1)).tolist())
    assert all(a in fan or b in fan for a, b in report.intersecting_pairs.tolist())


@pytest.mark.parametrize(
    "make",
    [
        lambda: sb.icosphere(4),
        lambda: sb.read_mesh(HAND),
        lambda: sb.box(subdivisions=2),
        lambda: sb.capsule(),
        lambda: sb.cylinder(),
        lambda: sb.uv_sphere(8, 16),
    ],
    ids=["icosphere", "hand", "box", "capsule", "cylinder", "uv_sphere"],
)
def test_clean_meshes_report_zero(make):
    """No false positives on clean closed meshes: flat fans (box, cylinder caps), poles
    (uv_sphere), thin fingers (the hand scan) and a 2,562-vertex sphere."""
    m = sb.inspect_mesh(make()).mesh
    assert len(self_intersections(m.vertices, m.faces)) == 0


def test_coplanar_fans_cross_exactly_when_their_sectors_overlap():
    """Two triangles in one plane sharing only a vertex overlap beyond it exactly when their
    angular sectors about that vertex overlap (each contains its sector's wedge near the
    vertex; disjoint sectors are separated by a line through it). Random fans, fixed seed:
    disjoint sectors (a flat fan, such as a stair's side) were reported crossing when the
    segment-against-triangle test lacked the triangle's own in-plane edge normals."""
    rng = np.random.default_rng(7)
    faces = np.array([[0, 1, 2], [0, 3, 4]])
    disjoint = overlapping = 0
    for _ in range(400):
        angle = np.sort(rng.uniform(0.0, 2.0 * np.pi, 4))
        radius = rng.uniform(0.2, 3.0, 4)
        if overlap := bool(rng.integers(2)):  # the second sector starts inside the first
            angle[2] = angle[0] + rng.uniform(0.1, 0.9) * (angle[1] - angle[0])
            angle[3] = angle[2] + rng.uniform(0.1, 3.0)
        if angle[1] - angle[0] >= np.pi - 0.05 or angle[3] - angle[2] >= np.pi - 0.05:
            continue
        ring = np.stack([radius * np.cos(angle), radius * np.sin(angle), 0 * angle], axis=1)
        v = np.vstack([np.zeros(3), ring]) @ _rotation(rng).T
        found = len(self_intersections(v, faces))
        assert found == int(overlap), (angle, radius)
        overlapping += overlap
        disjoint += not overlap
    assert disjoint > 100 and overlapping > 100


def _rotation(rng: np.random.Generator) -> np.ndarray:
    """A random rotation (3, 3): the QR factor of a Gaussian matrix, signs fixed."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q * np.sign(np.linalg.det(q))


def test_folded_neighbours_and_duplicate_triangles_count():
    """Neighbours across an edge cross only when folded flat onto each other; a triangle
    listed twice overlaps itself. Unfolded neighbours do not count."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.5, 0.2, 0], [0.5, -0.5, 0]], float)
    folded = np.array([[0, 1, 2], [1, 0, 3]])  # (3) lies on (2)'s side of edge 0-1
    flat = np.array([[0, 1, 2], [1, 0, 4]])  # (4) lies across the edge: a flat sheet
    twice = np.array([[0, 1, 2], [0, 1, 2]])
    assert len(self_intersections(v, folded)) == 1
    assert len(self_intersections(v, flat)) == 0
    assert len(self_intersections(v, twice)) == 1


def test_load_warns_naming_the_file_and_count(tmp_path):
    """Loading warns (MeshWarning with the path and the count) but does not refuse: a
    slightly self-intersecting mesh still encloses gas. The old loader was silent."""
    path = tmp_path / "pushed.obj"
    sb.save_mesh(_pushed_sphere(), path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mesh = sb.load_mesh(path)
    count = sb.inspect_mesh(mesh).self_intersection_count
    messages = [str(w.message) for w in caught if issubclass(w.category, MeshWarning)]
    assert any(str(path) in t and f"{count} pairs of triangles cross" in t for t in messages)


def test_inward_wound_crossing_mesh_reports_both_facts():
    """An inward-wound self-intersecting mesh is flipped by the winding seen from outside
    (rays), and the report says both that it was flipped and that it crosses itself."""
    m = _pushed_sphere().flipped()
    report = sb.inspect_mesh(m)
    assert report.outward_by_rays == -1
    assert report.repairs == ["flipped inward-facing winding"]
    assert report.self_intersection_count and report.warnings
    assert report.mesh.volume > 0


def test_info_prints_the_count(tmp_path):
    """`softbody info` on the pushed sphere prints the count and an example pair, and
    `none` for a clean mesh (the old command said neither)."""
    path = tmp_path / "pushed.obj"
    sb.save_mesh(_pushed_sphere(), path)
    count = sb.inspect_mesh(sb.read_mesh(path)).self_intersection_count
    run = lambda p: subprocess.run(  # noqa: E731
        [sys.executable, "-m", "softbody.cli", "info", str(p)], capture_output=True, text=True
    )
    out = run(path)
    assert out.returncode == 0, out.stderr
    assert f"self-intersecting: {count} pairs of triangles cross" in out.stdout
    assert "e.g. triangles" in out.stdout
    assert "self-intersections: none" in run(HAND).stdout


def test_run_warns_in_one_line_and_still_runs(tmp_path):
    """`softbody run` of a scene whose mesh crosses itself prints the load warning as
    one `softbody: warning:` line naming the file and the count (the CLI used to drop
    every warning) and still runs: the mesh can hold gas."""
    from softbody.cli import main

    path = tmp_path / "pushed.obj"
    sb.save_mesh(_pushed_sphere(), path)
    (tmp_path / "s.toml").write_text(
        "[simulation]\nintegrator = 'implicit_euler'\ndt = 0.01\nduration = 0.02\n"
        "[[bodies]]\nmesh = { file = 'pushed.obj' }\nmass = 1.0\nstiffness = 100.0\n"
        "gas = 10.0\n"
    )
    import contextlib
    import io

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["run", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out"),
                     "--no-video", "--no-gif"])  # fmt: skip
    assert code == 0, err.getvalue()
    lines = [line for line in err.getvalue().splitlines() if line.startswith("softbody: warning")]
    assert len(lines) == 1 and str(path) in lines[0] and "pairs of triangles cross" in lines[0]
