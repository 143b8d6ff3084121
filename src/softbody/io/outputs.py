"""An output folder that softbody adds files to by name, and never takes anything from.

The design, in three sentences (the user guide gives the same ones):

1. A run writes everything into a temporary folder that it creates inside the output
   folder, and only when the whole run has succeeded moves each of its files, by name, to
   its place there; that temporary folder is the only folder a run ever removes.
2. If a file or folder of one of those names already exists, the run stops before it
   simulates, with one line naming them, unless ``overwrite`` (``--overwrite``) is given:
   then exactly those files are replaced, and named; nothing else is ever deleted.
3. No link below the output folder is followed (the output folder itself may be one), and
   a lock on the folder keeps two runs from writing into it at once.

Nothing rests on a file anyone could write: there is no manifest of "our" files to trust,
and no folder is deleted because of its name. Every file name a run writes carries the
scene's file stem (``NAME.mp4``, ``NAME-meshes/frame_00000.obj``), so runs of different
scenes share an output folder without touching each other's files.

Links: a folder on a file's way down (``NAME-meshes``) must be a real folder, and a file
that is replaced a regular file; a link, a FIFO or anything else there stops the run,
even with ``overwrite``. Where the platform has the ``*at`` calls (``dir_fd``, POSIX) each
path is reached one folder at a time, each opened with ``O_NOFOLLOW`` relative to the one
above, and every new folder and move names one entry of a folder so held: a link swapped
in after the check is still not followed. Elsewhere each step re-checks its path with
``lstat``, one part at a time, right before it. Without ``overwrite`` a file is moved into
place with a hard link, which fails rather than replace a file that appeared since the
check (a plain rename, after a fresh check, where the file system has no hard links).
"""

from __future__ import annotations

import contextlib
import errno
import os
import signal
import stat
import threading
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

_O_READ = os.O_RDONLY | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0)
_O_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_O_DIRECTORY = getattr(os, "O_DIRECTORY", 0)
#: Whether paths below the output folder are reached through held folders (``dir_fd``);
#: otherwise by a fresh lstat walk before each step.
#: (``os.replace`` takes ``dir_fd`` wherever ``os.rename`` does.)
_AT_CALLS = {os.open, os.stat, os.mkdir, os.rename, os.link}
_AT = bool(_O_NOFOLLOW and _O_DIRECTORY) and _AT_CALLS <= os.supports_dir_fd
#: Existing paths named in a refusal; the rest are counted.
_NAMED = 3


class OutputError(ValueError):
    """The output folder holds something where a run's file would go (and ``overwrite``
    was not given, or it is not a regular file), or cannot be used (not a folder, locked
    by another run)."""


class _NotOurs(OSError):
    """A path below the output folder passes a link or something else that is not a
    folder: never used."""


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
            raise _NotOurs(errno.ENOTDIR, "not a folder (a link?)", str(self.path / name))
        if self.fd is None:
            return _Folder(self.path / name, None)
        fd = os.open(name, _O_READ | _O_DIRECTORY | _O_NOFOLLOW, dir_fd=self.fd)
        return _Folder(self.path / name, fd)

    def names(self) -> list[str]:
        """The entries of this folder."""
        return os.listdir(self.path if self.fd is None else self.fd)

    def replace_with(self, source: Path, name: str) -> None:
        """Rename ``source`` to ``name`` in this folder, replacing a file there."""
        if self.fd is None:
            os.replace(source, self.path / name)
        else:
            os.replace(source, name, dst_dir_fd=self.fd)

    def add(self, source: Path, name: str) -> None:
        """Move ``source`` to ``name`` in this folder, which must not exist: a hard link
        then the source's removal, so that a file that appeared at ``name`` since it was
        checked is never replaced (FileExistsError). Where the file system has no hard
        links, a rename after a fresh check."""
        try:
            if self.fd is None:
                os.link(source, self.path / name)
            else:
                os.link(source, name, dst_dir_fd=self.fd)
        except FileExistsError:
            raise
        except OSError as exc:
            if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV,
                                 errno.EMLINK):  # fmt: skip
                raise
            if self.lstat(name) is not None:
                raise FileExistsError(errno.EEXIST, "File exists", str(self.path / name)) from None
            self.replace_with(source, name)
            return
        os.unlink(source)


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


def _relative(rel: str) -> list[str]:
    """The parts of a run's file name (relative, ``/``-separated, normalised)."""
    parts = rel.split("/")
    if rel.startswith("/") or any(p in ("", ".", "..") or "\\" in p for p in parts):
        raise ValueError(f"{rel!r} is not a file name inside the output folder")
    return parts


def _kind(out: Path, parts: Sequence[str]) -> str | None:
    """What ``out / parts`` is: ``"folder"``, ``"file"`` (regular), ``"other"`` (a link,
    a FIFO, ..., or below one), or None when absent."""
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


