"""Where Numba caches the compiled kernels, and how that cache is written: whole, by one
process.

Numba invalidates a cached function only when its own file changes, not when a kernel it
calls from another module does: after editing ``collision/response.py``, the cached
``integrators/loop.simulate_explicit`` would still run the old contact code. Putting the
cache in a folder named after a digest of every kernel source file of the package makes any
change to them start a fresh cache. The files that define the tuples the kernels take
(``Workspace``, ``Partition``, ``ModelData``) count too: after fields were added to
``Workspace`` during development, a run from the old cache folder crashed with a
segmentation fault and a fresh cache did not.

A cache written piecemeal by several processes crashes too. An explicit run compiled and
cached the shared force kernels; an implicit run in a second process loaded them and
compiled its own time loop against them; a third process that loaded that loop died with a
segmentation fault, and so did every implicit and projective run after it (the class of
Numba issues 4807 and 10128: cached code compiled in different processes against each
other). So the cache for a version of the sources is written by one child process that
compiles every kernel (``softbody._kernel_warmup``) into a temporary folder, under a lock
so that two first runs do not both compile, and the folder is renamed into place only
when that process succeeded. Until then nothing else is cached. Set NUMBA_CACHE_DIR to
choose the location yourself: the cache is then a folder inside it.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: Environment variable a warm-up child reads: the folder it compiles into.
FOLDER_VARIABLE = "SOFTBODY_KERNEL_FOLDER"
#: File the warm-up leaves in the folder; a cache file newer than it was compiled later,
#: by a process that loaded the rest (what the tests check never happens).
COMPLETE = "complete"


def source_digest() -> str:
    """Short SHA-256 of the package's kernel sources: the .py files that use Numba or
    define named tuples (names and contents). Editing the CLI or the viewer keeps the
    cache."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        text = path.read_bytes()
        if b"numba" not in text and b"NamedTuple" not in text:
            continue
        h.update(str(path.relative_to(root)).encode())
        h.update(text)
    return h.hexdigest()[:16]


def cache_folder() -> Path:
    """The kernel cache of this version of the sources: ``numba-<digest>`` inside
    NUMBA_CACHE_DIR, or else inside ``$XDG_CACHE_HOME/softbody`` (``~/.cache/softbody``)."""
    chosen = os.environ.get("NUMBA_CACHE_DIR")
    if chosen:
        base = Path(chosen)
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "softbody"
    return base / f"numba-{source_digest()}"


def configure() -> None:
    """Point Numba's cache at this version's folder (before any kernel is defined),
    compiling every kernel first in a child process when the folder does not exist yet.

    When that fails (an unwritable home, a compiler error), this process compiles what
    it uses and caches it only until it exits."""
    import numba

    warmup_folder = os.environ.get(FOLDER_VARIABLE)
    if warmup_folder:  # this process is the warm-up child: compile into its folder
        numba.config.CACHE_DIR = warmup_folder
        return
    folder = cache_folder()
    if not folder.is_dir():
        try:
            _warm(folder)
        except (OSError, RuntimeError) as exc:
            # no lasting cache then (a piecemeal one is what crashes): this process
            # compiles what it uses into a folder removed when it exits
            print(f"softbody: {exc}; compiling in this process instead", file=sys.stderr)
            scratch = tempfile.mkdtemp(prefix="softbody-kernels-")
            atexit.register(shutil.rmtree, scratch, ignore_errors=True)
            numba.config.CACHE_DIR = scratch
            return
    numba.config.CACHE_DIR = str(folder)


def _warm(folder: Path) -> None:
    """Compile every kernel into ``folder`` in one child process, under a lock."""
    import fcntl

    folder.parent.mkdir(parents=True, exist_ok=True)
    with open(folder.parent / f"{folder.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another first run compiles: wait for it
        if folder.is_dir():
            return
        staging = folder.parent / f"{folder.name}.partial-{os.getpid()}"
        shutil.rmtree(staging, ignore_errors=True)
        print(
            "softbody: compiling the kernels, once per installed version "
            "(about two minutes on a 2-core machine)...",
            file=sys.stderr,
            flush=True,
        )
        start = time.perf_counter()
        env = {**os.environ, FOLDER_VARIABLE: str(staging)}
        try:
            done = subprocess.run(
                [sys.executable, "-m", "softbody._kernel_warmup", str(staging)],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
            )
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
        if done.returncode != 0:
            shutil.rmtree(staging, ignore_errors=True)
            last = (done.stderr.strip().splitlines() or ["no message"])[-1]
            raise RuntimeError(f"compiling the kernels failed ({last})")
        (staging / COMPLETE).write_text(f"{time.time()}\n")  # later files: compiled after
        staging.rename(folder)
        print(
            f"softbody: kernels compiled in {time.perf_counter() - start:.0f} s",
            file=sys.stderr,
            flush=True,
        )
