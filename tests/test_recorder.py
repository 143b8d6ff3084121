"""``softbody.Recorder``: capturing a model built in Python and saving it (issue 29, item 1).

Every file written is read back with an independent reader (ffmpeg's packet list, Pillow,
the USD library, plain OBJ parsing, trimesh) and compared with the simulation it came
from: frame counts and times, the rate the file plays at, positions, and the table's
volumes, pressures, centres of mass and energies against softbody's own diagnostics.
"""

from __future__ import annotations

import base64
import io
import re
import subprocess
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import softbody as sb

FPS = 30


def two_balls() -> sb.Model:
    """Two small balls (42 particles each, different masses and gas) over a ground plane."""
    builder = sb.ModelBuilder()
    for k, (mass, nrt) in enumerate([(1.0, 300.0), (0.5, 150.0)]):
        builder.add_soft_body(
            sb.icosphere(1, radius=0.3, center=(0.8 * k, 0.5 + 0.2 * k, 0.0)),
            mass=mass,
            stiffness=400.0,
            damping=0.5,
            gas=sb.Gas.isothermal(nrt),
        )
    builder.add_collider(sb.ColliderPlane())
    return builder.finalize()


@pytest.fixture(scope="module")
def model() -> sb.Model:
    return two_balls()


def simulator(model: sb.Model) -> sb.Simulator:
    return sb.Simulator(model, integrator="velocity_verlet", dt=1.0 / 1200)


@pytest.fixture(scope="module")
def recorded(model):
    """One second recorded at 30 fps through ``advance(record=)`` (31 frames), with the
    states of a plain loop advancing 1/30 s at a time for comparison."""
    rec = sb.Recorder(model, fps=FPS, width=160, height=120, body_names=["big", "small"])
    state = model.state()
    simulator(model).advance(state, 1.0, record=rec)
    plain, sim = model.state(), simulator(model)
    reference = [plain.copy()]
    for _ in range(FPS):
        sim.advance(plain, 1.0 / FPS)
        reference.append(plain.copy())
    yield rec, state, reference
    rec.close()


def test_advance_captures_a_frame_every_period(recorded):
    """advance(state, 1 s, record=) at 30 fps captures duration * fps + 1 = 31 frames at
    t = k / 30, ends exactly 1 s later, and frame k holds the positions a plain loop of
    1/30 s advances reaches (the same steps)."""
    rec, state, reference = recorded
    assert rec.frame_count == 31
    np.testing.assert_allclose(rec.times, np.arange(31) / FPS, rtol=0, atol=1e-12)
    assert state.time == pytest.approx(1.0, abs=1e-12)
    for k in (0, 1, 15, 30):
        np.testing.assert_allclose(rec.positions[k], reference[k].particle_q, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(rec.positions[-1], state.particle_q)


def test_frames_continue_across_calls_without_repeats(model):
    """Calls whose lengths are not whole frames keep one grid of frame times, k / fps from
    the first frame: 0.1 s, then 0.05 s, then 0.05 s capture at k = 0..3, then 4, then
    5 and 6 (no frame repeated at a joint, none skipped)."""
    rec = sb.Recorder(model, fps=FPS)
    sim, state = simulator(model), model.state()
    counts = []
    for duration in (0.1, 0.05, 0.05):
        sim.advance(state, duration, record=rec)
        counts.append(rec.frame_count)
    assert counts == [4, 5, 7]
    np.testing.assert_allclose(rec.times, np.arange(7) / FPS, atol=1e-12)
    assert state.time == pytest.approx(0.2, abs=1e-12)
    # a state that starts over (time before the last frame) begins a new stretch
    sim.advance(model.state(), 1.0 / FPS, record=rec)
    np.testing.assert_allclose(rec.times[7:], [0.0, 1.0 / FPS], atol=1e-12)
    rec.close()


def test_max_frames_is_refused_before_simulating(model):
    """A recorded advance that would pass max_frames raises ValueError before any step:
    the state and the recorder are unchanged."""
    rec = sb.Recorder(model, fps=FPS, max_frames=10)
    state = model.state()
    with pytest.raises(ValueError, match="max_frames=10"):
        simulator(model).advance(state, 1.0, record=rec)
    assert state.time == 0.0 and state.step_count == 0 and rec.frame_count == 0
    rec.close()


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"fps": 0}, "fps"),
        ({"fps": -30}, "fps"),
        ({"fps": float("nan")}, "fps"),
        ({"fps": float("inf")}, "fps"),
        ({"fps": True}, "fps"),
        ({"fps": "30"}, "fps"),
        ({"camera": (0, 0, 1)}, "camera"),
        ({"camera": ((0, 0), (0, 0, 1))}, "camera eye"),
        ({"camera": ((0, 1, 5), (0, float("nan"), 0))}, "camera target"),
        ({"camera": ((1, 2, 3), (1, 2, 3))}, "same point"),
        ({"width": 8}, "width"),
        ({"height": 10_000}, "height"),
        ({"style": "shiny"}, "style"),
        ({"body_names": ["one"]}, "body_names"),
        ({"max_frames": 0}, "max_frames"),
    ],
)
def test_bad_settings_are_refused_by_name(model, kwargs, word):
    """Each invalid setting raises ValueError naming it (fps > 0 and finite, a camera of
    two distinct finite 3-points, sizes 16..4096, a known style, one name per body)."""
    with pytest.raises(ValueError, match=word):
        sb.Recorder(model, **kwargs)


