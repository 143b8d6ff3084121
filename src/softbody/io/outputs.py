"""An output folder that holds exactly one run's files, and never anything else of ours.

A run writes into a temporary folder inside the output folder; :func:`commit` then
moves the files into place. What softbody owns in the folder is what the manifest
``softbody-run.json`` lists: each file's path (relative, ``/``-separated), size and
SHA-256. A file is *ours* only while it is listed and still has that size and hash, so
a user's file, or one of ours the user has since edited, is never overwritten or
deleted; a run that would have to replace one stops with :class:`OutputError` before
moving anything.

The manifest is also the journal that makes a failure half way recoverable. The commit

1. checks every target (:func:`check_targets`): it must be absent or ours;
2. replaces the manifest, atomically, with one listing the old files that are still
   ours *and* the new ones (``"complete": false``);
3. moves the new files into place (``os.replace``, one by one);
4. deletes the old files the new run did not write (a GIF after ``--no-gif``, surplus
   mesh frames), and the folders they leave empty;
5. replaces the manifest, atomically, with one listing exactly the new files.

Whatever step a crash or power loss interrupts, the manifest on disk lists every file
of ours that can be in the folder, so the next run may replace or delete each of them
and ends with a folder holding only its own files. SIGINT and SIGTERM are held back
during steps 2 to 5 (they take milliseconds) so an interrupted commit does not even
need that. A lock on the folder (``flock``) keeps two runs from committing into it at
once.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import signal
import threading
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

#: The manifest's file name in the output folder.
MANIFEST = "softbody-run.json"
#: The manifest's ``format`` value; another value is not a manifest this code wrote.
FORMAT = "softbody-run/1"
#: Largest manifest read [bytes]: a list of file names, far below this even for 10^5
#: mesh frames; a larger file is not one of ours.
MAX_MANIFEST_BYTES = 64 * 1024**2


class OutputError(ValueError):
    """The output folder holds something softbody did not write where a run's file would
    go, or cannot be used (not a folder, locked by another run)."""


@dataclass(frozen=True)
class Entry:
    """One file a run wrote: ``path`` relative to the folder, ``size`` [bytes], ``sha256``."""

    path: str
    size: int
    sha256: str


def file_entry(root: Path, rel: str) -> Entry:
    """The manifest entry of ``root / rel`` as it is now."""
    digest = hashlib.sha256()
    path = root / rel
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return Entry(rel, path.stat().st_size, digest.hexdigest())


def _relative(text) -> str:
    """Check that a manifest path stays inside the folder; return it."""
    if not isinstance(text, str) or not text:
        raise ValueError("not a path")
    p = PurePosixPath(text)
    if p.is_absolute() or "\\" in text or any(part in ("", ".", "..") for part in p.parts):
        raise ValueError(f"{text!r} leaves the folder")
    if p.as_posix() != text:
        raise ValueError(f"{text!r} is not a normalised path")
    return text


def read_manifest(out: Path) -> dict[str, Entry]:
    """The files the previous run in ``out`` wrote ({} when there is no manifest).

    Raises :class:`OutputError` when ``softbody-run.json`` exists but is not a manifest
    softbody wrote (then the folder is not ours to manage).
    """
    path = out / MANIFEST
    if not os.path.lexists(path):
        return {}
    refuse = OutputError(
        f"{path} is not a manifest softbody wrote; not touching this folder "
        "(choose another --out, or remove that file)"
    )
    if path.is_symlink() or not path.is_file() or path.stat().st_size > MAX_MANIFEST_BYTES:
        raise refuse
    try:
        data = json.loads(path.read_bytes())
        if data.get("format") != FORMAT:
            raise ValueError("format")
        entries = {}
        for item in data["files"]:
            rel = _relative(item["path"])
            entries[rel] = Entry(rel, int(item["size"]), str(item["sha256"]))
    except (ValueError, TypeError, KeyError, AttributeError, UnicodeDecodeError):
        raise refuse from None
    return entries


def is_ours(out: Path, entry: Entry) -> bool:
    """Whether ``out / entry.path`` is still the file softbody wrote (same size and hash;
    a regular file, not a link)."""
    path = out / entry.path
    try:
        if path.is_symlink() or not path.is_file() or path.stat().st_size != entry.size:
            return False
        return file_entry(out, entry.path).sha256 == entry.sha256
    except OSError:
        return False


def check_targets(out: Path, paths: Iterable[str], old: dict[str, Entry]) -> None:
    """Raise :class:`OutputError` unless every ``out / path`` is absent or ours (listed in
    ``old`` and unchanged), and each folder on the way is a real folder that ``old``
    has files in. Nothing is modified."""
    hint = "move it away or choose another --out"
    folders = {str(f) for p in old for f in PurePosixPath(p).parents}
    checked: set[str] = set()
    for rel in paths:
        parent = PurePosixPath(rel).parent
        for folder in reversed([parent, *parent.parents][:-1]):  # outermost first
            key = str(folder)
            if key in checked:
                continue
            checked.add(key)
            path = out / key
            if os.path.lexists(path):
                if path.is_symlink() or not path.is_dir():
                    raise OutputError(f"{path} is not a folder softbody wrote; {hint}")
                if key not in folders:
                    raise OutputError(
                        f"{path} exists and softbody did not write it; not writing into it "
                        f"({hint})"
                    )
        path = out / rel
        if not os.path.lexists(path):
            continue
        if rel not in old:
            raise OutputError(
                f"{path} exists and softbody did not write it; not overwriting it ({hint})"
            )
        if not is_ours(out, old[rel]):
            raise OutputError(
                f"{path} changed since softbody wrote it; not overwriting it ({hint})"
            )


def prepare(out: Path) -> None:
    """Create ``out`` (and its parents) if needed; refuse a path that is not a folder."""
    if os.path.lexists(out) and not out.is_dir():
        raise OutputError(f"{out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)


@contextlib.contextmanager
def folder_lock(out: Path) -> Iterator[None]:
    """Hold an exclusive ``flock`` on the folder ``out`` (where the platform has one);
    :class:`OutputError` at once when another run holds it."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock, the manifest checks still hold
        yield
        return
    fd = os.open(out, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise OutputError(
                f"{out}: another softbody run is writing to this folder; wait for it or "
                "choose another --out"
            ) from None
        except OSError:
            pass  # a file system without locks (some network mounts): go on unlocked
        yield
    finally:
        os.close(fd)  # releases the lock


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back for the duration (main thread only), then deliver
    the first that came, to its previous handler."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    names = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.signal(s, lambda signum, frame: caught.append(signum)) for s in names}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        if caught:
            signal.raise_signal(caught[0])


def _write_manifest(out: Path, scratch: Path, entries: Iterable[Entry], complete: bool) -> None:
    """Replace ``out / MANIFEST`` as a whole: written and synced in ``scratch`` (a folder
    on the same file system), then renamed over the old one."""
    data = {
        "format": FORMAT,
        "complete": complete,
        "files": [vars(e) for e in sorted(entries, key=lambda e: e.path)],
    }
    tmp = scratch / f".{MANIFEST}.{os.getpid()}"
    with open(tmp, "w") as f:
        json.dump(data, f, indent=1)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, out / MANIFEST)


