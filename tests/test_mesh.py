"""Meshes: generators, closed-form volumes, validation and repair, file formats."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import softbody as sb
from softbody.mesh.topology import bending_pairs, unique_rows

GENERATED = {
    "icosphere": lambda: sb.icosphere(2),
    "uv_sphere": lambda: sb.uv_sphere(8, 16),
    "box": lambda: sb.box(subdivisions=2),
    "capsule": lambda: sb.capsule(),
    "cylinder": lambda: sb.cylinder(),
}


@pytest.mark.parametrize("name", sorted(GENERATED))
def test_generators_are_closed_outward_genus_zero(name):
    """Every generator gives a closed, outward surface: V - E + F = 2 (Euler, genus 0)."""
    mesh = GENERATED[name]()
    report = sb.inspect_mesh(mesh)
    assert report.problems == [] and report.repairs == []
    assert mesh.volume > 0
    assert mesh.vertex_count - len(mesh.edges) + mesh.face_count == 2


def test_icosphere_counts_match_paper():
    """The paper's ball: 162 vertices and 320 faces (subdivision level 2)."""
    for s, v in [(0, 12), (1, 42), (2, 162), (3, 642)]:
        m = sb.icosphere(s)
        assert m.vertex_count == v and m.face_count == 2 * v - 4


def test_unit_cube_volume_is_one():
    """Divergence theorem on the unit cube: V = 1 (exact in floating point up to 1e-15)."""
    for level in (0, 1, 3):
        assert sb.box(subdivisions=level).volume == pytest.approx(1.0, abs=1e-14)
    assert sb.box((2.0, 3.0, 0.5), center=(100, -50, 7)).volume == pytest.approx(3.0, rel=1e-13)


def test_icosahedron_volume_closed_form():
    """Regular icosahedron, circumradius r: edge a = 4r/sqrt(10+2 sqrt5), V = 5/12 (3+sqrt5) a^3."""
    r = 1.7
    a = 4 * r / np.sqrt(10 + 2 * np.sqrt(5))
    expected = 5.0 / 12.0 * (3 + np.sqrt(5)) * a**3
    mesh = sb.icosphere(0, radius=r, center=(3.0, -2.0, 1.0))
    assert mesh.volume == pytest.approx(expected, rel=1e-13)
    lengths = np.linalg.norm(np.diff(mesh.vertices[mesh.edges], axis=1)[:, 0], axis=1)
    assert np.allclose(lengths, a, rtol=1e-13)


@pytest.mark.parametrize("subdivisions", [1, 2, 3, 4])
def test_icosphere_volume_is_sum_of_pyramids(subdivisions):
    """Icosphere volume = sum over faces of (1/3) area * distance of the face plane from
    the centre (pyramids, an independent formula), and lies below 4/3 pi r^3 by O(h^2)."""
    r = 2.0
    mesh = sb.icosphere(subdivisions, radius=r)
    n = mesh.face_normals_scaled
    unit = n / np.linalg.norm(n, axis=1, keepdims=True)
    heights = np.einsum("ij,ij->i", mesh.vertices[mesh.faces[:, 0]], unit)
    pyramids = float(np.sum(mesh.face_areas * heights) / 3.0)
    assert mesh.volume == pytest.approx(pyramids, rel=1e-13)
    sphere = 4.0 / 3.0 * np.pi * r**3
    edge = np.max(np.linalg.norm(np.diff(mesh.vertices[mesh.edges], axis=1)[:, 0], axis=1))
    # inscribed polyhedron: 0 < sphere - V <= sphere * 3 * (sagitta / r) with sagitta <= h^2/(2r)
    assert 0 < sphere - mesh.volume <= sphere * 3 * edge**2 / (2 * r**2)


def test_volume_far_from_origin_keeps_precision():
    """Translation invariance: the volume of a unit ball 1e6 m away matches the one at the
    origin to ~1e-9 (a sum about the origin would lose ~12 digits there)."""
    near = sb.icosphere(3).volume
    far = sb.icosphere(3, center=(1e6, -1e6, 1e6)).volume
    assert far == pytest.approx(near, rel=1e-9)