def test_record_must_be_a_recorder(model):
    """advance(record=) with an object lacking the recorder's methods is a TypeError
    before any step."""
    state = model.state()
    with pytest.raises(TypeError, match="Recorder"):
        simulator(model).advance(state, 0.1, record=object())
    assert state.step_count == 0


def packet_times(path: Path) -> tuple[Fraction, list[int]]:
    """(time base [s], sorted presentation times in time-base units) of the video's
    packets, as ffmpeg lists them without decoding."""
    import imageio_ffmpeg

    out = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(path), "-map", "0:v",
         "-c", "copy", "-f", "framecrc", "-"],
        capture_output=True, text=True, check=True,
    ).stdout  # fmt: skip
    num, den = re.search(r"#tb 0: (\d+)/(\d+)", out).groups()
    pts = sorted(int(line.split(",")[2]) for line in out.splitlines() if line.startswith("0,"))
    return Fraction(int(num), int(den)), pts


def test_mp4_has_every_frame_at_exactly_fps(recorded, tmp_path):
    """The MP4 holds one video frame per captured frame, 160 x 120, packets exactly
    1/30 s apart (from the container's time stamps), and its frames show what
    Recorder.render draws for the same frame (mean difference under 4/255 after H.264)."""
    import imageio_ffmpeg

    rec, _, _ = recorded
    path = rec.save(tmp_path / "clip.mp4")
    base, pts = packet_times(path)
    assert len(pts) == rec.frame_count
    steps = set(np.diff(pts).tolist())
    assert len(steps) == 1 and base * steps.pop() == Fraction(1, FPS)
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    assert meta["size"] == (160, 120)
    frames = [np.frombuffer(f, np.uint8).reshape(120, 160, 3) for f in reader]
    assert len(frames) == rec.frame_count
    for k in (0, 20):
        diff = np.abs(frames[k].astype(float) - rec.render(k).astype(float)).mean()
        assert diff < 4.0, k
    assert np.abs(frames[0].astype(float) - frames[20].astype(float)).mean() > 1.0


def test_rendered_frame_shows_both_bodies(recorded):
    """A rendered frame is (height, width, 3) uint8 and holds pixels near each body's
    colour (Tableau blue and orange: both balls are in the default framing)."""
    from softbody.render.frame import PALETTE, hex_rgb

    rec, _, _ = recorded
    image = rec.render(0).astype(float)
    assert image.shape == (120, 160, 3)
    for color in PALETTE[:2]:
        rgb = 255 * hex_rgb(color)
        # shaded between 0.32 and 1.0 of the colour: the hue is kept, so compare
        # directions of the RGB vectors
        unit = image / np.maximum(np.linalg.norm(image, axis=2, keepdims=True), 1e-9)
        near = (unit @ (rgb / np.linalg.norm(rgb))) > 0.995
        assert near.sum() > 50, color


