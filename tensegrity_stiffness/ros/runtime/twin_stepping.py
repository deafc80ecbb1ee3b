"""The stepping thread of the MuJoCo twins' nodes (``sim_node``, ``structure_sim_node``): paced
by the wall clock on absolute deadlines (steps due by more than one period are caught up at once
and counted missed) or as fast as possible, publishing every ``sim.publish_every`` steps, stopped
cleanly (the context's shutdown, the runner's :meth:`SteppingTwin.close`, at the latest at
exit), and guarded: an exception ends the thread with an internal-error log line instead of
silently. Only the stepping thread touches the simulation."""

from __future__ import annotations

import atexit
import threading
import time
from typing import Any

from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.runtime.pacing import periods_due, wait_until


class SteppingTwin:
    """Mixin of a twin node (an rclpy ``Node`` with a ``reporter``, ``_settings.values``
    holding ``sim.publish_every``, a ``_sim`` with ``time``, ``_period`` (s) and
    ``_real_time``): :meth:`_start_stepping` starts the thread, which calls :meth:`_advance`
    (``n`` steps under the current inputs, counted in ``steps``) and :meth:`_publish_due` each
    time ``steps`` crosses a multiple of ``sim.publish_every``; ``missed_steps`` counts the
    periods caught up late in real time."""

    steps: int
    missed_steps: int
    _period: float
    _real_time: bool
    _settings: Any
    _sim: Any
    reporter: Any

    def _advance(self, n: int) -> None:
        """``n`` steps of the twin under the current inputs (``steps`` counts them)."""
        raise NotImplementedError

    def _publish_due(self) -> None:
        """What the twin publishes every ``sim.publish_every`` steps."""
        raise NotImplementedError

    def _start_stepping(self, name: str) -> None:
        """Start the stepping thread ``name`` (at the end of the node's ``__init__``)."""
        self.steps = 0
        self.missed_steps = 0
        self._stop = threading.Event()
        self.context.on_shutdown(self._stop.set)  # SIGINT shuts the context down first
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()
        atexit.register(self.close)  # as the fast lane's: no publishing thread at finalization

    def close(self) -> None:
        """Stop the stepping thread (called by the runner before the node is destroyed, at the
        latest at exit, again if it outlived the join here)."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        if not self._thread.is_alive():
            atexit.unregister(self.close)

    def _run(self) -> None:
        """The stepping loop: real time (absolute deadlines; a step whose deadline has passed by
        a whole period is caught up at once and counted missed) or as fast as possible."""
        try:
            start = time.perf_counter()
            while not self._stop.is_set() and self.context.ok():
                n = 1
                if self._real_time:
                    now = wait_until(start + (self.steps + 1) * self._period)
                    n = periods_due(start, self.steps, self._period, now)
                    self.missed_steps += n - 1
                before = self.steps
                self._advance(n)
                every = self._settings.values['sim.publish_every']
                if self.steps // every != before // every:
                    self._publish_due()
        except Exception as exc:  # the stepping thread must not die silently
            if self.context.ok() and not self._stop.is_set():
                self.reporter.internal_error('stepping', exc)

    def _stamp(self) -> Any:
        """The stamp of a publication: the wall clock in real time, else the simulated time
        (the twin publishes it on ``/clock``)."""
        if self._real_time:
            return self.get_clock().now().to_msg()
        return conversions.stamp_from_seconds(self._sim.time)


__all__ = ['SteppingTwin']