def check_targets(out: Path, paths: Iterable[str], *, overwrite: bool = False) -> list[str]:
    """The run's files (``paths``, relative to ``out``) that exist and would be replaced;
    nothing is modified.

    Raises :class:`OutputError` naming the path when a folder on the way is a link or not
    a folder, or a target exists and is not a regular file (whatever ``overwrite``
    says); and, unless ``overwrite``, when any target or any folder on the way exists
    (up to three are named, the rest counted)."""
    hint = "move it away or choose another --out"
    existing: list[str] = []
    replaced: list[str] = []
    seen: set[str] = set()
    for rel in paths:
        parts = _relative(rel)
        for i in range(1, len(parts)):  # the folders on the way, outermost first
            key = "/".join(parts[:i])
            if key in seen:
                continue
            seen.add(key)
            kind = _kind(out, parts[:i])
            if kind == "folder":
                existing.append(key + "/")
            elif kind is not None:
                raise OutputError(f"{out / key} is not a folder (a link?); {hint}")
        kind = _kind(out, parts)
        if kind is None:
            continue
        if kind != "file":
            raise OutputError(
                f"{out / rel} exists and is not a file softbody can replace (a folder or a "
                f"link?); {hint}"
            )
        replaced.append(rel)
        if not any(p.endswith("/") and rel.startswith(p) for p in existing):
            existing.append(rel)
    if existing and not overwrite:
        shown = ", ".join(
            str(out / p) + ("/" if p.endswith("/") else "") for p in existing[:_NAMED]
        )
        more = f" and {len(existing) - _NAMED} more" if len(existing) > _NAMED else ""
        raise OutputError(
            f"{shown}{more} already exist{'s' if len(existing) == 1 else ''} (an earlier "
            "run's?); --overwrite replaces this run's files there, or choose another --out"
        )
    return replaced


def prepare(out: Path) -> None:
    """Create ``out`` (and its parents) if needed; refuse a path that is not a folder."""
    if os.path.lexists(out) and not out.is_dir():
        raise OutputError(f"{out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)


@contextlib.contextmanager
def folder_lock(out: Path) -> Iterator[None]:
    """Hold an exclusive ``flock`` on the folder ``out`` itself (where the platform has
    one; no lock file is made); :class:`OutputError` at once when another run holds it."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock; the checks before each move still hold
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
    """Hold SIGINT, SIGTERM and SIGHUP back for the duration (main thread only), then deliver
    the first that came, to its previous handler."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    names = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    previous = {s: signal.signal(s, lambda signum, frame: caught.append(signum)) for s in names}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        if caught:
            signal.raise_signal(caught[0])


@dataclass
class Committed:
    """What :func:`commit` did, as paths in the output folder."""

    written: list[Path] = field(default_factory=list)
    """The top-level files and folders the run wrote, sorted."""
    replaced: list[Path] = field(default_factory=list)
    """The files that existed and were replaced (with ``overwrite`` only), sorted."""
    others: list[Path] = field(default_factory=list)
    """Files in the run's folders (``NAME-meshes``) that this run did not write (an
    earlier run's surplus frames, a user's notes): left as they were, sorted."""


def commit(tmp: Path, out: Path, paths: Sequence[str], *, overwrite: bool = False) -> Committed:
    """Move the run's files ``paths`` (relative; each written under ``tmp``, a folder
    inside ``out``) to the same names in ``out``: checked again first
    (:func:`check_targets`; nothing moves when that fails), then moved one by one with
    SIGINT and SIGTERM held back for those milliseconds. Replaces an existing file only
    with ``overwrite``; deletes nothing."""
    paths = sorted(paths)
    replaced = set(check_targets(out, paths, overwrite=overwrite))
    folders: dict[str, set[str]] = {}
    with signals_held():
        for rel in paths:
            *parents, name = _relative(rel)
            with _walk(out, parents, create=True) as folder:
                if folder is None:
                    raise FileNotFoundError(errno.ENOENT, "No such folder", str(out))
                try:
                    if rel in replaced:
                        if _kind(out, [*parents, name]) not in ("file", None):
                            raise _NotOurs(errno.EEXIST, "not a regular file", str(out / rel))
                        folder.replace_with(tmp / rel, name)
                    else:
                        folder.add(tmp / rel, name)
                except (FileExistsError, _NotOurs):
                    raise OutputError(
                        f"{out / rel} appeared while the run was writing; not replacing it "
                        "(--overwrite replaces it)"
                    ) from None
                if parents:
                    folders.setdefault("/".join(parents), set()).add(name)
    others = []
    for key, written in folders.items():
        with contextlib.suppress(OSError), _walk(out, key.split("/")) as folder:
            others += [out / key / n for n in folder.names() if n not in written] if folder else []
    top = sorted({rel.split("/")[0] for rel in paths})
    return Committed(
        written=[out / name for name in top],
        replaced=[out / rel for rel in sorted(replaced)],
        others=sorted(others),
    )
