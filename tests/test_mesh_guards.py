"""Size guards and file errors of the mesh library (issue 19, items 3 and 11).

A Python user asking for an absurd mesh must get a one-line SizeLimitError naming the
argument before anything is allocated, not a MemoryError or the out-of-memory killer;
every error reading a mesh file must name the file.
"""

from __future__ import annotations

import tracemalloc

import pytest

import softbody as sb
from softbody.errors import MeshError, SizeLimitError


def _refused_fast(call, text: str) -> SizeLimitError:
    """Run ``call``; it must raise SizeLimitError mentioning ``text`` having allocated
    under 1 MB (tracemalloc peak), i.e. before building anything."""
    tracemalloc.start()
    try:
        with pytest.raises(SizeLimitError, match=text) as info:
            call()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2**20, f"allocated {peak} bytes before refusing"
    assert "\n" not in str(info.value)
    return info.value


@pytest.mark.parametrize(
    ("call", "text"),
    [
        (lambda: sb.icosphere(1000), r"icosphere\(subdivisions=1000\)"),
        (lambda: sb.icosphere(12), r"icosphere\(subdivisions=12\).*167,772,162 vertices"),
        (lambda: sb.uv_sphere(rings=100000, segments=100000), r"uv_sphere\(rings=100000"),
        (lambda: sb.box(subdivisions=40), r"box\(subdivisions=40\)"),
        (lambda: sb.capsule(rings=10**6, segments=10**6), r"capsule\(rings=1000000"),
        (lambda: sb.cylinder(segments=10**12), r"cylinder\(segments=1000000000000\)"),
        (lambda: sb.rectangle(resolution=(10**6, 10**6)), r"rectangle\(resolution="),
    ],
)
def test_generators_refuse_huge_meshes_before_allocating(call, text):
    """Issue 19 item 3: subdivisions = 1e3 took all memory, 12 and uv_sphere's 1e5 rings
    ended in a MemoryError traceback. Each generator now estimates its vertex count from
    its arguments (10 * 4**s + 2 for the icosphere) and refuses with the argument named,
    having allocated nothing; on the old code these run out of memory or allocate GBs."""
    _refused_fast(call, text)


@pytest.mark.parametrize("bad", [float("inf"), float("nan"), "x"])
def test_generator_counts_refuse_non_integers_with_a_value_error(bad):
    """int(inf) raised OverflowError and int(nan) a bare 'cannot convert' ValueError before:
    the message now names the argument (reference: the one-line error bar of issue 19)."""
    with pytest.raises(ValueError, match="rings must be an integer >= 2"):
        sb.uv_sphere(rings=bad)


def test_monte_carlo_samples_refused_before_allocating():
    """Issue 19 item 3: monte_carlo_samples = 1e12 ended in a MemoryError traceback
    (16 TB of sample lines); now a SizeLimitError naming the key, allocated nothing."""
    builder = sb.ModelBuilder()
    mesh = sb.icosphere(1)
    err = _refused_fast(
        lambda: builder.add_soft_body(
            mesh,
            mass=1.0,
            stiffness=1.0,
            damping=0.0,
            gas=1.0,
            volume_method="monte_carlo",
            monte_carlo_samples=1e12,
        ),
        "monte_carlo_samples=1000000000000",
    )
    assert "1,000,000,000,000 Monte Carlo sample lines" in str(err)
    assert builder.body_count == 0


def test_builder_refuses_a_model_over_the_memory_limit(monkeypatch):
    """The builder checks the whole model's particle count against the limit before
    validating or copying a body (2.5 MB for a 642-vertex ball at 3 kB per particle;
    SOFTBODY_MEMORY_LIMIT=1M). The old builder had no guard and accepted it."""
    mesh = sb.icosphere(3)
    monkeypatch.setenv("SOFTBODY_MEMORY_LIMIT", "1M")
    builder = sb.ModelBuilder()
    with pytest.raises(SizeLimitError, match=r"body 0 mesh: a model of 642 particles"):
        builder.add_soft_body(mesh, mass=1.0, stiffness=1.0, damping=0.0, gas=1.0)


def test_mesh_file_over_the_limit_refused_before_parsing(tmp_path, monkeypatch):
    """Issue 19 item 3: a 2 GB mesh took 4.3 GB before failing. read_mesh now multiplies
    the file size by BYTES_PER_FILE_BYTE (measured) and refuses before trimesh reads it:
    with a 64 kB limit a 9 kB OBJ is refused with the path named, and nothing is parsed
    (a file of text that is not a mesh would otherwise fail differently, in the parser)."""
    path = tmp_path / "big.obj"
    path.write_text("# not parsed\n" * 700)
    monkeypatch.setenv("SOFTBODY_MEMORY_LIMIT", "64K")
    with pytest.raises(SizeLimitError, match=r"big\.obj: reading a 8\.\d+ KiB file"):
        sb.read_mesh(path)


def test_parsed_mesh_over_the_limit_refused_by_its_counts(tmp_path, monkeypatch):
    """After parsing, the vertex and face counts are checked (check_mesh_size) before the
    mesh is copied and validated: a 642-vertex ball as a 20 kB binary PLY passes the file
    check under a 1.5 MB limit (20 bytes per byte: 0.4 MB) but not the count check
    (2.6 MB to build and simulate). The old reader had neither check."""
    path = tmp_path / "ball.ply"
    sb.save_mesh(sb.icosphere(3), path)  # binary PLY, 20 kB: 400 kB to parse
    monkeypatch.setenv("SOFTBODY_MEMORY_LIMIT", "1.5M")
    with pytest.raises(SizeLimitError, match=r"ball\.ply: a mesh of 642 vertices"):
        sb.read_mesh(path)


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n", "NaN"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1e400 0 1\nf 1 2 3\nf 1 2 4\n", "infinite"),
        ("", "empty"),
    ],
)
def test_mesh_file_errors_name_the_file(tmp_path, text, reason):
    """Issue 19 item 11: the NaN-in-mesh error did not name the file (TriMesh's message
    alone). NaN and infinite coordinates and an empty file now start with the path (bad
    indices already did, through trimesh's message)."""
    path = tmp_path / "broken_mesh.obj"
    path.write_text(text)
    with pytest.raises(MeshError, match=reason) as info:
        sb.load_mesh(path)
    assert str(info.value).startswith(str(path))


def test_out_of_memory_while_reading_names_the_file_and_size(tmp_path, monkeypatch):
    """Issue 19 item 11: a MemoryError while reading showed as 'could not read mesh ()'
    (MemoryError has no message). Now it names the file and its size. The MemoryError is
    raised by trimesh's loader, replaced here: a real one needs a machine's memory."""
    import trimesh

    path = tmp_path / "ball.obj"
    sb.save_mesh(sb.icosphere(1), path)

    def out_of_memory(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(trimesh, "load", out_of_memory)
    with pytest.raises(MeshError, match=r"ball\.obj: ran out of memory reading a \d+"):
        sb.read_mesh(path)
