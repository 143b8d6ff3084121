"""An output folder that holds exactly one run's files, and never anything else of ours.

A run writes into a temporary folder inside the output folder; :func:`commit` then
moves the files into place. What softbody owns in the folder is what the manifest
``softbody-run.json`` lists: each file's path (relative, ``/``-separated), size and
SHA-256. A file is *ours* only while it is listed and still has that size and hash, so
a user's file, or one of ours the user has since edited, is never overwritten or
deleted; a run that would have to replace one stops with :class:`OutputError` before
moving anything.

Only what lies *below* the output folder counts: the folder itself may be a link the
user chose, but a listed path is ours only when every folder on its way down is a real
folder (not a link) and the path itself a regular file. A link put in place of one of
our folders (``mv out/meshes keep && ln -s keep out/meshes``), or one in a downloaded
folder beside a forged manifest (``home -> ~`` with ``home/.bashrc`` listed), is never
followed: nothing behind it is hashed, deleted or written, and a run that would write a
file through it stops with :class:`OutputError` before moving anything. A listed path
must be relative and normalised (no ``..``, ``.`` or empty part), or the manifest is
not one softbody wrote. Where the platform has the ``*at`` calls (``dir_fd``, POSIX)
each path is reached one folder at a time, each opened with ``O_NOFOLLOW`` relative to
the one above, and every hash, deletion, new folder and move names one entry of a folder
so held: a link swapped in after the check is still not followed. Elsewhere each of
these steps re-checks its path with ``lstat``, one part at a time, right before it.

The manifest is also the journal that makes a failure half way recoverable. The commit

1. checks every target (:func:`check_targets`): it must be absent or ours;
2. replaces the manifest, atomically, with one listing the old files that are still
   ours *and* the new ones (``"complete": false``); a path both runs write accepts
   either file there (the new one, or the one it replaces, listed under ``previous``);
3. moves the new files into place (``os.replace``, one by one);
4. deletes the old files the new run did not write (a GIF after ``--no-gif``, surplus
   mesh frames), and the folders they leave empty;
5. replaces the manifest, atomically, with one listing exactly the new files.

Whatever step a crash, SIGKILL or power loss interrupts, the manifest on disk lists
every file of ours that can be in the folder, in every state it can be in, so the next
run may replace or delete each of them and ends with a folder holding only its own
files. SIGINT and SIGTERM are held back during steps 2 to 5 (they take milliseconds) so
an interrupted commit does not even need that. A lock on the folder (``flock``) keeps
two runs from committing into it at once; holding it, a run also removes the
temporary folders (``.softbody-run-`` and 8 characters, as ``tempfile.mkdtemp`` names
them) that a killed run left behind, since no other run can be using them.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import re
import shutil
import signal
import stat
import threading
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

#: The manifest's file name in the output folder.
MANIFEST = "softbody-run.json"
#: The manifest's ``format`` value written; 2 added ``previous`` (the interim manifest's
#: other accepted file at a path).
FORMAT = "softbody-run/2"
#: The ``format`` values read (1 is 2 without ``previous``); another value is not a
#: manifest this code wrote.
FORMATS = ("softbody-run/1", FORMAT)
#: Largest manifest read [bytes]: a list of file names, far below this even for 10^5
#: mesh frames; a larger file is not one of ours.
MAX_MANIFEST_BYTES = 64 * 1024**2
#: Exactly the names of the temporary folders a run makes in the output folder
#: (``tempfile.mkdtemp(prefix=".softbody-run-")`` in :func:`softbody.run.run_scene`).
TEMPORARY = re.compile(r"\.softbody-run-[a-z0-9_]{8}")

_O_READ = os.O_RDONLY | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0)
_O_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_O_DIRECTORY = getattr(os, "O_DIRECTORY", 0)
_O_NONBLOCK = getattr(os, "O_NONBLOCK", 0)  # a FIFO put in place of a file: no hang
#: Whether paths below the output folder are reached through held folders (``dir_fd``);
#: otherwise by a fresh lstat walk before each step.
#: (``os.replace`` takes ``dir_fd`` wherever ``os.rename`` does.)
_AT_CALLS = {os.open, os.stat, os.mkdir, os.unlink, os.rmdir, os.rename}
_AT = bool(_O_NOFOLLOW and _O_DIRECTORY) and _AT_CALLS <= os.supports_dir_fd


class OutputError(ValueError):
    """The output folder holds something softbody did not write where a run's file would
    go, or cannot be used (not a folder, locked by another run)."""


class _NotOurs(OSError):
    """A path below the output folder passes a link or something else that is not a
    folder, or ends at something that is not a regular file: never used."""


@dataclass(frozen=True)
class Entry:
    """One file a run wrote: ``path`` relative to the folder, ``size`` [bytes], ``sha256``.

    ``previous``: other ``(size, sha256)`` the path may hold, in the interim manifest
    only: the file this run is replacing there, until it is replaced."""

    path: str
    size: int
    sha256: str
    previous: tuple[tuple[int, str], ...] = ()

    @property
    def versions(self) -> tuple[tuple[int, str], ...]:
        """Every ``(size, sha256)`` of ours the path may hold."""
        return ((self.size, self.sha256), *self.previous)

    def as_json(self) -> dict:
        item = {"path": self.path, "size": self.size, "sha256": self.sha256}
        if self.previous:
            item["previous"] = [{"size": n, "sha256": h} for n, h in self.previous]
        return item


class _Folder:
    """A real folder: the output folder, or one below it reached without following a link.

    With ``dir_fd`` calls it is held open (``fd``) and each method names one entry in
    it; otherwise ``fd`` is None and the methods use ``path``, which :func:`_walk` has
    just checked part by part."""

    def __init__(self, path: Path, fd: int | None) -> None:
        self.path = path
        self.fd = fd

    def _at(self, name: str) -> tuple[str | Path, dict]:
        if self.fd is None:
            return self.path / name, {}
        return name, {"dir_fd": self.fd}

    def lstat(self, name: str) -> os.stat_result | None:
        """The entry ``name`` itself (a link is not followed); None when absent."""
        where, at = self._at(name)
        try:
            return os.stat(where, follow_symlinks=False, **at)
        except FileNotFoundError:
            return None

    def _not_ours(self, name: str, what: str) -> _NotOurs:
        return _NotOurs(errno.ENOTDIR, f"not {what} (a link?)", str(self.path / name))

    def child(self, name: str, create: bool = False) -> _Folder | None:
        """The real folder ``name`` in this one (created with ``create``); None when
        absent. The caller closes its ``fd``."""
        st = self.lstat(name)
        if st is None and create:
            where, at = self._at(name)
            with contextlib.suppress(FileExistsError):
                os.mkdir(where, **at)
            st = self.lstat(name)
        if st is None:
            return None
        if not stat.S_ISDIR(st.st_mode):
            raise self._not_ours(name, "a folder")
        if self.fd is None:
            return _Folder(self.path / name, None)
        fd = os.open(name, _O_READ | _O_DIRECTORY | _O_NOFOLLOW, dir_fd=self.fd)
        return _Folder(self.path / name, fd)

    def open_file(self, name: str) -> int:
        """A descriptor of the regular file ``name`` in this folder, for reading;
        FileNotFoundError when absent, :class:`_NotOurs` when a link or not a file."""
        st = self.lstat(name)
        if st is None:
            raise FileNotFoundError(errno.ENOENT, "No such file", str(self.path / name))
        if not stat.S_ISREG(st.st_mode):
            raise self._not_ours(name, "a regular file")
        where, at = self._at(name)
        fd = os.open(where, _O_READ | _O_NOFOLLOW | _O_NONBLOCK, **at)
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            raise self._not_ours(name, "a regular file")
        return fd

    def unlink(self, name: str) -> None:
        """Delete the regular file ``name`` (absent: nothing to do)."""
        st = self.lstat(name)
        if st is None:
            return
        if not stat.S_ISREG(st.st_mode):
            raise self._not_ours(name, "a regular file")
        where, at = self._at(name)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(where, **at)

    def rmdir(self, name: str) -> None:
        """Remove the empty real folder ``name``; OSError when it is not one."""
        st = self.lstat(name)
        if st is None or not stat.S_ISDIR(st.st_mode):
            raise self._not_ours(name, "a folder")
        where, at = self._at(name)
        os.rmdir(where, **at)

    def move_in(self, source: Path, name: str) -> None:
        """Rename ``source`` to ``name`` in this folder (replacing a file there)."""
        if self.fd is None:
            os.replace(source, self.path / name)
        else:
            os.replace(source, name, dst_dir_fd=self.fd)


@contextlib.contextmanager
def _walk(out: Path, parts: Sequence[str] = (), create: bool = False) -> Iterator[_Folder | None]:
    """The real folder ``out / parts``, reached part by part without following a link
    (``out`` itself may be one); None when ``out`` or a folder on the way is absent
    (with ``create`` the missing ones are made). :class:`_NotOurs` when a part is a
    link or not a folder."""
    with contextlib.ExitStack() as stack:
        yield _descend(stack, out, parts, create)


def _descend(
    stack: contextlib.ExitStack, out: Path, parts: Sequence[str], create: bool
) -> _Folder | None:
    if _AT:
        try:
            fd = os.open(out, _O_READ | _O_DIRECTORY)
        except (FileNotFoundError, NotADirectoryError):
            return None
        stack.callback(os.close, fd)
        folder = _Folder(out, fd)
    else:
        if not out.is_dir():
            return None
        folder = _Folder(out, None)
    for name in parts:
        folder = folder.child(name, create)
        if folder is None:
            return None
        if folder.fd is not None:
            stack.callback(os.close, folder.fd)
    return folder


def _split(rel: str) -> tuple[list[str], str]:
    *folders, name = rel.split("/")
    return folders, name


def _open_regular(out: Path, rel: str) -> int:
    """A descriptor of the regular file ``out / rel`` reached without a link (see
    :func:`_walk`); FileNotFoundError when absent, :class:`_NotOurs` when not ours."""
    folders, name = _split(rel)
    with _walk(out, folders) as folder:
        if folder is None:
            raise FileNotFoundError(errno.ENOENT, "No such file", str(out / rel))
        return folder.open_file(name)


def _digest(fd: int) -> tuple[int, str]:
    """``(size, sha256)`` of what the descriptor ``fd`` reads; closes it."""
    digest = hashlib.sha256()
    size = 0
    with os.fdopen(fd, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
            size += len(block)
    return size, digest.hexdigest()


def file_entry(root: Path, rel: str) -> Entry:
    """The manifest entry of ``root / rel`` as it is now (a regular file, reached
    without following a link below ``root``; OSError otherwise)."""
    return Entry(rel, *_digest(_open_regular(root, _relative(rel))))


def _held(out: Path, entry: Entry) -> tuple[int, str] | None:
    """Which of ``entry``'s versions ``out / entry.path`` holds now; None when none
    (absent, changed, a link, or reached through one)."""
    try:
        fd = _open_regular(out, entry.path)
    except OSError:
        return None
    try:
        if os.fstat(fd).st_size not in {size for size, _ in entry.versions}:
            os.close(fd)
            return None
    except OSError:
        os.close(fd)
        return None
    try:
        version = _digest(fd)
    except OSError:
        return None
    return version if version in entry.versions else None


def _relative(text) -> str:
    """Check that a manifest path stays inside the folder: relative, ``/``-separated,
    normalised (no ``..``, ``.`` or empty part), no NUL, backslash or drive colon;
    return it."""
    if not isinstance(text, str) or not text:
        raise ValueError("not a path")
    p = PurePosixPath(text)
    if p.is_absolute() or any(c in text for c in "\\:\0"):
        raise ValueError(f"{text!r} leaves the folder")
    if any(part in ("", ".", "..") for part in text.split("/")):
        raise ValueError(f"{text!r} leaves the folder")
    if p.as_posix() != text:
        raise ValueError(f"{text!r} is not a normalised path")
    return text


def _version(item) -> tuple[int, str]:
    size, sha256 = item["size"], item["sha256"]
    if isinstance(size, bool) or not isinstance(size, int) or size < 0:
        raise ValueError("size")
    if not isinstance(sha256, str):
        raise ValueError("sha256")
    return size, sha256


def read_manifest(out: Path) -> dict[str, Entry]:
    """The files the previous run in ``out`` wrote ({} when there is no manifest).

    Raises :class:`OutputError` when ``softbody-run.json`` exists but is not a manifest
    softbody wrote (then the folder is not ours to manage).
    """
    refuse = OutputError(
        f"{out / MANIFEST} is not a manifest softbody wrote; not touching this folder "
        "(choose another --out, or remove that file)"
    )
    try:
        with _walk(out) as folder:
            if folder is None or folder.lstat(MANIFEST) is None:
                return {}
            fd = folder.open_file(MANIFEST)
    except _NotOurs:
        raise refuse from None
    with os.fdopen(fd, "rb") as f:
        raw = f.read(MAX_MANIFEST_BYTES + 1)
    if len(raw) > MAX_MANIFEST_BYTES:
        raise refuse
    try:
        data = json.loads(raw)
        if data.get("format") not in FORMATS:
            raise ValueError("format")
        entries = {}
        for item in data["files"]:
            rel = _relative(item["path"])
            previous = item.get("previous", []) if data["format"] != FORMATS[0] else []
            if rel in entries or not isinstance(previous, list):
                raise ValueError(rel)
            entries[rel] = Entry(rel, *_version(item), tuple(_version(p) for p in previous))
    except (ValueError, TypeError, KeyError, AttributeError, UnicodeDecodeError):
        raise refuse from None
    return entries


def is_ours(out: Path, entry: Entry) -> bool:
    """Whether ``out / entry.path`` is still a file softbody wrote (one of the entry's
    sizes and hashes; a regular file, reached without following a link)."""
    return _held(out, entry) is not None


def _kind(out: Path, parts: Sequence[str]) -> str | None:
    """What ``out / parts`` is: ``"folder"``, ``"file"``, ``"other"`` (a link, or below
    one), or None when absent."""
    try:
        with _walk(out, parts[:-1]) as folder:
            st = None if folder is None else folder.lstat(parts[-1])
    except _NotOurs:
        return "other"
    if st is None:
        return None
    if stat.S_ISDIR(st.st_mode):
        return "folder"
    return "file" if stat.S_ISREG(st.st_mode) else "other"


def check_targets(out: Path, paths: Iterable[str], old: dict[str, Entry]) -> None:
    """Raise :class:`OutputError` unless every ``out / path`` is absent or ours (listed in
    ``old`` and unchanged), and each folder on the way is a real folder (not a link)
    that ``old`` has files in. Nothing is modified."""
    hint = "move it away or choose another --out"
    folders = {"/".join(p.split("/")[:i]) for p in old for i in range(1, p.count("/") + 1)}
    checked: set[str] = set()
    for rel in paths:
        parts = _relative(rel).split("/")
        for i in range(1, len(parts)):  # outermost first
            key = "/".join(parts[:i])
            if key in checked:
                continue
            checked.add(key)
            kind = _kind(out, parts[:i])
            if kind is None:
                continue
            path = out / key
            if kind != "folder":
                raise OutputError(f"{path} is not a folder softbody wrote; {hint}")
            if key not in folders:
                raise OutputError(
                    f"{path} exists and softbody did not write it; not writing into it "
                    f"({hint})"
                )
        path = out / rel
        if _kind(out, parts) is None:
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


def _remove_stale_temporaries(fd: int) -> None:
    """Remove the temporary folders (:data:`TEMPORARY`) in the folder held open as
    ``fd``: real folders only, never a link; for the holder of the folder lock only."""
    for name in os.listdir(fd):
        if not TEMPORARY.fullmatch(name):
            continue
        with contextlib.suppress(OSError):
            if stat.S_ISDIR(os.stat(name, dir_fd=fd, follow_symlinks=False).st_mode):
                shutil.rmtree(name, dir_fd=fd)


@contextlib.contextmanager
def folder_lock(out: Path) -> Iterator[None]:
    """Hold an exclusive ``flock`` on the folder ``out`` (where the platform has one);
    :class:`OutputError` at once when another run holds it. Once it is held, removes the
    temporary folders that killed runs left in ``out``."""
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
        else:  # no other run is writing here: their temporary folders are leftovers
            if _AT and shutil.rmtree.avoids_symlink_attacks:
                _remove_stale_temporaries(fd)
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
        "files": [e.as_json() for e in sorted(entries, key=lambda e: e.path)],
    }
    tmp = scratch / f".{MANIFEST}.{os.getpid()}"
    with open(tmp, "w") as f:
        json.dump(data, f, indent=1)
        f.flush()
        os.fsync(f.fileno())
    with _walk(out) as folder:
        if folder is None:
            raise FileNotFoundError(errno.ENOENT, "No such folder", str(out))
        folder.move_in(tmp, MANIFEST)


def _move_in(tmp: Path, out: Path, rel: str) -> None:
    """Move ``tmp / rel`` to ``out / rel``, making the folders on the way (real folders;
    :class:`_NotOurs` for a link there)."""
    folders, name = _split(rel)
    with _walk(out, folders, create=True) as folder:
        if folder is None:
            raise FileNotFoundError(errno.ENOENT, "No such folder", str(out))
        folder.move_in(tmp / rel, name)


def _remove(out: Path, rel: str) -> None:
    """Delete the regular file ``out / rel``; nothing when it is absent, a link, or
    behind one."""
    folders, name = _split(rel)
    with contextlib.suppress(FileNotFoundError, _NotOurs), _walk(out, folders) as folder:
        if folder is not None:
            folder.unlink(name)


def _remove_empty_folders(out: Path, rel: str) -> None:
    """Remove the folders above ``out / rel`` that are now empty (not ``out`` itself); a
    folder still holding something (a user's file), or a link, stays."""
    parts = rel.split("/")[:-1]
    while parts:
        try:
            with _walk(out, parts[:-1]) as folder:
                if folder is None:
                    return
                folder.rmdir(parts[-1])
        except OSError:
            return
        parts.pop()


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
    held = {rel: _held(out, entry) for rel, entry in old.items()}
    # the interim manifest: each old file as it is now, each new one, and for a path
    # both runs write, the old file there until it is replaced
    stale = [Entry(rel, *held[rel]) for rel in old if rel not in new and held[rel]]
    interim = [
        Entry(e.path, e.size, e.sha256, (held[rel],)) if held.get(rel) else e
        for rel, e in new.items()
    ]
    with signals_held():
        _write_manifest(out, tmp, [*stale, *interim], complete=False)
        for rel in rels:
            _move_in(tmp, out, rel)
        for entry in stale:
            _remove(out, entry.path)
            _remove_empty_folders(out, entry.path)
        _write_manifest(out, tmp, new.values(), complete=True)
    top = sorted({PurePosixPath(rel).parts[0] for rel in rels} | {MANIFEST})
    return [out / name for name in top]