def test_gif_frames_and_delays(recorded, tmp_path):
    """The GIF holds every frame; its delays are whole hundredths of a second that add up
    to frame_count / fps (3, 3, 4 hundredths at 30 fps), and it loops."""
    from PIL import Image

    rec, _, _ = recorded
    path = rec.save(tmp_path / "clip.gif")
    with Image.open(path) as gif:
        assert gif.n_frames == rec.frame_count and gif.size == (160, 120)
        delays = []
        for k in range(gif.n_frames):
            gif.seek(k)
            delays.append(gif.info["duration"])
        assert gif.info.get("loop") == 0
    assert set(delays) <= {30, 40}
    assert sum(delays) == pytest.approx(1000 * rec.frame_count / FPS, abs=10)


def test_usd_time_codes_and_points(recorded, model, tmp_path):
    """The USD point cache has fps time codes per second, one time sample per frame
    (codes 0..F-1), one mesh per body named after it, and at code k the points of frame
    k (float32) and the body's triangles."""
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom

    rec, _, _ = recorded
    path = rec.save(tmp_path / "clip.usdc")
    stage = Usd.Stage.Open(str(path))
    assert stage.GetTimeCodesPerSecond() == FPS
    assert stage.GetStartTimeCode() == 0 and stage.GetEndTimeCode() == rec.frame_count - 1
    for b, name in enumerate(["big", "small"]):
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/softbody/{name}"))
        points = mesh.GetPointsAttr()
        assert points.GetTimeSamples() == list(range(rec.frame_count))
        p0, p1 = model.body_particle_range[b]
        for k in (0, 17, rec.frame_count - 1):
            got = np.asarray(points.Get(k))
            np.testing.assert_allclose(got, rec.positions[k][p0:p1], rtol=1e-7, atol=1e-7)
        t0, t1 = model.body_tri_range[b]
        faces = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
        np.testing.assert_array_equal(faces, model.tri_indices[t0:t1] - p0)


def obj_vertices(path: Path) -> np.ndarray:
    return np.array(
        [[float(x) for x in line.split()[1:]] for line in path.read_text().splitlines()
         if line.startswith("v ")]
    )  # fmt: skip


def test_obj_and_ply_sequences(recorded, tmp_path):
    """A folder path writes frame_00000.obj... (one file per frame) whose vertices, in
    particle order, are the frame's positions (9 significant digits); the PLY sequence
    reads back with trimesh to the same positions and the model's triangles."""
    import trimesh

    rec, _, _ = recorded
    folder = rec.save(tmp_path / "frames")
    files = sorted(folder.iterdir())
    assert [f.name for f in files] == [f"frame_{k:05d}.obj" for k in range(rec.frame_count)]
    for k in (0, 9, rec.frame_count - 1):
        np.testing.assert_allclose(obj_vertices(files[k]), rec.positions[k], rtol=1e-8, atol=1e-9)
    ply = rec.save(tmp_path / "plys", mesh_format="ply")
    mesh = trimesh.load(ply / "frame_00012.ply", process=False)
    np.testing.assert_allclose(mesh.vertices, rec.positions[12], rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(mesh.faces, rec.model.tri_indices)


def test_dataframe_matches_the_diagnostics(recorded, model):
    """The table has one row per frame and body; at the last frame (the simulated state
    itself) each body's volume, pressure and energies equal softbody's diagnostics, and
    the centre of mass equals the mass-weighted mean of its particles."""
    pytest.importorskip("pandas")
    rec, state, _ = recorded
    df = rec.dataframe()
    assert len(df) == rec.frame_count * model.body_count
    assert list(df["name"][:2]) == ["big", "small"]
    last = df[df["frame"] == rec.frame_count - 1].set_index("body")
    assert last["time_s"].iloc[0] == pytest.approx(state.time)
    np.testing.assert_array_equal(last["volume_m3"], sb.body_volume(model, state))
    np.testing.assert_array_equal(last["pressure_Pa"], sb.body_pressure(model, state))
    e = sb.energies(model, state)
    np.testing.assert_array_equal(last["kinetic_J"], e.body_kinetic)
    np.testing.assert_array_equal(last["gas_J"], e.body_gas)
    total = e.body_kinetic + e.body_gravitational + e.body_spring + e.body_gas
    np.testing.assert_allclose(last["energy_J"], total, rtol=1e-12)
    m, q = model.particle_mass, state.particle_q
    for b, (p0, p1) in enumerate(model.body_particle_range):
        expected = np.average(q[p0:p1], axis=0, weights=m[p0:p1])
        got = last.loc[b, ["com_x_m", "com_y_m", "com_z_m"]].to_numpy(float)
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)
    # frame 0 is the model's initial state
    first = df[df["frame"] == 0]["volume_m3"].to_numpy()
    np.testing.assert_allclose(first, model.body_rest_volume, rtol=1e-12)


