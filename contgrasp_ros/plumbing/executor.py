"""A single-threaded rclpy executor that keeps its wait set between waits.

rclpy's :class:`~rclpy.executors.SingleThreadedExecutor` rebuilds its wait set on every wait and
wraps every callback in a Task; :class:`LeanExecutor` gathers the entities once (again when one is
added or removed: :meth:`wake`), refills one wait set, runs every ready callback directly through
rclpy's ``_take_*`` functions (messages before timers) and looks at QoS events only every
:data:`EVENTS_PERIOD_S`. Single-threaded by design: spin it from one thread, and create or destroy
entities from that thread or while it does not spin. docs/ros.md, "Executors".
"""

from __future__ import annotations

import time
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from typing import Any

from rclpy.context import Context
from rclpy.exceptions import InvalidHandle
from rclpy.executors import Executor, ExternalShutdownException, TimeoutObject
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.task import Task
from rclpy.utilities import timeout_sec_to_nsec
from rclpy.waitable import NumberOfEntities

__all__ = ["LeanExecutor", "EVENTS_PERIOD_S"]

EVENTS_PERIOD_S = 0.1  # wall seconds between two waits that include the QoS event handlers


@dataclass
class _Entities:
    """The entities of the executor's nodes, as last gathered, and the wait set sized for them.
    ``by_pointer`` maps each kind's rcl pointers (taken when gathered: an entity destroyed since
    has none to read) to its entity."""

    subscriptions: list[Any] = field(default_factory=list)
    timers: list[Any] = field(default_factory=list)
    clients: list[Any] = field(default_factory=list)
    services: list[Any] = field(default_factory=list)
    guards: list[Any] = field(default_factory=list)  # the nodes' own guard conditions
    waitables: list[Any] = field(default_factory=list)
    by_pointer: dict[str, dict[int, Any]] = field(default_factory=dict)
    wait_set: Any = None


