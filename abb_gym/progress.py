"""One progress bar for the whole package: tqdm on a terminal, a few plain lines in a log.

Every bar of abb-gym is a :class:`ProgressBar` (tests/test_progress.py checks that no module
makes a tqdm bar of its own).  On a terminal it is tqdm's bar, redrawn in place.  When its
output is not a terminal (a log file, a pipe, CI, a notebook's captured stderr), tqdm would
write every redraw with a carriage return into one long line of the log, about a hundred
updates per bar; there the bar writes plain lines instead, each ending in a newline: one at
each quarter of its total and one when it closes (none twice for the same count), and, while
it runs, one when :data:`FIRST_LINE_AFTER` seconds passed without a line, the wait doubling
after each such line up to :data:`LINE_INTERVAL` (an hour of work writes about a dozen
lines).  A bar without a total writes the time-based lines and its end.  A bar that is done
within seconds writes one line.

``ABB_GYM_PROGRESS=lines`` or ``=bar`` forces either form (``lines`` makes a terminal log
readable, ``bar`` keeps tqdm's redraws in a pseudo-terminal that does not say it is one).
"""
from __future__ import annotations

import os
import sys
import time

from tqdm import tqdm

__all__ = ["ProgressBar", "LINE_INTERVAL", "LINE_FRACTIONS", "writes_lines"]

#: [s] a line-mode bar that wrote no line for this long writes one (then waits twice as long)
FIRST_LINE_AFTER = 30.0
#: [s] the longest a line-mode bar stays silent while it runs
LINE_INTERVAL = 600.0
#: the fractions of its total at which a line-mode bar writes a line (and at its close)
LINE_FRACTIONS = (0.25, 0.5, 0.75, 1.0)
#: a line-mode bar shows no bar graphic: the count, the share, the times and the rate
LINE_FORMAT = "{desc}: {percentage:3.0f}% {n_fmt}/{total_fmt} [{elapsed}<{remaining}, " \
              "{rate_fmt}{postfix}]"
LINE_FORMAT_NO_TOTAL = "{desc}: {n_fmt} [{elapsed}, {rate_fmt}{postfix}]"


def writes_lines(file=None) -> bool:
    """True if a bar writing to ``file`` (default stderr) writes plain lines: not a
    terminal, or ``ABB_GYM_PROGRESS=lines``."""
    forced = os.environ.get("ABB_GYM_PROGRESS", "").strip().lower()
    if forced in ("lines", "bar"):
        return forced == "lines"
    stream = sys.stderr if file is None else file
    try:
        return not stream.isatty()
    except (AttributeError, ValueError, OSError):  # no isatty, or a closed stream
        return True


class ProgressBar(tqdm):
    """tqdm's bar, or plain lines when the output is not a terminal (module docstring).
    Takes tqdm's arguments."""

    def __init__(self, *args, **kwargs):
        # set before tqdm's constructor, which draws the bar's first state
        self._lines = writes_lines(kwargs.get("file")) and not kwargs.get("disable")
        self._line_n: float | None = None  # the count of the last line written
        self._line_t = time.monotonic()
        self._wait = FIRST_LINE_AFTER
        self._next_fraction = 0
        if self._lines and kwargs.get("bar_format") is None:
            has_total = kwargs.get("total") is not None or _has_length(args, kwargs)
            kwargs["bar_format"] = LINE_FORMAT if has_total else LINE_FORMAT_NO_TOTAL
        super().__init__(*args, **kwargs)

    def _line_due(self) -> bool:
        if self.n == self._line_n:
            return False
        if self.total:
            due = False
            while (self._next_fraction < len(LINE_FRACTIONS)
                   and self.n >= LINE_FRACTIONS[self._next_fraction] * self.total):
                self._next_fraction += 1
                due = True
            if due:
                return True
        if time.monotonic() - self._line_t >= self._wait:
            self._wait = min(2.0 * self._wait, LINE_INTERVAL)
            return True
        return False

    def _write_line(self) -> None:
        self.fp.write(self.__str__() + "\n")
        getattr(self.fp, "flush", lambda: None)()
        self._line_n = self.n
        self._line_t = time.monotonic()

    def display(self, msg=None, pos=None):
        if not self._lines:
            return super().display(msg, pos)
        if msg is None and self._line_due():  # msg '' clears a terminal bar: no line
            self._write_line()
        return True

    def clear(self, nolock=False):
        if not self._lines:
            super().clear(nolock)

    def close(self):
        if getattr(self, "_lines", False) and not getattr(self, "disable", True) \
                and hasattr(self, "sp"):
            with self._lock:
                if self.n != self._line_n:
                    self._ema_dt = lambda: None  # the overall rate, as tqdm's own close
                    self._write_line()
            self.sp = None  # tqdm's close then writes nothing more
        super().close()


def _has_length(args, kwargs) -> bool:
    iterable = args[0] if args else kwargs.get("iterable")
    return iterable is not None and hasattr(iterable, "__len__")
