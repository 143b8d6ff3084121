"""The helpers of the race against Jolt Physics (``benchmarks/jolt_peer.py`` and the checks
it shares with its child script, ``benchmarks/peers/drop_check.py``). Jolt itself is not
run here: it needs its own Python >= 3.12 environment."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import softbody as sb

sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))

import jolt_peer
from peers import drop_check

DROP_ENERGY = 9.81


def _drop(rebound: float, frames: int = 121) -> np.ndarray:
    """Centre-of-mass heights [m] of a ball falling from 2 m to 1 m (a parabola) and
    rising ``rebound`` metres after its lowest point, then falling back."""
    t = np.linspace(0.0, 1.0, frames)
    fall = 2.0 - 1.0 * (t / 0.45) ** 2
    rise = 1.0 + rebound * (1.0 - ((t - 0.75) / 0.3) ** 2)
    return np.where(t <= 0.45, fall, rise)


def test_rebound_is_the_rise_after_the_lowest_point():
    """The rebound is the highest height after the lowest frame minus the lowest (a
    parabola rising 1.1 m above its bottom at t = 0.75 s), not the drop's height range."""
    heights = _drop(1.1)
    assert drop_check.rebound(heights) == pytest.approx(1.1, abs=1e-9)
    # the start (2 m) comes before the lowest point and is not counted
    assert drop_check.rebound(_drop(0.3)) == pytest.approx(0.3, abs=1e-9)


def test_drop_verdict_checks_volume_rebound_and_resting_energy():
    """A drop is valid when every frame's volume lies in (0.7, 1.5) of the start, the
    centre of mass rises more than 5 cm after its lowest point and the resting internal
    kinetic energy is below 5% of m g h; ``ok`` further asks a rebound >= 0.9 m."""
    heights = _drop(1.0)
    volumes = np.full(heights.size, 4.0)
    volumes[60] = 4.0 * 1.4
    good = drop_check.drop_verdict(heights, volumes, 0.01, DROP_ENERGY)
    assert good["valid"] and good["ok"]
    assert good["volume_ratio_range"] == pytest.approx([1.0, 1.4])
    assert good["rebound_m"] == pytest.approx(1.0, abs=1e-9)

    swollen = volumes.copy()
    swollen[61] = 4.0 * 1.51
    assert not drop_check.drop_verdict(heights, swollen, 0.01, DROP_ENERGY)["valid"]
    squashed = volumes.copy()
    squashed[61] = 4.0 * 0.69
    assert not drop_check.drop_verdict(heights, squashed, 0.01, DROP_ENERGY)["valid"]
    shaking = drop_check.drop_verdict(heights, volumes, 0.051 * DROP_ENERGY, DROP_ENERGY)
    assert not shaking["valid"]
    damped = drop_check.drop_verdict(_drop(0.6), volumes, 0.01, DROP_ENERGY)
    assert damped["valid"] and not damped["ok"]
    assert not drop_check.drop_verdict(_drop(0.04), volumes, 0.01, DROP_ENERGY)["valid"]


def test_drop_verdict_of_a_drop_that_blew_up():
    """A drop whose heights or volumes are not finite is invalid and reports no rebound or
    volume range (None, so the result stays valid JSON)."""
    heights = _drop(1.0)
    volumes = np.full(heights.size, 4.0)
    volumes[80:] = np.nan
    out = drop_check.drop_verdict(heights, volumes, 0.01, DROP_ENERGY)
    assert out["valid"] is False and out["ok"] is False
    assert out["rebound_m"] is None and out["volume_ratio_range"] == [None, None]
    with pytest.raises(ValueError, match="as many heights as volumes"):
        drop_check.drop_verdict(heights[:-1], volumes, 0.01, DROP_ENERGY)


def test_mesh_volume_and_center_of_mass_match_softbody():
    """The child's volume (divergence theorem) is 1/6 on the unit corner tetrahedron and
    equals softbody's body_volume on the drop's 642-vertex ball; its centre-of-mass height
    equals softbody's."""
    tet = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    assert drop_check.mesh_volume(tet, faces) == pytest.approx(1 / 6)
    model = jolt_peer.ball_drop(3)
    state = model.state()
    mesh = sb.icosphere(3, radius=1.0, center=(0.0, 2.0, 0.0))
    assert drop_check.mesh_volume(state.particle_q, mesh.faces) == pytest.approx(
        sb.body_volume(model, state)[0], rel=1e-12
    )
    assert drop_check.center_of_mass_height(state.particle_q, model.particle_mass) == (
        pytest.approx(sb.body_center_of_mass(model, state)[0, 1], rel=1e-12)
    )


def test_internal_kinetic_energy_ignores_the_centre_of_mass_motion():
    """A rigid translation has no internal kinetic energy; two 1 kg particles moving apart
    at +-1 m/s on top of a common 5 m/s have 1/2 (1 + 1) = 1 J."""
    masses = np.array([1.0, 1.0])
    assert drop_check.internal_kinetic_energy(np.full((2, 3), 5.0), masses) == 0.0
    v = np.array([[6.0, 5, 5], [4.0, 5, 5]])
    assert drop_check.internal_kinetic_energy(v, masses) == pytest.approx(1.0)