def _seamed_uv_sphere():
    """A UV sphere whose longitude-0 seam vertices are duplicated, as texture seams are."""
    mesh = sb.uv_sphere(6, 12)
    v, f = mesh.vertices.copy(), mesh.faces.copy()
    seam = np.flatnonzero((np.abs(v[:, 2]) < 1e-12) & (v[:, 0] > 1e-9))
    dup = np.arange(len(v), len(v) + len(seam))
    v2 = np.vstack([v, v[seam]])
    # faces on the z < 0 side of the seam use the duplicates
    side = v[f].mean(axis=1)[:, 2] < 0
    sub = f[side]
    for s, d in zip(seam, dup, strict=True):
        sub[sub == s] = d
    f[side] = sub
    return mesh, sb.TriMesh(v2, f), len(seam)


def test_uv_seam_is_welded_so_gas_cannot_leak():
    """Duplicated seam vertices leave the surface open (boundary edges) until welded."""
    original, seamed, seam_count = _seamed_uv_sphere()
    raw = sb.TriMesh(seamed.vertices, seamed.faces)
    # without welding the seam is a slit from pole to pole: seam_count + 1 segments, each
    # a pair of boundary edges
    report = sb.inspect_mesh(raw, weld_tolerance=0.0)
    assert report.boundary_edge_count == 2 * (seam_count + 1)
    with pytest.warns(sb.MeshWarning, match=f"welded {seam_count} duplicate vertices"):
        fixed = sb.validate_mesh(seamed)
    assert fixed.vertex_count == original.vertex_count
    assert fixed.volume == pytest.approx(original.volume, rel=1e-13)


def test_inward_mesh_is_flipped_with_warning():
    """An inward-wound mesh has negative signed volume; it is flipped and warned about."""
    inward = sb.icosphere(1).flipped()
    assert inward.volume < 0
    with pytest.warns(sb.MeshWarning, match="flipped"):
        fixed = sb.validate_mesh(inward)
    assert fixed.volume == pytest.approx(-inward.volume)


def test_open_mesh_is_refused_with_edge_count():
    """Removing one triangle opens 3 boundary edges."""
    m = sb.icosphere(1)
    with pytest.raises(sb.MeshError, match="open: 3 boundary edges"):
        sb.validate_mesh(sb.TriMesh(m.vertices, m.faces[1:]))


def test_nonmanifold_edge_is_refused():
    """A fin: an extra triangle on an existing edge makes that edge shared by 3 faces."""
    m = sb.icosphere(1)
    a, b, _ = m.faces[0]
    v = np.vstack([m.vertices, [[5.0, 5.0, 5.0]]])
    f = np.vstack([m.faces, [[a, b, len(v) - 1]]])
    with pytest.raises(sb.MeshError, match="non-manifold: 1 edges"):
        sb.validate_mesh(sb.TriMesh(v, f))


def test_inconsistent_winding_is_refused():
    """Flipping one triangle of a closed mesh makes its 3 edges run the same way twice."""
    m = sb.icosphere(1)
    f = m.faces.copy()
    f[0] = f[0, ::-1]
    with pytest.raises(sb.MeshError, match="inconsistent winding: 3 edges"):
        sb.validate_mesh(sb.TriMesh(m.vertices, f))


def test_degenerate_triangles_are_refused():
    """A vertex moved onto the line through two others leaves zero-area triangles."""
    m = sb.box()
    v = m.vertices.copy()
    tri = m.faces[0]
    v[tri[2]] = 0.5 * (v[tri[0]] + v[tri[1]])  # collinear with its neighbours in face 0
    with pytest.raises(sb.MeshError, match=r"degenerate: \d+ triangles"):
        sb.validate_mesh(sb.TriMesh(v, m.faces))


def test_two_shells_are_refused():
    """Two disjoint balls in one mesh must be two bodies."""
    a, b = sb.icosphere(1), sb.icosphere(1, center=(3, 0, 0))
    both = sb.TriMesh(
        np.vstack([a.vertices, b.vertices]), np.vstack([a.faces, b.faces + a.vertex_count])
    )
    with pytest.raises(sb.MeshError, match="2 separate shells"):
        sb.validate_mesh(both)


def test_pinched_vertex_is_refused():
    """Two tetrahedra sharing one vertex: edges are manifold but the vertex is not."""
    tet_v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    tet_f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    v = np.vstack([tet_v, -tet_v[1:]])
    f2 = np.where(tet_f == 0, 0, tet_f + 3)[:, ::-1]  # mirrored copy, shares vertex 0
    with pytest.raises(sb.MeshError, match="1 vertices where separate"):
        sb.validate_mesh(sb.TriMesh(v, np.vstack([tet_f, f2])))


