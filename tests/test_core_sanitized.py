"""The engine core built with AddressSanitizer and UndefinedBehaviorSanitizer
(``tools/build_core.py --sanitize``) running the core's fast tests
(test_core.py, test_core_projective.py, test_core_implicit.py, test_trajectories.py,
test_terms.py).
Reference: the
sanitizers' own checks; a read or write outside an array, a use after free or undefined
behaviour (overflow, misalignment, a bad shift) in the C++ aborts the run with its
report, so this passes only when none fired on any instruction-set path."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import package_copy

ROOT = Path(__file__).resolve().parent.parent
#: the core's test files and the reference trajectories, and among their tests the fast
#: ones (a fresh process per run, or runs on one instruction set only, add nothing here)
CORE_TESTS = ("test_core.py", "test_core_projective.py", "test_core_implicit.py",
              "test_trajectories.py", "test_terms.py")  # fmt: skip
FAST = "not without_compiling"


def _runtime(name: str) -> str | None:
    compiler = shutil.which("g++") or shutil.which("c++")
    if compiler is None:
        return None
    path = subprocess.run(
        [compiler, f"-print-file-name={name}"], capture_output=True, text=True
    ).stdout.strip()
    return path if os.path.isabs(path) and os.path.exists(path) else None


@pytest.mark.skipif(sys.platform != "linux", reason="the sanitizer runtimes are gcc's on Linux")
def test_core_tests_pass_under_address_and_undefined_behaviour_sanitizers(tmp_path):
    """Build the sanitized core, put it beside a copy of the package, and run the core's
    fast tests on every instruction set with the sanitizers' runtimes preloaded."""
    asan, ubsan = _runtime("libasan.so"), _runtime("libubsan.so")
    if asan is None or ubsan is None:
        pytest.skip("no gcc with sanitizer runtimes on this machine")
    build = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "build_core.py"), "--sanitize", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=540,
    )
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    (module,) = (tmp_path / "softbody").glob("_core*")
    env = package_copy(tmp_path / "pkg")
    package = tmp_path / "pkg" / "softbody"
    for old in package.glob("_core*"):
        old.unlink()
    shutil.copy2(module, package / module.name)
    env = {
        **env,
        "PYTHONPATH": env["PYTHONPATH"] + os.pathsep + str(ROOT / "tests"),
        "LD_PRELOAD": f"{asan} {ubsan}",
        "ASAN_OPTIONS": "detect_leaks=0:abort_on_error=1",
        "UBSAN_OPTIONS": "halt_on_error=1:print_stacktrace=1",
    }
    which = subprocess.run(
        [sys.executable, "-S", "-c", "import softbody._core as c; print(c.__file__)"],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert which.returncode == 0, which.stderr[-3000:]
    assert which.stdout.strip() == str(package / module.name)
    command = [sys.executable, "-S", "-m", "pytest", "-q", "-p", "no:cacheprovider"]
    tests = subprocess.run(
        [*command, *(str(ROOT / "tests" / name) for name in CORE_TESTS), "-k", FAST],
        env=env,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=540,
    )
    assert tests.returncode == 0, tests.stdout[-4000:] + tests.stderr[-4000:]
    assert " passed" in tests.stdout and " failed" not in tests.stdout
