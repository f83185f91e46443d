"""One BLAS thread for the rod engine's small dense solves.

The implicit step solves a dense (N x N) Newton system a few times per step, N ~ 100: a
multi-threaded BLAS gains nothing at that size, and on a busy machine its threads wait for
cores: measured on 2 shared cores, N = 100 150 us vs 60 us per solve, N = 200 190 ms vs 0.29 ms,
and a whole lock-step step 15-17x slower at load 6. :meth:`RodSystem.advance
<contgrasp_core.rod.integrator.RodSystem.advance>` therefore solves dense systems on one thread,
whoever calls it (the core loops, the ROS simulator, a notebook); the structured solve of
:mod:`contgrasp_core.rod.newton_matrix` (the compiled kernels without a movable object or
stick-slip friction) calls no BLAS.
"""

from __future__ import annotations

import contextlib
from typing import Any

__all__ = ["single_thread_blas"]

_CONTROLLER: list[Any] = []  # threadpoolctl's controller, made once (finding the libraries costs ms)


def single_thread_blas() -> contextlib.AbstractContextManager[Any]:
    """A context limiting BLAS to one thread (:mod:`threadpoolctl`; a no-op without it: a ROS
    install from rosdep lacks it, since rosdep has no key for it)."""
    try:
        if not _CONTROLLER:
            from threadpoolctl import ThreadpoolController

            _CONTROLLER.append(ThreadpoolController())
    except ImportError:
        return contextlib.nullcontext()
    return _CONTROLLER[0].limit(limits=1, user_api="blas")
