"""Build the compiled core (softbody._core) in place, for development and tests.

    python tools/build_core.py                  # release build into src/softbody/
    python tools/build_core.py --sanitize DIR   # ASan + UBSan build into DIR/softbody/

``pip install -e .`` builds the same module through scikit-build-core; this script runs
CMake directly so that a checkout (or a worktree) can be tested with ``PYTHONPATH=src``.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _tool(name: str) -> str:
    """A build tool from this Python's environment (the test extras install cmake and
    ninja there), else from PATH."""
    here = Path(sys.executable).parent / name
    return str(here) if here.is_file() else (shutil.which(name) or name)


def build(build_dir: Path, out_dir: Path, *, sanitize: bool = False, jobs: int = 2) -> Path:
    """Configure and build with CMake; copy the module into ``out_dir``; return its path."""
    cmake = _tool("cmake")
    args = [
        cmake, "-S", str(ROOT), "-B", str(build_dir), "-G", "Ninja",
        f"-DCMAKE_MAKE_PROGRAM={_tool('ninja')}",
        f"-DPython_EXECUTABLE={sys.executable}",
        "-DCMAKE_BUILD_TYPE=" + ("RelWithDebInfo" if sanitize else "Release"),
        f"-DSOFTBODY_SANITIZE={'ON' if sanitize else 'OFF'}",
    ]  # fmt: skip
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL)
    subprocess.run([cmake, "--build", str(build_dir), "-j", str(jobs)], check=True)
    suffix = sysconfig.get_config_var("EXT_SUFFIX")
    built = build_dir / f"_core{suffix}"
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / built.name
    tmp = target.with_name(target.name + ".tmp")
    shutil.copy2(built, tmp)
    tmp.replace(target)
    return target


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sanitize", metavar="DIR", help="ASan/UBSan build into DIR/softbody")
    args = parser.parse_args()
    if args.sanitize:
        out = Path(args.sanitize)
        print(build(out / "build", out / "softbody", sanitize=True))
    else:
        print(build(ROOT / "build" / "dev", ROOT / "src" / "softbody"))


if __name__ == "__main__":
    main()
