"""The fit command's second process: it reads the recording, then draws the figures.

A fresh ``impact-arm fit`` spends a third of a second importing the optimiser (scipy) and
another third importing the figures' library (matplotlib), each before the step that needs it.
A process forked at the start takes what needs neither off the critical path: it reads the
recording while this one imports the optimiser, sends it back, imports matplotlib while this
one fits, and then only draws what it is sent (``FigureData``: plain arrays, no model). It
runs nothing of the compiled model: a first run's compilation stays in one process, with one
notice. When the process cannot be forked (no ``fork`` on the platform, or threads
running in this process, which a fork could leave holding a lock) or fails, the same work is
done here: the results and files are the same either way, and a refusal of the recording
(``ImpactArmError``) is raised here as it was raised there.
"""

from __future__ import annotations

import multiprocessing
import signal
import sys
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Generic, TypeVar

from ..physics.errors import ImpactArmError

if TYPE_CHECKING:
    from multiprocessing.connection import Connection
    from multiprocessing.process import BaseProcess

    from .fit_figures import FigureData

T = TypeVar('T')  # what the process's first job returns


def _serve(conn: Connection, first: Callable[[], Any]) -> None:
    """The forked process: ``first()`` answered as ('ok', value) or ('refused', error), then
    the drawing library imported, then each (data, out) it is sent drawn and answered
    ('ok', paths), until told to stop (None) or the pipe closes. Anything else that fails
    is answered ('failed', why): the parent then does that work itself."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    try:
        conn.send(('ok', first()))
    except ImpactArmError as exc:
        conn.send(('refused', exc))
        return
    except Exception as exc:  # noqa: BLE001 - the parent does it again, and raises it there
        conn.send(('failed', f'{type(exc).__name__}: {exc}'))
    from .fit_figures import draw_figures

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
            conn.send(('failed', f'{type(exc).__name__}: {exc}'))


def other_threads() -> list[str]:
    """The names of this process's threads besides the main one: fork is only safe without
    them (a child would inherit their locks held)."""
    return [t.name for t in threading.enumerate() if t is not threading.main_thread()]


class SideProcess(Generic[T]):
    """``start(first)`` forks the process, which runs ``first`` (None when it cannot fork);
    ``first_result()`` is its value; ``submit(data, out)`` hands it the figures,
    ``figures()`` waits for their paths; ``close()`` ends it."""

    def __init__(self, process: BaseProcess, conn: Connection, first: Callable[[], T]) -> None:
        self._process = process
        self._conn = conn
        self._first = first
        self._job: tuple[FigureData, str] | None = None

    @classmethod
    def start(cls, first: Callable[[], T]) -> SideProcess[T] | None:
        if not sys.platform.startswith('linux') or other_threads():
            return None  # fork is only safe without other threads (and is POSIX's)
        try:
            context = multiprocessing.get_context('fork')
            parent, child = context.Pipe()
            process = context.Process(target=_serve, args=(child, first), daemon=True)
            process.start()
        except (OSError, ValueError):
            return None
        child.close()
        return cls(process, parent, first)

    def _answer(self) -> tuple[str, Any]:
        try:
            return self._conn.recv()
        except (EOFError, OSError):
            return 'failed', 'the side process ended'

    def first_result(self) -> T:
        """``first()``'s value from the process, its refusal raised here, or, if the process
        failed, ``first()`` run here."""
        status, answer = self._answer()
        if status == 'ok':
            return answer
        if status == 'refused':
            raise answer
        return self._first()

    def submit(self, data: FigureData, out: str) -> None:
        self._job = (data, out)
        try:
            self._conn.send(self._job)
        except (OSError, ValueError):
            pass  # figures() draws them here

    def figures(self) -> list[str]:
        """The figures' paths, drawn by the process, or here if it could not."""
        from .fit_figures import draw_figures

        assert self._job is not None, 'submit() first'
        status, answer = self._answer()
        if status == 'ok':
            return answer
        return draw_figures(*self._job)  # the same files, or the real error, from here

    def close(self) -> None:
        """End the process (idle once its answer is read; still at work when this process
        gave up on it: refused input, an error, Ctrl-C)."""
        self._process.terminate()
        self._process.join()
        self._conn.close()