def test_dataframe_pressure_is_the_applied_one(model):
    """With a Control setting body 0's nRT, advance(control, record=) captures the
    pressure that control applies (nRT / V at the frame), not the model's."""
    pytest.importorskip("pandas")
    control = model.control()
    control.body_gas_nrt[0] = 3 * model.body_gas_value[0]
    rec = sb.Recorder(model, fps=FPS)
    state = model.state()
    simulator(model).advance(state, 0.1, control, record=rec)
    df = rec.dataframe()
    big = df[df["body"] == 0]
    np.testing.assert_allclose(
        big["pressure_Pa"], 3 * model.body_gas_value[0] / big["volume_m3"], rtol=1e-12
    )
    rec.close()


def test_dataframe_without_pandas_says_what_to_install(recorded, monkeypatch):
    """Without pandas, dataframe() raises ImportError naming pandas and how to get it."""
    import builtins

    real = builtins.__import__

    def no_pandas(name, *args, **kwargs):
        if name == "pandas" or name.startswith("pandas."):
            raise ImportError("No module named 'pandas'")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_pandas)
    with pytest.raises(ImportError, match="pip install pandas"):
        recorded[0].dataframe()


def test_frames_stream_to_a_file_and_close_removes_it(model):
    """Each capture appends the frame to the recorder's temporary file (8 (6 N + 12 C +
    2 B + V) bytes a frame: positions, velocities, collider poses, each body's gas amount
    and temperature, each vent's latch) instead of a list in memory;
    positions are read back through a memory map; close() deletes the file and later use
    is refused."""
    rec = sb.Recorder(model, fps=FPS)
    state = model.state()
    for _ in range(5):
        rec.capture(state)
    frames = rec._dir / "frames.f64"
    rec._frames.flush()
    row = 6 * model.particle_count + 12 * model.collider_count + 2 * model.body_count
    row += len(model.vent_body)
    assert frames.stat().st_size == 5 * 8 * row
    assert isinstance(rec.positions.base, np.memmap) or isinstance(rec.positions, np.memmap)
    rec.close()
    assert not rec._dir.exists()
    with pytest.raises(RuntimeError, match="closed"):
        rec.capture(state)


def test_save_to_a_missing_folder_writes_nothing(recorded, tmp_path):
    """Saving into a folder that does not exist raises FileNotFoundError naming it and
    creates nothing."""
    rec, _, _ = recorded
    with pytest.raises(FileNotFoundError, match="missing"):
        rec.save(tmp_path / "missing" / "clip.mp4")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["clip.mp4", "frames"])
def test_failed_save_leaves_no_partial_file(recorded, tmp_path, monkeypatch, name):
    """A save that fails part way (an error while writing the third frame) leaves neither
    the target nor any temporary file, and an existing file it was to replace keeps its
    content."""
    from softbody.io import sequence
    from softbody.render import video

    calls = {"n": 0}

    def failing(original):
        def wrapper(*args, **kwargs):
            calls["n"] += 1
            if calls["n"] == 3:
                raise OSError("disk full (simulated)")
            return original(*args, **kwargs)

        return wrapper

    monkeypatch.setattr(video.VideoWriter, "append", failing(video.VideoWriter.append))
    monkeypatch.setattr(sequence, "write_mesh_frame", failing(sequence.write_mesh_frame))
    rec, _, _ = recorded
    with pytest.raises(OSError, match="simulated"):
        rec.save(tmp_path / name)
    assert list(tmp_path.iterdir()) == []
    old = tmp_path / "old.mp4"
    old.write_bytes(b"the user's video")
    calls["n"] = 0
    with pytest.raises(OSError, match="simulated"):
        rec.save(old, overwrite=True)
    assert old.read_bytes() == b"the user's video"
    assert list(tmp_path.iterdir()) == [old]


