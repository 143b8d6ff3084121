"""The memory limit the size guards compare their estimates with."""

from __future__ import annotations

import pytest

from softbody import limits
from softbody.errors import SizeLimitError

GIB = 1024**3


@pytest.fixture
def no_variable(monkeypatch):
    monkeypatch.delenv("SOFTBODY_MEMORY_LIMIT", raising=False)


def cgroup_file(tmp_path, monkeypatch, text: str) -> None:
    """Point the v2 cgroup limit file at one holding ``text`` (no v1 file)."""
    path = tmp_path / "memory.max"
    path.write_text(text + "\n")
    monkeypatch.setattr(limits, "CGROUP_LIMIT_FILES", (str(path), str(tmp_path / "none")))


def test_a_container_limit_below_the_machine_is_what_counts(tmp_path, monkeypatch, no_variable):
    """A job in a 2 GiB container on a larger host may plan half of 2 GiB, not half of
    the host's memory (which the OOM killer would never let it have)."""
    monkeypatch.setattr(limits, "physical_memory", lambda: 24 * GIB)
    cgroup_file(tmp_path, monkeypatch, str(2 * GIB))
    assert limits.memory_limit() == GIB
    with pytest.raises(SizeLimitError, match="container"):
        limits.check_memory("bodies.0.mesh.subdivisions", 1.5 * GIB, "a mesh")


@pytest.mark.parametrize("text", ["max", "9223372036854771712", "garbage", ""])
def test_no_container_limit_leaves_the_machine(tmp_path, monkeypatch, no_variable, text):
    """cgroup v2's "max", v1's huge "no limit" number, or an unreadable value: half of the
    physical memory."""
    monkeypatch.setattr(limits, "physical_memory", lambda: 24 * GIB)
    cgroup_file(tmp_path, monkeypatch, text)
    assert limits.memory_limit() == 12 * GIB


@pytest.mark.parametrize(
    "value,expected", [("8G", 8 * GIB), ("1.5M", int(1.5 * 1024**2)), ("4096", 4096)]
)
def test_the_variable_sets_the_limit(monkeypatch, value, expected):
    """SOFTBODY_MEMORY_LIMIT in bytes or with a K/M/G/T suffix (powers of 1024)."""
    monkeypatch.setenv("SOFTBODY_MEMORY_LIMIT", value)
    assert limits.memory_limit() == expected


@pytest.mark.parametrize("value", ["-1G", "0", "lots", "inf", "1X"])
def test_a_bad_variable_is_a_one_line_error(monkeypatch, value):
    """A limit that is not a positive size is refused by name, not silently ignored."""
    monkeypatch.setenv("SOFTBODY_MEMORY_LIMIT", value)
    with pytest.raises(SizeLimitError, match="^SOFTBODY_MEMORY_LIMIT must be"):
        limits.memory_limit()


def test_reading_the_container_limit_closes_its_file(tmp_path, monkeypatch, no_variable):
    """Issue 29 item 16: ``available_memory`` left the cgroup file open, so every sweep
    row's ``warning`` read ``unclosed file <.../memory.limit_in_bytes>``. Reference: no
    ResourceWarning at all once the file object is collected, checked with warnings as
    errors (a warning raised in a finaliser is reported through ``sys.unraisablehook``,
    which is recorded here too)."""
    import gc
    import sys
    import warnings

    monkeypatch.setattr(limits, "physical_memory", lambda: 24 * GIB)
    cgroup_file(tmp_path, monkeypatch, str(2 * GIB))
    unraisable = []
    monkeypatch.setattr(sys, "unraisablehook", unraisable.append)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("error")
        assert limits.available_memory() == 2 * GIB
        gc.collect()
    assert not caught and not unraisable, [str(w.message) for w in caught] + unraisable
