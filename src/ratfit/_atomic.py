"""Output that cannot be half-written, and that never replaces what the user named.

* A regular file (or a new path) is written to a temporary file beside it, then
  renamed over it: a failure at any point leaves the old file (or nothing) there.
* A symlink is followed: its final target is replaced that way, the link stays a link.
* A character or block device, a FIFO or a socket (``/dev/null``, ``/dev/stdout``,
  a named pipe) is written through, never renamed over: it stays what it is.
* ``-`` is standard output.
* A directory is an error naming the path (``IsADirectoryError``).

:func:`atomic_dir` does the same for outputs of several files (a report, a demo, a
batch folder): they are written into a temporary folder beside the target and
moved into place only once every one of them was written.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import stat
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO

__all__ = ["STDOUT", "atomic_dir", "atomic_open", "atomic_path", "completed", "forget_completed",
           "is_stream", "output_kind"]

STDOUT = "-"

# Outputs completed in this process (since forget_completed()): when a later step fails
# (printing the report to a full stdout), the error can say which files are complete.
_COMPLETED: list[str] = []


def completed() -> list[str]:
    """Paths written completely since the last :func:`forget_completed`, in order."""
    return list(_COMPLETED)


def forget_completed() -> None:
    _COMPLETED.clear()


def output_kind(path: str | os.PathLike[str]) -> tuple[Path, str]:
    """The real target of an output path and what it is.

    ``"stdout"`` (the name ``-``), ``"new"`` (nothing there yet), ``"file"``,
    ``"dir"`` or ``"stream"`` (a device, FIFO or socket, or anything reached through a
    file descriptor link such as ``/dev/stdout``). Symlinks are followed, a dangling
    one to the file it names.
    """
    if os.fspath(path) == STDOUT or _descriptor(path) == 1:
        # /dev/stdout, /dev/fd/1, /proc/self/fd/1: our own standard output, written in
        # order with everything else printed there (re-opening it would write at the
        # start of a file a shell opened for us, over what we print)
        return Path(STDOUT), "stdout"
    try:
        st = os.stat(path)  # the kernel follows every link, /proc's fd links included
    except FileNotFoundError:
        return Path(os.path.realpath(path)), "new"
    if stat.S_ISDIR(st.st_mode):
        return Path(path), "dir"
    if stat.S_ISREG(st.st_mode) and _descriptor(path) is None:
        return Path(os.path.realpath(path)), "file"
    # written through the name given: a file reached through a file descriptor link is
    # an open file of some process, not a file to replace
    return Path(path), "stream"


_FD_LINK = re.compile(r"^/(?:proc/(self|thread-self|\d+)/fd/(\d+)$|dev/fd/(\d+)$"
                      r"|dev/(stdin|stdout|stderr)$)")
_STD = {"stdin": 0, "stdout": 1, "stderr": 2}


def _descriptor(path: str | os.PathLike[str]) -> int | None:
    """The file descriptor number when following ``path``'s symlinks passes through a
    file-descriptor link (/dev/stdout, /dev/fd/N, /proc/self/fd/N); -1 for another
    process's descriptor; None otherwise."""
    p = os.path.abspath(path)
    for _ in range(40):
        m = _FD_LINK.match(p)
        if m:
            who, fd_proc, fd_dev, std = m.groups()
            if std:
                return _STD[std]
            if fd_dev:
                return int(fd_dev)
            return int(fd_proc) if who in ("self", "thread-self") or int(who) == os.getpid() \
                else -1
        if not os.path.islink(p):
            return None
        p = os.path.normpath(os.path.join(os.path.dirname(p), os.readlink(p)))
    return None


def is_stream(path: str | os.PathLike[str]) -> bool:
    """True for ``-`` and for outputs written through (devices, FIFOs, sockets)."""
    return output_kind(path)[1] in ("stdout", "stream")


def _named(exc: OSError, path: str | os.PathLike[str], own: tuple[str, ...]) -> OSError:
    """``exc`` naming the user's ``path`` instead of one of our temporary names (or of
    nothing: a full disk's write error names no file)."""
    name = exc.filename
    if name is not None and not any(os.fspath(name) == o or os.fspath(name).startswith(
            o + os.sep) for o in own):
        return exc
    return OSError(exc.errno, exc.strerror or str(exc), os.fspath(path))


def _make_parents(folder: Path) -> list[Path]:
    """Create ``folder`` and missing parents; return the ones created, deepest first."""
    made: list[Path] = []
    p = folder
    while not p.exists():
        made.append(p)
        if p.parent == p:
            break
        p = p.parent
    folder.mkdir(parents=True, exist_ok=True)
    return made


def _remove_made(made: list[Path]) -> None:
    for d in made:
        with contextlib.suppress(OSError):
            d.rmdir()  # only if still empty: never what something else put there


def _usual_mode(existing: Path | None) -> int:
    """The mode of the file being replaced, else what a plain open() would give."""
    if existing is not None:
        with contextlib.suppress(OSError):
            return stat.S_IMODE(os.stat(existing).st_mode)
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def _not_a_dir(path: str | os.PathLike[str]) -> OSError:
    return IsADirectoryError(errno.EISDIR, "is a directory, not a file", os.fspath(path))