class LeanExecutor(Executor):
    """Single-threaded executor whose wait set is rebuilt only when the entities change."""

    def __init__(self, *, context: Context | None = None) -> None:
        super().__init__(context=context)
        self._entities: _Entities | None = None  # None: gather again before the next wait
        self._events_due = 0.0  # (monotonic time of the next wait that includes the QoS events)

    # -- changes of the entity set (rclpy's nodes call wake() when they create or destroy one)
    def wake(self) -> None:
        """Something changed (an entity, a node, a task, shutdown): gather again and wake the wait."""
        self._entities = None
        super().wake()

    def add_node(self, node: Node) -> bool:
        """Manage ``node``'s callbacks (its entities join the wait set at the next spin)."""
        self._entities = None
        return super().add_node(node)

    def remove_node(self, node: Node) -> None:
        """Stop managing ``node``'s callbacks."""
        self._entities = None
        super().remove_node(node)

    def _gather(self) -> _Entities:
        e = _Entities()
        for node in self.get_nodes():
            e.subscriptions.extend(node.subscriptions)
            e.timers.extend(node.timers)
            e.clients.extend(node.clients)
            e.services.extend(node.services)
            e.guards.extend(node.guards)
            e.waitables.extend(node.waitables)
        kinds = {"timer": e.timers, "subscription": e.subscriptions, "guard_condition": e.guards,
                 "client": e.clients, "service": e.services}
        e.by_pointer = {kind: {x.handle.pointer: x for x in entities} for kind, entities in kinds.items()}
        count = NumberOfEntities(len(e.subscriptions), len(e.guards) + 2, len(e.timers), len(e.clients), len(e.services))
        for w in e.waitables:
            count += w.get_num_entities()
        e.wait_set = _rclpy.WaitSet(count.num_subscriptions, count.num_guard_conditions, count.num_timers,
                                    count.num_clients, count.num_services, count.num_events, self._context.handle)
        return e

    # -- one turn
    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Wait up to ``timeout_sec`` (None or < 0: for ever, 0: not at all) for work and run
        every callback that is ready, then the pending tasks."""
        self._spin_once_impl(timeout_sec)

    def spin_once_until_future_complete(self, future: Any, timeout_sec: float | TimeoutObject | None = None) -> None:
        """As :meth:`spin_once` (the future's completion wakes the wait)."""
        self._spin_once_impl(timeout_sec)

    def _spin_once_impl(self, timeout_sec: float | TimeoutObject | None = None) -> None:
        if self._is_shutdown:
            return
        if self._run_tasks():  # (work already there: do not block)
            timeout_sec = 0.0
        if self._entities is None:
            self._entities = self._gather()
        e = self._entities
        ws = e.wait_set
        timeout = timeout_sec.timeout if isinstance(timeout_sec, TimeoutObject) else timeout_sec
        now = time.monotonic()
        waitables = e.waitables if now >= self._events_due else []
        if waitables:
            self._events_due = now + EVENTS_PERIOD_S
        elif e.waitables:  # (back in time for the next look at the events)
            left = max(self._events_due - now, 0.0)
            timeout = left if timeout is None or timeout < 0 else min(timeout, left)
        try:
            ws.clear_entities()
            for sub in e.subscriptions:
                ws.add_subscription(sub.handle)
            for tmr in e.timers:
                ws.add_timer(tmr.handle)
            for cli in e.clients:
                ws.add_client(cli.handle)
            for srv in e.services:
                ws.add_service(srv.handle)
            for gc in e.guards:
                ws.add_guard_condition(gc.handle)
            ws.add_guard_condition(self._guard.handle)
            ws.add_guard_condition(self._sigint_gc.handle)
            for w in waitables:
                w.add_to_wait_set(ws)
            ws.wait(timeout_sec_to_nsec(timeout))
        except InvalidHandle:  # an entity destroyed from another thread: gather again next time
            self._entities = None
            return
        if self._is_shutdown:
            return
        if not self._context.ok():
            raise ExternalShutdownException()
        self._dispatch(e, ws, waitables)
        self._run_tasks()

    def _dispatch(self, e: _Entities, ws: Any, waitables: list[Any]) -> None:
        """Run the callbacks of what the wait found ready: subscriptions, timers, guard
        conditions, clients, services (each kind in the order added), then QoS events.
        Messages before timers: a periodic callback that is due when a message arrives sees it
        (the free-running simulator's step uses the couple that answered the state before it,
        not the one before that; docs/ros.md, "Executors")."""
        ready_waitables = [w for w in waitables if w.is_ready(ws)]
        takes = (("subscription", self._take_subscription), ("timer", self._take_timer),
                 ("guard_condition", self._take_guard_condition), ("client", self._take_client),
                 ("service", self._take_service))
        for kind, take in takes:
            entities = e.by_pointer[kind]
            for pointer in ws.get_ready_entities(kind):
                entity = entities.get(pointer)  # (None: the executor's own guard conditions)
                if entity is None or not self._ready(kind, entity):
                    continue
                self._call(take(entity))
        for w in ready_waitables:
            self._call(self._take_waitable(w))

    @staticmethod
    def _ready(kind: str, entity: Any) -> bool:
        """Whether a ready entity has work: a timer that was not cancelled meanwhile (rcl reports
        cancelled timers ready), a guard condition with a callback; anything destroyed has none."""
        try:
            if kind == "timer":
                with entity.handle:  # (InvalidHandle once destroyed, e.g. by a callback earlier in this turn)
                    return bool(entity.handle.is_timer_ready())
            return kind != "guard_condition" or entity.callback is not None
        except InvalidHandle:
            return False

    def _call(self, execute: Callable[[], Coroutine[Any, Any, Any]] | None) -> None:
        """Run one taken callback to its end, or, if it awaits a future, as a task from here on."""
        if execute is None:  # (nothing taken: e.g. the entity was destroyed meanwhile)
            return
        coro = execute()
        try:
            coro.send(None)
        except StopIteration:
            return
        task = Task(coro, executor=self)  # (suspended on a future: resumed by _run_tasks)
        with self._tasks_lock:
            self._tasks.append((task, None, None))

    def _run_tasks(self) -> bool:
        """Step every pending task once (an exception propagates, as from rclpy's executors);
        True when tasks were added meanwhile (e.g. done callbacks), so the next wait must not block."""
        with self._tasks_lock:
            if not self._tasks:
                return False
            stepped = {id(t[0]) for t in self._tasks}
            tasks = [t[0] for t in self._tasks]
        try:
            for task in tasks:
                if not task.done() and not task.executing():
                    task()
                    exc = task.exception()
                    if exc is not None:
                        raise exc
        finally:
            with self._tasks_lock:
                self._tasks = [t for t in self._tasks if not t[0].done()]
                added = any(id(t[0]) not in stepped for t in self._tasks)
        return added
