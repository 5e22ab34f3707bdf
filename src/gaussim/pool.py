"""Batches of independent jobs: where they run, and the file that keeps what they finished.

A job runs in a local process pool, or on a Dask cluster when given its scheduler address (or a
client). Each finished job's record, a JSON-able dict with a ``"key"`` that names the job, is appended
to a JSON-lines file at once: an interrupted batch keeps what it finished, and the same batch started
again skips every key already in the file. One batch at a time writes a folder (:func:`exclusive`).
Used by the benchmark's knob sweep (:mod:`gaussim.bench.sweep`) and the user's parameter studies
(:mod:`gaussim.study`).
"""

from __future__ import annotations

import json
import os
import signal
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from .exceptions import GaussimError, InvalidOptions, shown
from .files import Busy, OutputError, take_lock

Job = TypeVar("Job")
# called with (done, total, record) after each job: done counts this batch's jobs, total those it runs
Progress = Callable[[int, int, dict], None]
# the lock file of a folder a batch writes (exclusive), and the folders this process holds: by which thread
LOCK = ".lock"
# a stopped batch's workers are told to stop again this often until they have [s]
STOP_WAIT = 1.0
_HELD: dict[Path, int] = {}


class FolderInUse(GaussimError):
    """Another batch (another process) is writing the folder."""


@contextmanager
def exclusive(folder: Path) -> Iterator[None]:
    """Hold ``folder``'s lock (its file LOCK, the folder made if missing) while the block runs: a second
    batch into the folder would make every job again and append its records twice, so it stops at
    once. The lock is a POSIX record lock (lockf): the OS releases it when its process ends, even by a
    kill, and the pool's forked workers do not inherit it (an flock they shared outlived a killed
    sweep in its orphaned workers), so a lock file left behind stops nobody. The thread that holds it
    may take it again (gaussim sweep holds it from its count of the finished runs to its table, and
    :func:`run_all` takes it).

    Raises:
        FolderInUse: another process, or another thread of this one, holds the lock (the message names
            the folder and that process).
        OutputError: the folder cannot be locked (a file system without locks).
    """
    resolved = folder.resolve()
    held = _HELD.get(resolved)
    if held == threading.get_ident():
        yield
        return
    if held is not None:  # a second descriptor's close would drop this process's lock: never open one
        raise FolderInUse(f"{folder}: another sweep of this process is writing this folder")
    folder.mkdir(parents=True, exist_ok=True)
    try:
        fd = take_lock(folder / LOCK)
    except Busy as busy:
        raise FolderInUse(
            f"{folder}: another sweep{f' (process {busy.holder})' if busy.holder else ''} is writing this "
            "folder; wait for it to end, or give another output folder"
        ) from None
    except OSError as err:
        raise OutputError(f"{folder}: cannot lock it for the sweep ({err.strerror or err})") from err
    _HELD[resolved] = threading.get_ident()
    try:
        yield
    finally:
        del _HELD[resolved]
        os.close(fd)


def load(path: Path) -> list[dict]:
    """The records of a results file (none when it does not exist); a torn last line is skipped."""
    if not path.exists():
        return []
    records = []
    for line in path.read_text().splitlines():
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return records


def run_all(
    todo: Sequence[Job],
    key: Callable[[Job], str],
    job: Callable[[Job], dict],
    path: Path,
    workers: int | None = None,
    scheduler: Any = None,
    progress: Progress | None = None,
    refresh: Callable[[Job, dict], dict | None] | None = None,
) -> list[dict]:
    """Run ``job`` on each item of ``todo`` whose ``key`` is not already in ``path``, appending each
    record as it finishes; return the records of ``todo`` (those in the file and the new ones), in
    its order. ``refresh(item, record)``, for each item's record already in the file: a new record to
    append in its place (the file's last record of a key is its record), or None to keep it.

    ``job`` must be picklable (a module-level function) and return a JSON-able dict whose ``"key"`` is
    its item's; it should catch its own errors and record them, since an exception it raises stops the
    batch (a KeyboardInterrupt stops it too: what finished is kept).

    Args:
        workers: local processes (default: the machine's cores; 1 runs in this process).
        scheduler: a Dask scheduler address ("tcp://host:8786"), or a ``dask.distributed.Client``-like
            object with ``map``; the jobs then run on that cluster.
        progress: called with (done, total, record) after each job.

    Raises:
        InvalidOptions: ``workers`` is not a whole number >= 1, or ``scheduler`` is no Dask address
            (:func:`check_scheduler`), before any job.
        FolderInUse: another batch is writing ``path``'s folder (:func:`exclusive`).
    """
    check_workers(workers)
    if isinstance(scheduler, str):
        check_scheduler(scheduler)
    with exclusive(path.parent):
        done = {r["key"]: r for r in load(path) if "key" in r}
        remaining = [item for item in todo if key(item) not in done]
        torn = path.exists() and path.stat().st_size > 0 and not path.read_bytes().endswith(b"\n")
        with path.open("a") as out:
            if torn:  # a line cut by an interruption ends here: the next record starts a line of its own
                out.write("\n")
            for item in todo:
                held = done.get(key(item))
                if held is not None and refresh is not None and (fresh := refresh(item, held)) is not None:
                    out.write(json.dumps(fresh, default=str) + "\n")
                    out.flush()
                    done[key(item)] = fresh
            for count, record in enumerate(_results(job, remaining, workers, scheduler), start=1):
                out.write(json.dumps(record, default=str) + "\n")
                out.flush()
                done[record["key"]] = record
                if progress is not None:
                    progress(count, len(remaining), record)
    return [done[key(item)] for item in todo if key(item) in done]