def _copy_to(src: Path, dest: Path | None) -> None:
    """Stream ``src`` to a device/FIFO ``dest`` (opened without create or truncate),
    or to standard output when ``dest`` is None."""
    with open(src, "rb") as fin:
        if dest is None:
            out = sys.stdout.buffer
            sys.stdout.flush()
            shutil.copyfileobj(fin, out)
            out.flush()
            return
        fd = os.open(dest, os.O_WRONLY | getattr(os, "O_NOCTTY", 0))
        with os.fdopen(fd, "wb") as fout:
            shutil.copyfileobj(fin, fout)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path to write; on success it becomes ``path`` (see the module).

    On error the temporary file is removed, folders created for it too, and an
    ``OSError`` names ``path`` rather than the temporary file.
    """
    target, kind = output_kind(path)
    if kind == "dir":
        raise _not_a_dir(path)
    if kind in ("stream", "stdout"):
        # written through: the content is built in a private folder first, so a
        # failure sends nothing; the device or pipe is never replaced
        scratch = Path(tempfile.mkdtemp(prefix="ratfit-"))
        tmp = scratch / (target.name if kind == "stream" else "stdout")
        try:
            yield tmp
            _copy_to(tmp, target if kind == "stream" else None)
        except OSError as exc:
            raise _named(exc, path, (str(tmp),)) from None
        finally:
            shutil.rmtree(scratch, ignore_errors=True)
        return
    made = _make_parents(target.parent)
    try:
        fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    except OSError as exc:
        _remove_made(made)
        raise _named(exc, path, (str(target.parent),)) from None
    os.close(fd)
    tmp = Path(name)
    os.chmod(tmp, _usual_mode(target if kind == "file" else None))  # mkstemp makes 0600
    try:
        yield tmp
        os.replace(tmp, target)
        _COMPLETED.append(os.fspath(path))
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        _remove_made(made)
        if isinstance(exc, OSError):
            raise _named(exc, path, (str(tmp), str(target))) from None
        raise


class _Unclosed:
    """A stream handed out by :func:`atomic_open` that its ``with`` must not close."""

    def __init__(self, stream: IO) -> None:
        self._s = stream

    def __getattr__(self, name: str):
        return getattr(self._s, name)

    def close(self) -> None:
        self._s.flush()


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO]:
    """Open ``path`` for writing (see the module): a regular file appears whole on
    success; a device, FIFO or ``-`` (standard output) is written to as it goes."""
    if "r" in mode or "a" in mode or "+" in mode:
        raise ValueError(f"atomic_open writes new content, not mode {mode!r}")
    target, kind = output_kind(path)
    if kind == "dir":
        raise _not_a_dir(path)
    if kind == "stdout":
        stream: IO = sys.stdout.buffer if "b" in mode else sys.stdout
        try:
            yield _Unclosed(stream)  # type: ignore[misc]
            stream.flush()
        except OSError as exc:
            raise _named(exc, "<stdout>", ()) from None
        return
    if kind == "stream":
        try:
            fd = os.open(target, os.O_WRONLY | getattr(os, "O_NOCTTY", 0))
            with os.fdopen(fd, mode) as fh:
                yield fh
        except OSError as exc:
            raise _named(exc, path, (str(target),)) from None
        return
    with atomic_path(path) as tmp, open(tmp, mode) as fh:
        yield fh


# ---------------------------------------------------------------------------- folders
def _merge(src: Path, dest: Path) -> None:
    """Move every entry of ``src`` into the existing folder ``dest`` (rename each)."""
    for entry in sorted(src.iterdir()):
        there = dest / entry.name
        if entry.is_dir() and not entry.is_symlink():
            if there.is_dir() and not there.is_symlink():
                _merge(entry, there)
                continue
            if there.exists() or there.is_symlink():
                raise IsADirectoryError(errno.EEXIST, "cannot replace a file by a folder",
                                        str(there))
            os.rename(entry, there)
        else:
            if there.is_dir() and not there.is_symlink():
                raise _not_a_dir(there)
            os.replace(entry, there)


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield an empty temporary folder beside ``path`` to write a multi-file output in.

    On success a new ``path`` appears whole (one rename of the folder); an existing
    folder receives each file by rename, only after every file was written (files
    already there that the output does not name are left alone). On error the
    temporary folder is removed, and so are parent folders made for it: nothing
    is left, and an ``OSError`` names ``path``.
    """
    if os.fspath(path) == STDOUT:
        raise OSError(errno.EINVAL, "a folder output cannot be standard output", STDOUT)
    target, kind = output_kind(path)
    if kind not in ("new", "dir"):
        raise NotADirectoryError(errno.ENOTDIR, "exists and is not a folder", os.fspath(path))
    made = _make_parents(target.parent)
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
    except OSError as exc:
        _remove_made(made)
        raise _named(exc, path, (str(target.parent),)) from None
    inside = str(tmp) + os.sep
    try:
        yield tmp
        if kind == "new":
            os.chmod(tmp, 0o777 & ~_umask())  # mkdtemp makes 0700
            os.rename(tmp, target)
        else:
            _merge(tmp, target)
            shutil.rmtree(tmp)
        # the files written inside count as the folder, under its own name
        _COMPLETED[:] = [p for p in _COMPLETED if not p.startswith(inside)]
        _COMPLETED.append(os.fspath(path))
    except BaseException as exc:
        _COMPLETED[:] = [p for p in _COMPLETED if not p.startswith(inside)]
        shutil.rmtree(tmp, ignore_errors=True)
        _remove_made(made)
        if isinstance(exc, OSError):
            raise _named(exc, path, (str(tmp),)) from None
        raise


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask
