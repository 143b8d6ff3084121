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
when that process succeeded. It runs before the first kernel does (``ensure_compiled``:
building a model, making a simulator), not at import, so ``softbody --help`` or a
library import never waits for it. Set NUMBA_CACHE_DIR to
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
    define named tuples (names and contents), and where the package is. Editing the CLI
    or the viewer keeps the cache.

    The location counts because Numba files each kernel under its source file's path: a
    second checkout of the same version would find the first one's folder complete but
    none of its own kernels in it, and compile them piecemeal into it, which is what
    crashes. Each installed copy gets its own folder and its own warm-up."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256(str(root).encode())
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


_ready = False


def configure() -> None:
    """Point Numba's cache at this version's folder; call before any kernel is defined
    (Numba fixes each kernel's cache folder when it is decorated). Nothing is compiled
    here: :func:`ensure_compiled` fills the folder before the first kernel runs.

    When the folder cannot be made (an unwritable home), this process compiles what it
    uses into a scratch folder removed when it exits."""
    global _ready
    import numba

    warmup_folder = os.environ.get(FOLDER_VARIABLE)
    if warmup_folder:  # this process is the warm-up child: compile into its folder
        numba.config.CACHE_DIR = warmup_folder
        _ready = True
        return
    folder = cache_folder()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        _use_scratch(numba, f"cannot write the kernel cache ({exc})")
        return
    numba.config.CACHE_DIR = str(folder)


def _use_scratch(numba, reason: str) -> None:
    """No lasting cache (a piecemeal one is what crashes): compile in this process, into
    a folder removed at exit."""
    global _ready
    print(f"softbody: {reason}; compiling in this process instead", file=sys.stderr)
    scratch = tempfile.mkdtemp(prefix="softbody-kernels-")
    atexit.register(shutil.rmtree, scratch, ignore_errors=True)
    numba.config.CACHE_DIR = scratch
    _ready = True


def ensure_compiled() -> None:
    """Make sure the kernel cache is complete before a kernel runs: if it is not, compile
    every kernel in one child process (the module docstring says why) and put its folder
    in place. Called by ``ModelBuilder.finalize`` and ``Simulator``; cheap once done.

    Raises ``RuntimeError`` (one line) when compiling fails, and lets KeyboardInterrupt
    through after stopping the child and removing its folder."""
    global _ready
    if _ready:
        return
    import numba

    if numba.config.DISABLE_JIT:
        _ready = True  # kernels run as Python: nothing to compile
        return

    folder = Path(numba.config.CACHE_DIR)
    if not (folder / COMPLETE).is_file():
        _warm(folder)
    _ready = True


def _warm(folder: Path) -> None:
    """Compile every kernel into a staging folder in one child process, under a lock,
    then swap it in for ``folder`` (which holds at most the empty folders Numba made
    when the kernels were decorated)."""
    import fcntl

    with open(folder.parent / f"{folder.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another first run compiles: wait for it
        if (folder / COMPLETE).is_file():
            return
        # with the lock held no other warm-up of this version runs: what a killed one
        # left behind is garbage
        for stale in folder.parent.glob(f"{folder.name}.partial-*"):
            shutil.rmtree(stale, ignore_errors=True)
        staging = folder.parent / f"{folder.name}.partial-{os.getpid()}"
        print(
            "softbody: compiling the kernels, once per installed version "
            "(about two minutes on a 2-core machine)...",
            file=sys.stderr,
            flush=True,
        )
        start = time.perf_counter()
        env = {**os.environ, FOLDER_VARIABLE: str(staging)}
        child = subprocess.Popen(
            [sys.executable, "-m", "softbody._kernel_warmup", str(staging)],
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,  # a Ctrl-C reaches this process, which stops the child
        )
        try:
            _, errors = child.communicate()
        except BaseException:
            child.kill()
            child.wait()
            shutil.rmtree(staging, ignore_errors=True)
            raise
        if child.returncode != 0:
            shutil.rmtree(staging, ignore_errors=True)
            last = (errors.strip().splitlines() or ["no message"])[-1]
            raise RuntimeError(f"compiling the kernels failed ({last})")
        (staging / COMPLETE).write_text(f"{time.time()}\n")  # later files: compiled after
        old = folder.parent / f"{folder.name}.old-{os.getpid()}"
        if folder.exists():
            folder.rename(old)
        staging.rename(folder)
        shutil.rmtree(old, ignore_errors=True)
        print(
            f"softbody: kernels compiled in {time.perf_counter() - start:.0f} s",
            file=sys.stderr,
            flush=True,
        )