def test_nan_vertices_are_refused():
    """NaN coordinates are rejected when the mesh is made."""
    v = sb.icosphere(0).vertices.copy()
    v[3, 1] = np.nan
    with pytest.raises(sb.MeshError, match="1 of 12 vertices have NaN"):
        sb.TriMesh(v, sb.icosphere(0).faces)


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl", ".off", ".glb"])
def test_file_round_trip(tmp_path, suffix):
    """Write and load each format: same volume and vertex count after welding."""
    mesh = sb.icosphere(2, radius=0.5, center=(1, 2, 3))
    path = sb.save_mesh(mesh, tmp_path / f"ball{suffix}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sb.MeshWarning)  # STL stores triangle soup
        loaded = sb.load_mesh(path)
    assert loaded.vertex_count == mesh.vertex_count
    # files store float32 or 8 decimals: coordinates (|x| <= 3.5) move by <= 3.5 * 6e-8,
    # and V of a ball of radius 0.5 moves by <= 3 dx / r relative = 1.3e-6
    assert loaded.volume == pytest.approx(mesh.volume, rel=1.3e-6)

    # STL keeps no vertex order (triangle soup welded back), so compare sorted positions
    def rows(v):
        return v[np.lexsort(np.round(v, 5).T)]

    assert np.allclose(rows(loaded.vertices), rows(mesh.vertices), atol=3.5 * 6e-8)


def test_spot_cow_loads_welded():
    """Keenan Crane's Spot (tests/data): 3,225 stored vertices weld to 2,930; V ~ 0.718."""
    from pathlib import Path

    path = Path(__file__).parent / "data" / "spot_triangulated.obj"
    with pytest.warns(sb.MeshWarning, match="welded 295"):
        spot = sb.load_mesh(path)
    assert (spot.vertex_count, spot.face_count) == (2930, 5856)
    assert spot.volume == pytest.approx(0.718, abs=5e-4)
    assert spot.vertex_count - len(spot.edges) + spot.face_count == 2


def test_load_errors_name_the_file(tmp_path):
    """Missing files, unknown formats and open meshes give one clear MeshError."""
    with pytest.raises(sb.MeshError, match="no such file"):
        sb.load_mesh(tmp_path / "missing.obj")
    (tmp_path / "x.xyz").write_text("1 2 3\n")
    with pytest.raises(sb.MeshError, match="unsupported mesh format"):
        sb.load_mesh(tmp_path / "x.xyz")
    m = sb.icosphere(1)
    path = sb.save_mesh(sb.TriMesh(m.vertices, m.faces[2:]), tmp_path / "open.obj")
    with pytest.raises(sb.MeshError, match=r"open\.obj cannot hold gas: open"):
        sb.load_mesh(path)


def test_bending_pairs_one_per_edge():
    """On a closed triangle mesh every edge has two adjacent faces, so one bending pair."""
    m = sb.icosphere(2)
    pairs = bending_pairs(m.faces)
    assert len(pairs) == len(m.edges)
    # the opposite vertices are never adjacent on an icosphere of level >= 1
    keys = m.edges[:, 0] * 1000 + m.edges[:, 1]
    assert not np.any(np.isin(pairs[:, 0] * 1000 + pairs[:, 1], keys))


@pytest.mark.parametrize(
    ("shape", "low", "high"),
    [
        ((0, 2), 0, 5),
        ((1, 3), -4, 4),
        ((400, 2), 0, 9),
        ((500, 3), -7, 7),
        ((300, 3), -(2**40), 2**40),
    ],
)
def test_unique_rows_equals_numpy_unique(shape, low, high):
    """Reference: np.unique(axis=0), whose outputs unique_rows reproduces by a faster sort;
    the last case's key would overflow 64 bits and takes the lexsort path. Seeded rows,
    drawn from a small range so that rows repeat."""
    rows = np.random.default_rng(7).integers(low, high, size=shape)
    want = np.unique(rows, axis=0, return_index=True, return_inverse=True, return_counts=True)
    got = unique_rows(rows, return_index=True, return_inverse=True, return_counts=True)
    for w, g in zip(want, got, strict=True):
        np.testing.assert_array_equal(g, w.reshape(g.shape))
    np.testing.assert_array_equal(unique_rows(rows), want[0])
