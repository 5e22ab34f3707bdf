"""Output files written so that a failure never leaves a half-written one: each is written to a temporary
file in its own folder and renamed over the target (atomic on POSIX), and a path is checked before a run
spends time on what it would hold."""

from __future__ import annotations

import errno
import fcntl
import os
import re
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from .exceptions import GaussimError


class OutputError(GaussimError):
    """An output path cannot be written (the message names it and the cause)."""


class Busy(Exception):
    """Another process holds the lock :func:`take_lock` asked for; ``holder`` is its process id as that
    process wrote it in the lock file ("" when it wrote none)."""

    def __init__(self, holder: str) -> None:
        super().__init__(f"locked by process {holder or '(unknown)'}")
        self.holder = holder


# the name of a temporary file of atomic_path: ".NAME.XXXXXXXX.tmpSUFFIX" (mkstemp's 8 random characters)
_TEMPORARY = re.compile(r"\..+\.[a-z0-9_]{8}\.tmp(\.[^.]*)?")


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` (same suffix, for writers that pick the format from it), renamed
    to ``path`` when the block succeeds and removed when it fails; an OSError of its making or of the
    block (a read-only folder, a full disk midway, whose write names no file) is raised again naming
    ``path``."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    except OSError as err:  # named after path, not the temporary file no one asked for
        raise OSError(err.errno, err.strerror or str(err), str(path)) from err
    os.close(fd)
    tmp = Path(name)
    try:
        tmp.chmod(0o666 & ~umask())  # mkstemp's 0600 would make every output private
        yield tmp
        os.replace(tmp, path)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise OSError(err.errno, err.strerror or str(err), str(path)) from err
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def leftovers(folder: str | Path) -> list[Path]:
    """The temporary files of :func:`atomic_path` in ``folder``: those a process killed while writing
    (SIGKILL, a power cut) left behind; none is ever renamed into a result."""
    return [p for p in Path(folder).iterdir() if _TEMPORARY.fullmatch(p.name) and p.is_file()]


def write_atomic(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; the path."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def umask() -> int:
    """The process's umask (read by setting it, the only way POSIX offers)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def check_writable(path: str | Path, what: str, suffixes: tuple[str, ...] = ()) -> Path:
    """Raise OutputError unless a file can be created at ``path`` (its folder made if missing): a folder
    in its place, a read-only or missing parent that cannot be made, or a name that does not end in one
    of ``suffixes`` (when given: a slip such as ``--html scene.toml`` would overwrite the scene). ``what``
    names it in the message."""
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{what} {path}: is a directory; give a file name")
    if suffixes and path.suffix.lower() not in suffixes:
        raise OutputError(f"{what} {path}: the file's name must end in {' or '.join(suffixes)}")
    _probe(path.parent, f"{what} {path}")
    return path


def check_folder(path: str | Path, what: str) -> Path:
    """Raise OutputError unless files can be created in the folder ``path`` (made if missing): a file in
    its place, or a parent that is a file or read-only. ``what`` names it in the message."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{what} {path}: is a file, not a folder; give a folder")
    _probe(path, f"{what} {path}")
    return path


def _probe(folder: Path, named: str) -> None:
    """Make ``folder`` if missing, and create and remove a file in it; an OSError is an OutputError
    that begins with ``named``."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=".gaussim.", suffix=".check", dir=folder)
        os.close(fd)
        os.unlink(name)
    except OSError as err:
        raise OutputError(f"{named}: cannot be written ({err.strerror or err})") from err


def take_lock(path: str | Path) -> int:
    """Take the POSIX record lock (lockf) of the file ``path`` (made if missing) without waiting, and
    write this process's id in it; the descriptor, whose close releases the lock. The system releases
    it too when the process ends, however it ends (SIGKILL included), and forked children do not
    inherit it. Each process must take a file's lock once: closing a second descriptor of the file
    would release it (POSIX), so callers keep a registry of what they hold.

    Raises:
        Busy: another process holds it.
        OSError: the file cannot be made or locked (a file system without locks).
    """
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as err:
        holder = os.pread(fd, 64, 0).decode(errors="replace").strip()
        os.close(fd)
        if err.errno in (errno.EACCES, errno.EAGAIN):
            raise Busy(holder) from None
        raise
    except BaseException:
        os.close(fd)
        raise
    os.ftruncate(fd, 0)
    os.pwrite(fd, str(os.getpid()).encode(), 0)  # who holds it, for the message of those it stops
    return fd


def lock_holder(path: str | Path) -> str | None:
    """The process id (as text, "" when unknown) of the process holding the lock of the file ``path``
    (:func:`take_lock`), or None when no process holds it; an OSError when that cannot be told (no
    such file, a file system without locks). Never ask about a lock this process holds: the probe's
    close would release it."""
    fd = os.open(path, os.O_RDONLY)
    try:
        try:
            fcntl.lockf(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError as err:
            if err.errno in (errno.EACCES, errno.EAGAIN):
                return os.pread(fd, 64, 0).decode(errors="replace").strip()
            raise
        return None
    finally:
        os.close(fd)  # releases the probe's shared lock
