"""The one progress line the user tools print on stderr.

On a terminal the line is rewritten in place and, when the amount of work is known, ends with
the fraction done and an estimate of the time left. Elsewhere (logs, pipes, CI) rewriting would
pile up, so only the updates the caller marks as worth a line (``log=True``) are printed, one
per line, without ETA noise.
"""
from __future__ import annotations

import sys
import time


class Progress:
    """``show(text, done=None, log=False)`` as work advances; ``end()`` once.

    ``total``: the amount of work (same unit as ``done``), or None if unknown. ``prefix``
    starts every line. ``keep``: on a terminal, leave the last line visible at ``end()``
    (else it is erased). ``stream``/``clock`` are for tests."""

    def __init__(self, total=None, prefix='', keep=False, stream=None, clock=time.monotonic):
        self.total = total
        self.prefix = prefix
        self.keep = keep
        self.stream = sys.stderr if stream is None else stream
        self.clock = clock
        self.started = clock()
        self.tty = self.stream.isatty()
        self.shown = False

    def eta(self, done) -> str:
        """' 40 %  ETA 12 s' from the average pace so far ('' while it cannot be told)."""
        if not self.total or done is None or done <= 0:
            return ''
        fraction = min(done / self.total, 1.0)
        left = (self.clock() - self.started) * (1.0 - fraction) / fraction
        return f'  {100 * fraction:3.0f} %  ETA {_duration(left)}'

    def show(self, text: str, done=None, log: bool = False) -> None:
        if self.tty:
            self.stream.write(f'\r\033[K{self.prefix}{text}{self.eta(done)}')
            self.stream.flush()
            self.shown = True
        elif log:
            print(f'{self.prefix}{text}', file=self.stream, flush=True)

    def end(self) -> None:
        """Finish the terminal line (kept or erased); nothing to do off a terminal."""
        if self.tty and self.shown:
            self.stream.write('\n' if self.keep else '\r\033[K')
            self.stream.flush()
            self.shown = False


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    if seconds < 60:
        return f'{seconds} s'
    minutes, seconds = divmod(seconds, 60)
    if minutes < 60:
        return f'{minutes} min {seconds:02d} s'
    return f'{minutes // 60} h {minutes % 60:02d} min'
