"""What a node does with bad messages and unexpected exceptions: :class:`DropCounter` counts and
logs them (throttled), :func:`guarded` is the last-resort guard of a callback (counted, never
raised out of it), :class:`FatalNodeError` the one error that ends a node (docs/RELIABILITY.md)."""

from __future__ import annotations

import functools
import time
import traceback
from collections.abc import Callable
from typing import Any, TypeVar, cast

from rclpy.node import Node

from contgrasp_core.errors import RunFailure, interruption
from contgrasp_ros.plumbing import topics

__all__ = ["FatalNodeError", "DropCounter", "guarded", "service_failure"]

F = TypeVar("F", bound=Callable[..., Any])


class FatalNodeError(RunFailure):
    """Raised from a callback when the node cannot go on (e.g. the recorder's disk is full):
    :func:`run_node` cleans up and exits with code 1 and the message. The callback guard lets
    it through."""


class DropCounter:
    """Counts dropped messages per ``<topic>: <reason>`` and warns at most once per
    ``period_s`` wall seconds per key (saying how many were not logged).

    Unexpected exceptions caught by the callback guard are counted the same way under
    ``<where>: internal error: <ExcType>``, logged with their traceback the first time.
    ``on_first_drop`` is called after the first drop (the node's diagnostics publish at once).
    """

    def __init__(self, node: Node, period_s: float = 2.0) -> None:
        self._node = node
        self._period = period_s
        self.counts: dict[str, int] = {}
        self._last_log: dict[str, tuple[float, int]] = {}  # key -> (wall time, count then)
        self.on_first_drop: Callable[[], None] | None = None

    def stopping(self) -> bool:
        """The node's context was shut down (SIGINT/SIGTERM): failures from now on are not faults."""
        return not self._node.context.ok()

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def _absolute(self, where: str) -> str:
        """``where`` as counted and logged: a graph topic (``contgrasp/...``) by its absolute name."""
        return topics.resolve(where, self._node.get_namespace()) if where.startswith("contgrasp/") else where

    def drop(self, topic: str, reason: str, detail: str = "") -> None:
        """Count a dropped message on ``topic`` under the short ``reason``; log ``detail`` (throttled)."""
        topic = self._absolute(topic)
        key = f"{topic}: {reason}"
        self._count(key)
        self._log(key, f"dropped message on {topic}: {detail or reason}")

    def drop_error(self, topic: str, exc: Exception) -> None:
        """Count a drop for a validation/processing error: the reason is the error's ``reason``
        (:class:`~contgrasp_ros.plumbing.convert.MessageError`) or its class name."""
        self.drop(topic, getattr(exc, "reason", None) or type(exc).__name__, str(exc))

    def internal_error(self, where: str, exc: BaseException) -> None:
        """Count an unexpected exception of a callback; log it, with the traceback the first time."""
        where = self._absolute(where)
        key = f"{where}: internal error: {type(exc).__name__}"
        first = key not in self.counts
        self._count(key)
        if first:
            tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
            self._node.get_logger().error(f"internal error in {where} (the node keeps running):\n{tb}")
            self._last_log[key] = (time.monotonic(), self.counts[key])
        else:
            self._log(key, f"internal error in {where}: {type(exc).__name__}: {exc}")

    def guard(self, where: str, fn: F, on_error: Callable[[BaseException, tuple[Any, ...]], Any] | None = None) -> F:
        """``fn`` wrapped so that an unexpected exception is counted (:meth:`internal_error`) and
        ``on_error(exc, args)`` (or None) returned instead; FatalNodeError passes through."""

        @functools.wraps(fn)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            return _call_guarded(self, where, fn, args, kwargs, on_error)

        return cast(F, wrapper)

    def key_values(self) -> dict[str, str]:
        """``dropped_messages`` (total) and one ``dropped: <topic>: <reason>`` entry per key."""
        out = {"dropped_messages": str(self.total)}
        out.update({f"dropped: {key}": str(n) for key, n in sorted(self.counts.items())})
        return out

    def _count(self, key: str) -> None:
        self.counts[key] = self.counts.get(key, 0) + 1
        if self.total == 1 and self.on_first_drop is not None:
            self.on_first_drop()

    def _log(self, key: str, text: str) -> None:
        now, n = time.monotonic(), self.counts[key]
        last_t, last_n = self._last_log.get(key, (-float("inf"), 0))
        if now - last_t < self._period:
            return
        unlogged = n - last_n - 1
        more = f"; {unlogged} more since the last warning" if unlogged > 0 else ""
        self._node.get_logger().warn(f"{text} ({n} dropped for this reason, {self.total} in total{more})")
        self._last_log[key] = (now, n)


def _call_guarded(drops: DropCounter, where: str, fn: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any],
                  on_error: Callable[[BaseException, tuple[Any, ...]], Any] | None) -> Any:
    try:
        return fn(*args, **kwargs)
    except FatalNodeError:
        raise
    except Exception as exc:
        if (stop := interruption(exc)) is not None:  # (a Ctrl-C inside a compiled kernel: a stop)
            raise stop from None
        if drops.stopping():
            # SIGINT/SIGTERM shut the context down while this callback ran (its publish failed):
            # the node is stopping, not broken
            return None if on_error is None else on_error(exc, args)
        drops.internal_error(where, exc)
        return None if on_error is None else on_error(exc, args)


def guarded(where: str, on_error: Callable[[BaseException, tuple[Any, ...]], Any] | None = None) -> Callable[[F], F]:
    """Method decorator: the last-resort guard of a callback method of an object with a
    ``drops`` :class:`DropCounter` (a node, the object tracker). Direct calls are guarded too."""

    def deco(method: F) -> F:
        @functools.wraps(method)
        def wrapper(self: Any, *args: Any, **kwargs: Any) -> Any:
            return _call_guarded(self.drops, where, functools.partial(method, self), args, kwargs, on_error)

        return cast(F, wrapper)

    return deco


def service_failure(exc: BaseException, args: tuple[Any, ...]) -> Any:
    """``on_error`` for services with ``success``/``message`` responses (std_srvs): the response
    (the callback's last argument) reports the internal error."""
    resp = args[-1]
    resp.success, resp.message = False, f"internal error: {type(exc).__name__}: {exc}"
    return resp