def _remove_empty_folders(out: Path, rel: str) -> None:
    """Remove the folders above ``out / rel`` that are now empty (not ``out`` itself); a
    folder still holding something (a user's file) stays."""
    parent = PurePosixPath(rel).parent
    for folder in [parent, *parent.parents][:-1]:
        try:
            (out / folder).rmdir()
        except OSError:
            return


def commit(tmp: Path, out: Path) -> list[Path]:
    """Move every file under ``tmp`` (a folder inside ``out``) into ``out`` and remove the
    previous run's files that this run did not write; returns the top-level paths
    written (files and folders), sorted. See the module docstring for the steps."""
    old = read_manifest(out)
    rels = sorted(
        p.relative_to(tmp).as_posix()
        for p in tmp.rglob("*")
        if p.is_file() and not p.name.startswith(".")
    )
    check_targets(out, rels, old)
    new = {rel: file_entry(tmp, rel) for rel in rels}
    stale = [e for rel, e in old.items() if rel not in new and is_ours(out, e)]
    with signals_held():
        _write_manifest(out, tmp, [*stale, *new.values()], complete=False)
        for rel in rels:
            (out / rel).parent.mkdir(parents=True, exist_ok=True)
            os.replace(tmp / rel, out / rel)
        for entry in stale:
            with contextlib.suppress(FileNotFoundError):
                (out / entry.path).unlink()
            _remove_empty_folders(out, entry.path)
        _write_manifest(out, tmp, new.values(), complete=True)
    top = sorted({PurePosixPath(rel).parts[0] for rel in rels} | {MANIFEST})
    return [out / name for name in top]
