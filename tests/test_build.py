"""The build's choice of kernels (CMakeLists.txt), read from CMake's configure step (about a
second; nothing is compiled). Reference: the build contract in docs/development.md: on an
x86-64 target the scalar, AVX2 and AVX-512 kernels, each without FMA contraction; with
``-DSOFTBODY_SIMD=OFF`` or on a target that is not x86-64 (asked of the compiler, not of the
host) the scalar kernels only, with no x86 flag anywhere. The builds themselves (Clang,
scalar-only, the wheel) are compiled and tested by ``.ci/build-checks``."""

from __future__ import annotations

import platform
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
from build_core import _tool  # noqa: E402

X86_FLAG = re.compile(r"-mavx|-mfma|/arch:")


def _configure(build: Path, *options: str) -> tuple[str, str]:
    """Configure into ``build``; return CMake's output and the generated build.ninja."""
    if shutil.which(_tool("cmake")) is None or shutil.which(_tool("ninja")) is None:
        pytest.skip("cmake and ninja are needed (the test extras install them)")
    done = subprocess.run(
        [_tool("cmake"), "-S", str(ROOT), "-B", str(build), "-G", "Ninja",
         f"-DCMAKE_MAKE_PROGRAM={_tool('ninja')}", f"-DPython_EXECUTABLE={sys.executable}",
         *options],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return done.stdout, (build / "build.ninja").read_text()


def _kernel_flags(ninja: str) -> dict[str, str]:
    """The FLAGS line of each kernel object's compile rule, by target name."""
    flags = {}
    for block in ninja.split("\nbuild ")[1:]:
        target = re.search(r"CMakeFiles/(kernels_\w+)\.dir", block.splitlines()[0])
        found = re.search(r"^\s+FLAGS = (.*)$", block, flags=re.M)
        if target and found:
            flags[target.group(1)] = found.group(1)
    return flags


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="x86-64 host")
def test_x86_build_compiles_every_kernel_variant_without_contraction(tmp_path):
    """On an x86-64 host the scalar, AVX2 and AVX-512 kernels are built, each with
    -ffp-contract=off, and only the SIMD variants get x86 instruction-set flags."""
    out, ninja = _configure(tmp_path / "b")
    flags = _kernel_flags(ninja)
    assert set(flags) == {"kernels_scalar", "kernels_avx2", "kernels_avx512"}, flags
    assert all("-ffp-contract=off" in f for f in flags.values()), flags
    assert not X86_FLAG.search(flags["kernels_scalar"])
    assert "-mavx2" in flags["kernels_avx2"] and "-mavx512f" in flags["kernels_avx512"]
    assert "scalar, AVX2, AVX-512" in out


def test_simd_off_builds_the_scalar_kernels_only(tmp_path):
    """-DSOFTBODY_SIMD=OFF: one kernel object, the scalar one, and no x86 flag in the
    whole build."""
    out, ninja = _configure(tmp_path / "b", "-DSOFTBODY_SIMD=OFF")
    assert set(_kernel_flags(ninja)) == {"kernels_scalar"}
    assert not X86_FLAG.search(ninja)
    assert "scalar only (SOFTBODY_SIMD=OFF)" in out


def test_a_non_x86_target_builds_the_scalar_kernels_only(tmp_path):
    """A target that is not x86-64 (Clang cross-configured for aarch64 on this host, as an
    ARM wheel built on an x86 machine is): the scalar kernels only, no x86 flag, whatever
    the host processor is."""
    if shutil.which("clang++") is None:
        pytest.skip("clang++ is needed to configure for another target")
    out, ninja = _configure(
        tmp_path / "b", "-DCMAKE_CXX_COMPILER=clang++",
        "-DCMAKE_CXX_COMPILER_TARGET=aarch64-linux-gnu",
        "-DCMAKE_TRY_COMPILE_TARGET_TYPE=STATIC_LIBRARY",  # no aarch64 libraries to link
    )  # fmt: skip
    assert set(_kernel_flags(ninja)) == {"kernels_scalar"}
    assert not X86_FLAG.search(ninja)
    assert "scalar only (not an x86-64 target)" in out