def test_peer_python_is_the_first_at_least_3_12():
    """The peer's interpreter is the first candidate reporting Python >= 3.12; with none,
    the error says what culverin needs and how to name one."""
    versions = {"/a": (3, 11), "/b": None, "/c": (3, 12), "/d": (3, 13)}
    assert jolt_peer.find_peer_python(["/a", "/b", "/c", "/d"], versions.get) == "/c"
    with pytest.raises(jolt_peer.PeerError, match=r"Python >= 3\.12.*--peer-python"):
        jolt_peer.find_peer_python(["/a", "/b"], versions.get)
    with pytest.raises(jolt_peer.PeerError, match="pyenv install 3.12"):
        jolt_peer.find_peer_python([], versions.get)


def test_python_version_of_a_real_and_a_missing_interpreter(tmp_path):
    """python_version runs the interpreter: this one reports its own version, a missing
    path gives None instead of an exception."""
    assert jolt_peer.python_version(sys.executable) == tuple(sys.version_info[:2])
    assert jolt_peer.python_version(str(tmp_path / "no-python")) is None


def test_a_failed_peer_install_is_a_one_line_error(tmp_path):
    """Where the peer's environment cannot be made (here: an interpreter that exits 1),
    ensure_peer_venv raises PeerError naming the pinned binding and what to do, and writes
    no marker that would let a later run take the environment as ready."""
    with pytest.raises(jolt_peer.PeerError, match=r"culverin==0\.15\.0.*--peer-venv") as error:
        jolt_peer.ensure_peer_venv("/bin/false", tmp_path / "venv")
    assert "\n" not in str(error.value)
    assert not (tmp_path / "venv" / "softbody-peer.txt").exists()


def test_fewest_valid_stops_at_the_first_ok_count():
    """The search runs the counts fewest first and stops at the first whose drop is ok; a
    count too slow to run (None) ends it, recorded as skipped."""
    calls = []

    def drop(count):
        calls.append(count)
        return {"ok": count >= 40, "rebound_m": 1.0, "volume_ratio_range": [1.0, 1.2],
                "simulated_per_wall_second": 100.0 / count}  # fmt: skip

    entry, tries = jolt_peer.fewest_valid((10, 20, 40, 80), drop)
    assert calls == [10, 20, 40] and entry["ok"]
    assert [t["count"] for t in tries] == [10, 20, 40]
    assert [t["ok"] for t in tries] == [False, False, True]

    entry, tries = jolt_peer.fewest_valid((10, 20, 40), lambda c: drop(c) if c < 20 else None)
    assert entry["ok"] is False and tries[-1] == {
        "count": 20, "ok": None, "skipped": "slower than the budget"
    }  # fmt: skip
    entry, _ = jolt_peer.fewest_valid((10,), lambda c: None)
    assert entry["ok"] is None


def test_speed_ratio_takes_the_fastest_passing_run():
    """softbody / Jolt is the fastest of softbody's runs that pass with the bounce kept
    over Jolt's rate; None where Jolt or every softbody run fails."""
    softbody = {
        "a": {"ok": True, "simulated_per_wall_second": 2.0},
        "b": {"ok": False, "simulated_per_wall_second": 9.0},
        "c": {"ok": True, "simulated_per_wall_second": 3.0},
        "d": {"ok": None, "skipped": "slower than the budget"},
    }
    jolt = {"ok": True, "simulated_per_wall_second": 1.5}
    assert jolt_peer.speed_ratio(softbody, jolt) == pytest.approx(2.0)
    assert jolt_peer.speed_ratio(softbody, {**jolt, "ok": False}) is None
    assert jolt_peer.speed_ratio({"b": softbody["b"]}, jolt) is None


def test_a_peer_without_culverin_is_a_one_line_error(tmp_path):
    """A peer environment that cannot import culverin (this test's own Python) or does not
    exist gives PeerError naming the pin and what to do, not a traceback."""
    with pytest.raises(jolt_peer.PeerError, match=r"cannot import culverin.*culverin==0\.15\.0"):
        jolt_peer.peer_version(Path(sys.executable))
    with pytest.raises(jolt_peer.PeerError, match="cannot run the peer's Python"):
        jolt_peer.peer_version(tmp_path / "venv" / "bin" / "python")


def test_paired_ratios_are_taken_within_each_round():
    """The ratio of round k is the fastest passing softbody run's rate in round k over
    Jolt's in round k (not the best of one over the best of the other); a run not timed in
    a round is left out of it, a round without any passing run dropped."""
    rates = {
        "jolt": [10.0, 4.0, 8.0],
        "a": [5.0, 2.0, 4.0],
        "b": [6.0, 1.0],
        "failing": [100.0, 100.0, 100.0],
    }
    ratios = jolt_peer.paired_ratios(rates, ["a", "b"], "jolt")
    assert ratios == pytest.approx([0.6, 0.5, 0.5])
    assert jolt_peer.paired_ratios(rates, [], "jolt") == []
    assert jolt_peer.paired_ratios(rates, ["a"], "jolt_one_worker") == []
