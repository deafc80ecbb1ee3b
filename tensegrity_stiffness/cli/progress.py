"""Progress of long computations on stderr, drawn by tqdm, only when stderr is a terminal."""

from __future__ import annotations

import sys
from typing import TextIO

from tqdm import tqdm


class ProgressBar:
    """``progress(done, total)`` shown as a tqdm bar (label, percent, done/total, elapsed, time
    left, rate in ``unit``/s) on ``stream`` (stderr by default), only when the stream is a
    terminal; the line ends when ``done`` reaches ``total`` or at :meth:`finish`."""

    def __init__(self, label: str, unit: str = 'it', stream: TextIO | None = None) -> None:
        self.label = label
        self.unit = unit
        self.stream = sys.stderr if stream is None else stream
        isatty = getattr(self.stream, 'isatty', None)
        self.enabled = bool(isatty()) if callable(isatty) else False
        self._bar: tqdm | None = None
        self._closed = False

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled or self._closed:
            return
        if self._bar is None:
            self._bar = tqdm(total=total, desc=self.label, unit=self.unit, file=self.stream,
                             leave=True)
        elif self._bar.total != total:
            self._bar.total = total
        self._bar.update(done - self._bar.n)
        if done >= total:
            self.finish()

    def finish(self) -> None:
        """End the bar's line (nothing if nothing was drawn); later calls draw nothing."""
        if self._bar is not None and not self._closed:
            self._bar.close()
        self._closed = True