def test_existing_files_are_replaced_only_when_asked(recorded, tmp_path):
    """An existing file is refused without overwrite=True (FileExistsError, content kept)
    and replaced with it; a sequence never replaces a folder holding other files."""
    rec, _, _ = recorded
    target = tmp_path / "clip.gif"
    target.write_bytes(b"keep")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        rec.save(target)
    assert target.read_bytes() == b"keep"
    rec.save(target, overwrite=True)
    assert target.read_bytes()[:6] == b"GIF89a"
    (tmp_path / "clip.mp4").mkdir()  # a folder named like a video is not replaced
    with pytest.raises(IsADirectoryError, match="folder"):
        rec.save(tmp_path / "clip.mp4", overwrite=True)
    (tmp_path / "clip.mp4").rmdir()
    folder = tmp_path / "frames"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="notes.txt"):
        rec.save(folder, overwrite=True)
    assert [p.name for p in folder.iterdir()] == ["notes.txt"]
    (folder / "notes.txt").unlink()
    rec.save(folder)
    first = sorted(p.name for p in folder.iterdir())
    rec.save(folder, overwrite=True)  # a previous sequence: replaced
    assert sorted(p.name for p in folder.iterdir()) == first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.gif", "frames"]


def test_save_refuses_unknown_suffix_and_empty_recording(model, tmp_path):
    """An unknown suffix and a recorder without frames are ValueErrors; nothing is
    written."""
    rec = sb.Recorder(model)
    with pytest.raises(ValueError, match="no frame"):
        rec.save(tmp_path / "clip.mp4")
    rec.capture(model.state())
    with pytest.raises(ValueError, match=r"\.mp4"):
        rec.save(tmp_path / "clip.avi")
    assert list(tmp_path.iterdir()) == []
    rec.close()


def test_notebook_display_is_a_bounded_inline_gif(model):
    """_repr_html_ embeds a looping GIF of the clip: at most 100 frames (every 3rd of 250)
    at most 320 pixels wide."""
    from PIL import Image

    rec = sb.Recorder(model, fps=FPS)
    state = model.state()
    for k in range(250):
        state.particle_q[:, 0] = model.particle_q[:, 0] + 0.004 * k  # slide right: no two
        state.time = k / FPS  # frames alike (a GIF merges equal frames)
        rec.capture(state)
    html = rec._repr_html_()
    data = re.search(r'src="data:image/gif;base64,([^"]+)"', html).group(1)
    with Image.open(io.BytesIO(base64.b64decode(data))) as gif:
        assert gif.n_frames == 84 and gif.size == (320, 240)
    assert "250 frames" in html
    rec.close()
    assert "closed" in rec._repr_html_()


def test_engine_does_not_import_the_application_layer():
    """Layering: ``Simulator.advance(record=)`` takes the recorder by its methods alone;
    no engine module (sim, solvers, collision, mesh, reference, diagnostics, ...) imports
    the application layer (render, viewer, io, run, scenes, sweep, cli), at the top or
    inside a function."""
    import ast

    src = Path(sb.__file__).parent
    app = ("render", "viewer", "io", "run", "scenes", "sweep", "cli")
    engine = ["sim", "solvers", "collision", "mesh", "reference"]
    files = [f for d in engine for f in (src / d).rglob("*.py")]
    files += [src / f"{m}.py" for m in ("diagnostics", "stability", "gas", "volume", "core",
                                         "integrators", "errors", "limits")]  # fmt: skip
    bad = []
    for path in files:
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            for name in names:
                parts = name.split(".")
                if parts[0] == "softbody" and len(parts) > 1 and parts[1] in app:
                    bad.append(f"{path.relative_to(src)}: {name}")
    assert not bad, bad
