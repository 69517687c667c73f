"""The fit's figures drawn by a second process, forked before the fit.

Importing matplotlib takes a third of a second of a fresh ``impact-arm fit``; the forked
process does it on the other core while this one reads the recording and fits, and then only
draws what it is sent (``FigureData``: plain arrays, no model). When the process cannot be
forked (no ``fork`` on the platform, or threads running in this process, which a fork could
leave holding a lock) or fails, the figures are drawn here, as they would be without it: the
files are the same either way.
"""

from __future__ import annotations

import multiprocessing
import signal
import sys
import threading
from typing import Any


def _serve(conn: Any) -> None:
    """The forked process: import the drawing library, then draw each (data, out) it is sent
    and answer ('ok', paths) or ('error', why) until told to stop (None) or the pipe closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    from .fit import draw_figures

    try:
        import matplotlib.backends.backend_agg  # noqa: F401  # the import this process is for
        import matplotlib.figure  # noqa: F401
    except ImportError:
        pass  # draw_figures says so, in whichever process draws
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        data, out = job
        try:
            conn.send(('ok', draw_figures(data, out)))
        except Exception as exc:  # noqa: BLE001 - the parent draws again and raises it there
            conn.send(('error', f'{type(exc).__name__}: {exc}'))


class FigureProcess:
    """``start()`` forks the drawing process (None when it cannot); ``submit(data, out)``
    hands it the figures, ``result()`` waits for their paths; ``close()`` ends it."""

    def __init__(self, process: Any, conn: Any) -> None:
        self._process = process
        self._conn = conn
        self._job: tuple | None = None

    @classmethod
    def start(cls) -> FigureProcess | None:
        if not sys.platform.startswith('linux') or threading.active_count() > 1:
            return None  # fork is only safe without other threads (and is POSIX's)
        try:
            context = multiprocessing.get_context('fork')
            parent, child = context.Pipe()
            process = context.Process(target=_serve, args=(child,), daemon=True)
            process.start()
        except (OSError, ValueError):
            return None
        child.close()
        return cls(process, parent)

    def submit(self, data: Any, out: str) -> None:
        self._job = (data, out)
        try:
            self._conn.send(self._job)
        except (OSError, ValueError):
            pass  # result() draws them here

    def result(self) -> list:
        """The figures' paths, drawn by the process, or here if it could not."""
        from .fit import draw_figures

        assert self._job is not None, 'submit() first'
        try:
            status, answer = self._conn.recv()
        except (EOFError, OSError):
            status, answer = 'error', 'the drawing process ended'
        if status == 'ok':
            return answer
        return draw_figures(*self._job)  # the same files, or the real error, from here

    def close(self) -> None:
        """End the process (idle once its answer is read; still importing or drawing when
        this process gave up on it: refused input, an error, Ctrl-C)."""
        self._process.terminate()
        self._process.join()
        self._conn.close()
