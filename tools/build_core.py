"""Build the compiled core (softbody._core) in place, for development and tests.

    python tools/build_core.py                  # release build into src/softbody/
    python tools/build_core.py --sanitize DIR   # ASan + UBSan build into DIR/softbody/
    python tools/build_core.py --cxx clang++ --package DIR   # a whole package in DIR/softbody/
    python tools/build_core.py --no-simd --package DIR       # the scalar kernels only

``pip install -e .`` builds the same module through scikit-build-core; this script runs
CMake directly so that a checkout (or a worktree) can be tested with ``PYTHONPATH=src``.
``--package DIR`` copies the Python sources beside the module, so that another compiler's
or option's build is tested without touching ``src/``: ``PYTHONPATH=DIR python -S ...``
(with the environment's site-packages on PYTHONPATH too; ``-S`` keeps an editable
install's import hook from handing over the checkout's package instead).
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


def build(
    build_dir: Path,
    out_dir: Path,
    *,
    sanitize: bool = False,
    simd: bool = True,
    cxx: str | None = None,
    jobs: int = 2,
) -> Path:
    """Configure and build with CMake; copy the module into ``out_dir``; return its path.

    ``simd=False`` builds the scalar kernels only (``-DSOFTBODY_SIMD=OFF``); ``cxx`` names
    the C++ compiler (else CMake's choice: ``$CXX``, then ``c++``)."""
    cmake = _tool("cmake")
    args = [
        cmake, "-S", str(ROOT), "-B", str(build_dir), "-G", "Ninja",
        f"-DCMAKE_MAKE_PROGRAM={_tool('ninja')}",
        f"-DPython_EXECUTABLE={sys.executable}",
        "-DCMAKE_BUILD_TYPE=" + ("RelWithDebInfo" if sanitize else "Release"),
        f"-DSOFTBODY_SANITIZE={'ON' if sanitize else 'OFF'}",
        f"-DSOFTBODY_SIMD={'ON' if simd else 'OFF'}",
    ]  # fmt: skip
    if cxx is not None:
        args.append(f"-DCMAKE_CXX_COMPILER={cxx}")
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL)
    subprocess.run([cmake, "--build", str(build_dir), "-j", str(jobs)], check=True)
    suffix = sysconfig.get_config_var("EXT_SUFFIX")
    built = build_dir / f"_core{suffix}"
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / built.name
    tmp = target.with_name(target.name + ".tmp")
    shutil.copy2(built, tmp)
    tmp.replace(target)
    # the generated declaration of the model's core fields (core/fields.hpp), beside sim/
    fields = out_dir / "sim" / "_model_fields.py"
    fields.parent.mkdir(parents=True, exist_ok=True)
    tmp = fields.with_name(fields.name + ".tmp")
    shutil.copy2(build_dir / "_model_fields.py", tmp)
    tmp.replace(fields)
    return target


def package(folder: Path, **options) -> Path:
    """Build the module into ``folder/build`` and put it beside a copy of the Python sources
    in ``folder/softbody`` (which must not exist yet); return the module's path."""
    target = folder / "softbody"
    if target.exists():
        raise FileExistsError(f"{target} already exists; name a new folder")
    source = ROOT / "src" / "softbody"
    shutil.copytree(source, target, ignore=shutil.ignore_patterns("__pycache__", "_core*"))
    return build(folder / "build", target, **options)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sanitize", metavar="DIR", help="ASan/UBSan build into DIR/softbody")
    parser.add_argument(
        "--package",
        metavar="DIR",
        help="build into DIR/build and copy the package with it to DIR/softbody",
    )
    parser.add_argument("--cxx", metavar="COMPILER", help="the C++ compiler, e.g. clang++")
    parser.add_argument("--no-simd", action="store_true",
                        help="the scalar kernels only (-DSOFTBODY_SIMD=OFF)")  # fmt: skip
    args = parser.parse_args()
    options = {"simd": not args.no_simd, "cxx": args.cxx}
    if args.sanitize and args.package:
        parser.error("--sanitize and --package name different folders; give one")
    if args.sanitize:
        out = Path(args.sanitize)
        print(build(out / "build", out / "softbody", sanitize=True, **options))
    elif args.package:
        try:
            print(package(Path(args.package), **options))
        except FileExistsError as error:
            parser.error(str(error))
    elif args.cxx or args.no_simd:
        parser.error("--cxx and --no-simd build into a folder of their own: add --package DIR")
    else:
        print(build(ROOT / "build" / "dev", ROOT / "src" / "softbody"))


if __name__ == "__main__":
    main()
