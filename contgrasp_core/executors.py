"""Running independent tasks serially, on a process pool or on a Dask cluster, in order.

The sweeps (:mod:`contgrasp_core.quality_map`, :mod:`contgrasp_core.holding_study`) are pure
functions of their items; :func:`run_tasks` yields their results in the items' order whatever
the executor, with a tqdm progress bar on request, so every executor gives the same results.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

from .errors import InvalidParameterError, MissingDependencyError

__all__ = ["EXECUTORS", "run_tasks"]

EXECUTORS = ("serial", "processes", "dask")

T = TypeVar("T")


def run_tasks(task: Callable[[Any], T], items: Sequence[Any], executor: str = "serial", *, workers: int | None = None,
              scheduler: str | None = None, progress: str | None = None, unit: str = "task") -> Iterator[T]:
    """``task(item)`` for each item, yielded in order as they complete in order: ``serial``,
    ``processes`` (a pool of ``workers``, forked where the platform can; interrupted or failed,
    it ends its workers at once) or ``dask`` (the cluster at ``scheduler``).
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


def _ignore_interrupts() -> None:
    """A pool worker leaves SIGINT to its parent (a terminal's Ctrl-C reaches the whole process
    group): the parent stops them, and no worker prints a KeyboardInterrupt traceback."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _results(task: Callable[[Any], T], items: Sequence[Any], executor: str, workers: int | None,
             scheduler: str | None) -> Iterator[T]:
    if executor == "serial":
        for item in items:
            yield task(item)
    elif executor == "processes":
        import multiprocessing as mp

        # fork where the platform has it (the workers inherit the loaded modules); spawn on Windows
        method = "fork" if "fork" in mp.get_all_start_methods() else "spawn"
        pool = mp.get_context(method).Pool(workers, initializer=_ignore_interrupts)
        try:
            yield from pool.imap(task, items)
        except BaseException:
            # Ctrl-C (or a failed task, or the consumer stopping): end the workers now; a pool
            # that waits for its busy workers is what made the study hang on the first Ctrl-C
            pool.terminate()
            raise
        else:
            pool.close()
        finally:
            pool.join()
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
