"""One BLAS thread for the rod engine's small dense solves.

The implicit step solves a dense (N x N) Newton system a few times per step, N ~ 100: a
multi-threaded BLAS gains nothing at that size, and on a busy machine (other processes, the
graph's own nodes) its threads wait for cores: measured 15-17x slower per step with OpenBLAS's
default threads under load 6 on 2 cores. Runs and node processes therefore use one thread.
"""

from __future__ import annotations

import contextlib
from typing import Any

__all__ = ["single_thread_blas"]


def single_thread_blas() -> contextlib.AbstractContextManager[Any]:
    """A context (also usable for a whole process: keep the returned object) limiting BLAS to one
    thread, via :mod:`threadpoolctl` (a dependency; a no-op without it)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")
