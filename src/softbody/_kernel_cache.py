"""Where Numba caches the compiled kernels, keyed by a digest of this package's source.

Numba invalidates a cached function only when its own file changes, not when a kernel it
calls from another module does: after editing ``collision/response.py``, the cached
``integrators/loop.simulate_explicit`` would still run the old contact code. Putting the
cache in a folder named after a digest of every kernel source file of the package makes any
change to them start a fresh cache. The files that define the tuples the kernels take
(``Workspace``, ``Partition``, ``ModelData``) count too: after fields were added to
``Workspace`` during development, a run from the old cache folder crashed with a
segmentation fault and a fresh cache did not. Set NUMBA_CACHE_DIR to choose the
location yourself.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path


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


def configure() -> None:
    """Point Numba's cache at a per-source-version folder (before any kernel is defined)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    import numba

    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    folder = base / "softbody" / f"numba-{source_digest()}"
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return  # unwritable home: fall back to Numba's default (next to the sources)
    numba.config.CACHE_DIR = str(folder)