def check_workers(workers: object, name: str = "workers") -> None:
    """Raise InvalidOptions naming ``name`` unless ``workers`` is None (the machine's cores) or a whole
    number >= 1 (0 read as the default, a negative one a traceback of the pool's)."""
    if workers is not None and not (isinstance(workers, int) and workers >= 1):
        raise InvalidOptions(name, f"must be a whole number >= 1, got {shown(workers)}")


def check_scheduler(address: str) -> None:
    """Raise InvalidOptions naming ``--scheduler`` unless ``address`` is one a Dask client can connect
    to: a known scheme, a host that resolves and a port (``tcp://host:8786``, or ``host:8786``). A typo
    stops the batch before any job, not in a traceback of dask's; a valid address that nobody answers
    fails when the client connects.

    Raises:
        GaussimError: dask.distributed is not installed (the message gives the install command).
    """
    try:
        from distributed.comm import parse_address, parse_host_port, resolve_address
    except ImportError:
        raise GaussimError("--scheduler needs dask.distributed: pip install 'dask[distributed]'") from None
    try:
        scheme, location = parse_address(resolve_address(address))
        port = parse_host_port(location)[1] if scheme in ("tcp", "tls") else 1
        if not 0 < port < 65536:  # dask would try it for its 30 s timeout
            raise ValueError(f"its port {port} is not one of 1 to 65535")
    except (ValueError, OSError) as err:
        cause = err.strerror if isinstance(err, OSError) and err.strerror else str(err)
        if cause.startswith("invalid literal for int()"):  # dask's reading of the port
            cause = f"its port {cause.partition(': ')[2]} is not a number"
        raise InvalidOptions(
            "--scheduler", f"{address!r}: {cause}; a Dask scheduler's address is tcp://HOST:PORT"
        ) from None


def _results(
    job: Callable[[Job], dict], todo: list[Job], workers: int | None, scheduler: Any
) -> Iterator[dict]:
    if not todo:
        return
    if scheduler is not None:
        from dask.distributed import Client
        from dask.distributed import as_completed as dask_completed

        client = Client(scheduler) if isinstance(scheduler, str) else scheduler
        futures = client.map(job, todo, pure=False)
        try:
            for future in dask_completed(futures):
                yield future.result()
        finally:  # stopped midway (Ctrl-C): the cluster drops the jobs not done
            client.cancel(futures)
            if isinstance(scheduler, str):
                client.close()
        return
    workers = workers or os.cpu_count() or 1
    if workers == 1:
        yield from map(job, todo)
        return
    pool = ProcessPoolExecutor(min(workers, len(todo)), initializer=_worker_signals)
    submitted = [pool.submit(job, item) for item in todo]
    processes = list(pool._processes.values())  # the executor names them nowhere else
    stopped = True
    try:
        for done in as_completed(submitted):
            yield done.result()
        stopped = False
    finally:
        if stopped:  # Ctrl-C, a kill of this process, an error: no job starts, the running ones stop
            _stop_workers(pool, submitted, processes)
        pool.shutdown(wait=True)


def _worker_signals() -> None:
    """A pool worker's stop signals (SIGINT, SIGTERM, SIGHUP) while no job runs: it exits quietly (the
    handler it inherits from the command raised KeyboardInterrupt in multiprocessing's loop, a traceback
    on the terminal). A job's run handles them its own way: it stops at the end of its step, its log
    kept (:mod:`gaussim.runner`)."""
    from .stops import STOP_SIGNALS

    for stop in STOP_SIGNALS:
        if signal.getsignal(stop) != signal.SIG_IGN:  # one the command ignores stays ignored
            signal.signal(stop, _quit)


def _quit(signum: int, frame: object) -> None:
    raise SystemExit(128 + signum)


def _stop_workers(pool: ProcessPoolExecutor, submitted: list[Future], processes: list[Any]) -> None:
    """Stop a pool whose batch stopped midway: cancel the jobs not started and tell each worker to stop
    (SIGTERM: a run stops at the end of its step, its log kept; an idle worker exits), again every
    STOP_WAIT until all have exited (a worker whose run took the first one is then idle). A stop signal
    that lands meanwhile (a second Ctrl-C) only makes the wait go on: the executor's own shutdown, left
    midway, hung the command at its exit on workers waiting for work."""
    for waiting in submitted:
        waiting.cancel()
    pool.shutdown(wait=False, cancel_futures=True)
    while True:
        try:
            alive = [process for process in processes if process.is_alive()]
            if not alive:
                return
            for process in alive:
                process.terminate()
            for process in alive:
                process.join(STOP_WAIT)
        except KeyboardInterrupt:
            continue
