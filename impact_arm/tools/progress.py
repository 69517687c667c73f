"""The one progress line the user tools print on stderr.

On a terminal the line is rewritten in place and, when the amount of work is known, ends with
the fraction done and an estimate of the time left. Elsewhere (logs, pipes, CI) rewriting would
pile up, so only the updates the caller marks as worth a line (``log=True``) are printed, one
per line, without ETA noise.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from typing import Any, Literal, TextIO


class _Screen:
    """The terminal shared by the progress lines and the compile notice: while a notice is
    open (from its first line to its last), progress output waits and follows it, so the two
    never interleave (the notice's counter runs in a thread of its own)."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.held = False
        self.waiting: list[tuple[TextIO, str]] = []  # (stream, text) of log lines held back
        # (progress, stream, text) of the terminal line last drawn
        self.line: tuple[Progress, TextIO, str] | None = None

    def hold(self) -> None:
        with self.lock:
            self.held = True

    def release(self) -> None:
        """After the notice's last line: the held log lines, then the last terminal line."""
        with self.lock:
            self.held = False
            for stream, text in self.waiting:
                stream.write(text)
                stream.flush()
            self.waiting = []
            if self.line is not None:
                progress, stream, text = self.line
                if progress.shown:
                    stream.write(text)
                    stream.flush()


SCREEN = _Screen()


class Progress:
    """``show(text, done=None, log=False)`` as work advances; ``end()`` once.

    ``total``: the amount of work (same unit as ``done``), or None if unknown. ``prefix``
    starts every line. ``keep``: on a terminal, leave the last line visible at ``end()``
    (else it is erased). ``stream``/``clock`` are for tests."""

    def __init__(
        self,
        total: float | None = None,
        prefix: str = '',
        keep: bool = False,
        stream: TextIO | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.total = total
        self.prefix = prefix
        self.keep = keep
        self.stream = sys.stderr if stream is None else stream
        self.clock = clock
        self.started = clock()
        self.tty = self.stream.isatty()
        self.shown = False

    def eta(self, done: float | None) -> str:
        """' 40 %  ETA 12 s' from the average pace so far ('' while it cannot be told)."""
        if not self.total or done is None or done <= 0:
            return ''
        fraction = min(done / self.total, 1.0)
        left = (self.clock() - self.started) * (1.0 - fraction) / fraction
        return f'  {100 * fraction:3.0f} %  ETA {_duration(left)}'

    def show(self, text: str, done: float | None = None, log: bool = False) -> None:
        with SCREEN.lock:
            if self.tty:
                line = f'\r\033[K{self.prefix}{text}{self.eta(done)}'
                SCREEN.line = (self, self.stream, line)
                self.shown = True
                if not SCREEN.held:  # else drawn when the compile notice ends
                    self.stream.write(line)
                    self.stream.flush()
            elif log:
                line = f'{self.prefix}{text}\n'
                if SCREEN.held:
                    SCREEN.waiting.append((self.stream, line))
                else:
                    self.stream.write(line)
                    self.stream.flush()

    def end(self) -> None:
        """Finish the terminal line (kept or erased); nothing to do off a terminal."""
        with SCREEN.lock:
            if self.tty and self.shown:
                self.shown = False
                if SCREEN.held:  # the notice holds the line: keep it as a finished one
                    if self.keep and SCREEN.line and SCREEN.line[0] is self:
                        SCREEN.waiting.append((self.stream, SCREEN.line[2] + '\n'))
                else:
                    self.stream.write('\n' if self.keep else '\r\033[K')
                    self.stream.flush()
                if SCREEN.line and SCREEN.line[0] is self:
                    SCREEN.line = None


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    if seconds < 60:
        return f'{seconds} s'
    minutes, seconds = divmod(seconds, 60)
    if minutes < 60:
        return f'{minutes} min {seconds:02d} s'
    return f'{minutes // 60} h {minutes % 60:02d} min'


COMPILE_NOTICE = 'compiling the kernel for this scene shape (one time, ~30 s)'


class CompileNotice:
    """Says on stderr when the core compiles (numba, sympy) instead of loading its cache: one
    line ``compiling the kernel ... (one time, ~30 s)`` with the elapsed seconds (rewritten in
    place on a terminal, every 10 s elsewhere) and ``compiled in N s`` once no compile has
    followed for ``SETTLE`` seconds (a first run compiles in a few bursts: one notice for
    all). A compile that is over within a second says nothing. Use as a context manager."""

    QUIET = 1.0  # s: shorter compiles are not worth a line
    SETTLE = 1.5  # s without a compile before the notice ends
    LOG_EVERY = 10.0  # s between lines off a terminal

    def __init__(
        self,
        stream: TextIO | None = None,
        clock: Callable[[], float] = time.monotonic,
        prefix: str = '',
    ) -> None:
        self.stream = sys.stderr if stream is None else stream
        self.clock = clock
        self.prefix = prefix
        self.tty = self.stream.isatty()
        self.total = 0.0  # s compiled in this process so far
        self._burst_start: float | None = None  # start of the compile running now
        self._first: float | None = None  # start of the first compile of this notice
        self._idle_since: float | None = None  # end of the last compile (None while one runs)
        self._compiled = 0.0  # s compiled within this notice
        self._shown = False
        self._logged = 0.0
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._remove: Callable[[], Any] | None = None

    def __enter__(self) -> CompileNotice:
        from ..physics import jit

        self._remove = jit.add_compile_hook(self._start, self._end)
        return self

    def __exit__(self, *exc: object) -> Literal[False]:
        if self._remove is not None:
            self._remove()
        with self._lock:
            if self._burst_start is not None:
                self._close_burst()
            self._finish()
        return False

    def _start(self) -> None:
        with self._lock:
            self._burst_start = self.clock()
            self._idle_since = None
            if self._first is None:
                self._first = self._burst_start
                self._compiled, self._shown, self._logged = 0.0, False, 0.0
                self._thread = threading.Thread(target=self._tick, daemon=True)
                self._thread.start()

    def _end(self) -> None:
        with self._lock:
            if self._burst_start is not None:
                self._close_burst()

    def _close_burst(self) -> None:
        assert self._burst_start is not None, 'called with a compile running'
        elapsed = self.clock() - self._burst_start
        self._compiled += elapsed
        self.total += elapsed
        self._burst_start = None
        self._idle_since = self.clock()

    def _finish(self) -> None:
        """End the notice (lock held): the closing line if the opening one was shown."""
        if self._first is None:
            return
        if self._shown:
            self._write(
                f'{COMPILE_NOTICE}: compiled in {self._compiled:.0f} s, cached for next time',
                final=True,
            )
            SCREEN.release()
        self._first, self._idle_since, self._shown = None, None, False

    def _tick(self) -> None:
        while True:
            time.sleep(0.5 if self.tty else 1.0)
            with self._lock:
                if self._first is None:
                    return
                now = self.clock()
                if self._idle_since is not None and now - self._idle_since >= self.SETTLE:
                    self._finish()
                    return
                elapsed = now - self._first
                if self._idle_since is not None or elapsed < self.QUIET:
                    continue
                if not self._shown:
                    self._shown = True
                    SCREEN.hold()
                    self._logged = elapsed
                    self._write(f'{COMPILE_NOTICE} ...' + (f' {elapsed:.0f} s' if self.tty else ''))
                elif self.tty:
                    self._write(f'{COMPILE_NOTICE} ... {elapsed:.0f} s')
                elif elapsed - self._logged >= self.LOG_EVERY:
                    self._logged = elapsed
                    self._write(f'  ... {elapsed:.0f} s')

    def _write(self, text: str, final: bool = False) -> None:
        with SCREEN.lock:
            self._write_now(text, final)

    def _write_now(self, text: str, final: bool) -> None:
        if self.tty:
            self.stream.write(f'\r\033[K{self.prefix}{text}' + ('\n' if final else ''))
        else:
            self.stream.write(f'{self.prefix}{text}\n')
        self.stream.flush()
