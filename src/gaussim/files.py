"""Output files written so that a failure never leaves a half-written one: each is written to a temporary
file in its own folder and renamed over the target (atomic on POSIX), and a path is checked before a run
spends time on what it would hold."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from .exceptions import GaussimError


class OutputError(GaussimError):
    """An output path cannot be written (the message names it and the cause)."""


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` (same suffix, for writers that pick the format from it), renamed
    to ``path`` when the block succeeds and removed when it fails; an OSError of the block (a full disk
    midway, whose write names no file) is raised again naming ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".tmp{path.suffix}", dir=path.parent)
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
