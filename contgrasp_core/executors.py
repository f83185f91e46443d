"""Running independent tasks serially, on a process pool or on a Dask cluster, in order.

The sweeps (:mod:`contgrasp_core.quality_map`, :mod:`contgrasp_core.holding.study`) are pure
functions of their items; :func:`run_tasks` yields their results in the items' order whatever
the executor, with a tqdm progress bar on request, so every executor gives the same results.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, TypeVar

from .errors import InvalidParameterError, MissingDependencyError

__all__ = ["EXECUTORS", "run_tasks"]

EXECUTORS = ("serial", "processes", "dask")

T = TypeVar("T")


def run_tasks(task: Callable[[Any], T], items: Sequence[Any], executor: str = "serial", *, workers: int | None = None,
              scheduler: str | None = None, progress: str | None = None, unit: str = "task") -> Iterator[T]:
    """``task(item)`` for each item, yielded in order as they complete in order: ``serial``,
    ``processes`` (``workers`` processes, forked where the platform can; interrupted or failed,
    it ends them at once) or ``dask`` (the cluster at ``scheduler``).
    ``progress``: the description of a progress bar (None: no bar)."""
    if executor not in EXECUTORS:
        raise InvalidParameterError(f"unknown executor {executor!r}: serial, processes or dask")
    if executor == "dask" and not scheduler:
        raise InvalidParameterError("the dask executor needs a scheduler address (--scheduler tcp://host:port)")
    bar = None
    if progress is not None:
        from tqdm import tqdm

        bar = tqdm(total=len(items), desc=progress, unit=unit)
    try:
        for result in _results(task, items, executor, workers, scheduler):
            if bar:
                bar.update()
            yield result
    finally:
        if bar:
            bar.close()


def _worker(task: Callable[[Any], Any], conn: Any) -> None:
    """A pool worker: leaves SIGINT to its parent (a terminal's Ctrl-C reaches the whole process
    group; the parent ends the workers, and no worker prints a KeyboardInterrupt traceback), then
    answers ``(index, item)`` with ``(index, ok, result or exception)`` until it reads None."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    while (message := conn.recv()) is not None:
        index, item = message
        try:
            conn.send((index, True, task(item)))
        except Exception as exc:  # noqa: BLE001 - the parent raises it
            try:
                conn.send((index, False, exc))
            except Exception:  # noqa: BLE001 - an exception that does not pickle
                conn.send((index, False, RuntimeError(f"{type(exc).__name__}: {exc}")))


@contextmanager
def _interrupts_deferred() -> Iterator[None]:
    """SIGINT blocked while the workers are forked: they start with it blocked (and ignore it
    before unblocking), and a Ctrl-C meanwhile reaches the parent afterwards."""
    import signal

    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _pool_results(task: Callable[[Any], T], items: Sequence[Any], workers: int | None) -> Iterator[T]:
    """The ``processes`` executor: one pipe per worker and no lock shared between processes, so
    that ending the workers (Ctrl-C, a failed task, the consumer stopping) cannot deadlock, as
    :class:`multiprocessing.pool.Pool` can when it terminates a worker that holds its queue's lock;
    a worker that dies is reported instead of waited for."""
    import multiprocessing as mp
    import os
    from multiprocessing.connection import wait

    if not items:
        return
    # fork where the platform has it (the workers inherit the loaded modules); spawn on Windows
    ctx: Any = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
    size = max(1, min(workers or os.cpu_count() or 1, len(items)))
    procs: dict[Any, Any] = {}  # the parent's end of each worker's pipe -> its process
    finished = False
    try:
        with _interrupts_deferred():
            for _ in range(size):
                mine, theirs = ctx.Pipe()
                proc = ctx.Process(target=_worker, args=(task, theirs), daemon=True)
                proc.start()
                theirs.close()
                procs[mine] = proc
        pending = iter(enumerate(items))
        busy = set()  # the workers with an item to answer
        for conn in procs:
            conn.send(next(pending))
            busy.add(conn)
        done: dict[int, T] = {}
        following = 0
        while following < len(items):
            # (a bounded wait: a Ctrl-C that the kernel hands to another thread of this process,
            # tqdm's monitor say, leaves this thread asleep in poll(); waking twice a second lets
            # it raise the KeyboardInterrupt even then, instead of at the next answer, which
            # may be minutes away)
            ready: list[Any] = wait(list(busy), timeout=0.5)
            for conn in ready:
                try:
                    index, ok, value = conn.recv()
                except EOFError:  # its end of the pipe closed: the worker is ending
                    procs[conn].join(timeout=5)
                    raise RuntimeError(f"a worker process ended with exit code {procs[conn].exitcode} "
                                       "before answering") from None
                if not ok:
                    raise value
                done[index] = value
                following_item = next(pending, None)
                conn.send(following_item)  # None: no item left, the worker ends
                if following_item is None:
                    busy.discard(conn)
            while following in done:
                yield done.pop(following)
                following += 1
        finished = True
    finally:
        for conn, proc in procs.items():
            if not finished:  # Ctrl-C, a failed task or the consumer stopping: end the workers now
                proc.terminate()
            proc.join(timeout=5)
            if proc.is_alive():
                proc.kill()
                proc.join()
            conn.close()


def _results(task: Callable[[Any], T], items: Sequence[Any], executor: str, workers: int | None,
             scheduler: str | None) -> Iterator[T]:
    if executor == "serial":
        for item in items:
            yield task(item)
    elif executor == "processes":
        yield from _pool_results(task, items, workers)
    else:
        try:
            from distributed import Client
        except ModuleNotFoundError as exc:
            raise MissingDependencyError(
                f"the dask executor needs dask.distributed (module {exc.name!r} is missing): pip install 'contgrasp[dist]'"
            ) from exc

        with Client(scheduler) as client:
            futures = client.map(task, list(items), pure=False)
            for fut in futures:  # keep the items' order
                yield fut.result()
