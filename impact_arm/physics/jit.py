"""One switch for compilation: numba's ``njit(cache=True)`` when available, else plain Python.

The hot path (contact laws, generated equations, the integrator kernel) is written once in a
numba-compatible subset of Python, so the same source runs compiled or interpreted; there is no
slow twin to keep in step. Set ``IMPACT_ARM_JIT=0`` to force the interpreter (debugging,
platforms without numba). Compiled code is cached on disk, so only the first run of a scene
shape pays for compilation.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import Any, TypeVar

F = TypeVar('F', bound=Callable[..., Any])

ENABLED = os.environ.get('IMPACT_ARM_JIT', '1') != '0'


def _load_numba_without_blas():
    """Import numba's array support while ``scipy.linalg`` looks absent.

    On first use numba probes for BLAS (for ``np.dot`` & co. in compiled code) by importing
    ``scipy.linalg``: 0.2 s and ~12 MB in every process, the nodes included, for routines our
    kernels never call (they solve their small systems by hand). Hiding the module during that
    one import makes numba record "no BLAS"; it is visible again right after, so scipy works as
    usual in the same process. Skipped when numba or scipy.linalg is already loaded."""
    if 'numba.np.arraymath' in sys.modules or 'scipy.linalg' in sys.modules:
        return
    sys.modules['scipy.linalg'] = None  # type: ignore[assignment]  # import fails: no BLAS
    try:
        import numba.np.arraymath  # noqa: F401
    except ImportError:  # a numba that needs it after all: imported normally later
        pass
    finally:
        del sys.modules['scipy.linalg']


def _load_cached_without_refresh():
    """Let numba load a cached compiled function without first loading everything it would
    need to *compile* one.

    ``Cache.load_overload`` refreshes the target context before each load: it imports and
    registers numba's whole typing and lowering library (numba.cpython, np.linalg, the typed
    containers, ...): 0.09-0.14 s of a fresh process's first kernel call, for a load that
    only links machine code from the cache file. Nor does it initialise numba's
    reference-counting runtime (JIT-compiling it costs 20-30 ms): no function of this package
    uses it (``OPTIONS``). A cache miss
    still compiles with everything: numba's compiler refreshes the context itself, after
    ``_load_numba_without_blas`` (only then: a process that just loads never imports
    numba's array library, 27 ms). Only this package's functions are loaded this way."""
    from numba.core import caching

    original = caching.Cache.load_overload
    if getattr(original, '_impact_arm', False):
        return

    def load_overload(self: Any, sig: Any, target_context: Any) -> Any:
        if not getattr(self._py_func, '__module__', '').startswith('impact_arm'):
            return original(self, sig, target_context)  # other packages' functions
        loaded = None
        with self._guard_against_spurious_io_errors():
            loaded = self._load_overload(sig, target_context)
        if loaded is None:  # a compilation follows
            _load_numba_without_blas()
        return loaded

    load_overload._impact_arm = True  # type: ignore[attr-defined]  # marks our patch
    caching.Cache.load_overload = load_overload  # type: ignore[method-assign]  # the patch


UNAVAILABLE = ''  # why the kernel runs interpreted (empty when compiled)
FIX = ''  # what the user does about it
try:
    if not ENABLED:
        raise ImportError('IMPACT_ARM_JIT=0 is set')
    from numba import njit as _njit

    _load_cached_without_refresh()
    AVAILABLE = True
except ImportError as exc:  # interpreter fallback: identical code, ~100x slower
    _njit = None  # type: ignore[assignment]  # no numba: jit is the identity
    AVAILABLE = False
    UNAVAILABLE = str(exc) if not ENABLED else f'numba cannot be imported ({exc})'
    FIX = (
        'unset IMPACT_ARM_JIT'
        if not ENABLED
        else 'install numba (rosdep install --from-paths src -y, or pip install numba)'
    )


# No numba reference counting (NRT) in the hot path: with it, every array a compiled function
# handles is counted up and down with atomic instructions around each inlined call, and the
# pruning pass removes those pairs only in branch-free code. In the right-hand side (early
# returns, phase branches) they cost 4/5 of each evaluation (0.49 -> 0.09 us measured, two
# links). Functions built this way must not allocate (np.empty & co. fail to compile): the
# kernel's scratch comes from its caller (``integrator.scratch_arrays``), so no function of
# this package needs numba's runtime at all, and loading one never initialises it.
OPTIONS: dict[str, Any] = dict(cache=True, nogil=True, _nrt=False)
# Small leaf functions (force laws, control laws, generated equations) are inlined at the IR
# level into their callers: calls between compiled functions otherwise cost more than the
# arithmetic of a two-link right-hand side (measured 0.36 -> 0.21 us per call). Inlining the
# big kernel functions too would make compilation explode, so they stay plain calls.
LEAF_OPTIONS: dict[str, Any] = dict(OPTIONS, inline='always')


def jit(func: F) -> F:
    """Compile ``func`` in nopython mode with an on-disk cache (identity without numba).
    ``func`` must not allocate arrays (see OPTIONS)."""
    if _njit is None:
        return func
    return _njit(**OPTIONS)(func)


def jit_leaf(func: F) -> F:
    """Like ``jit``, and inlined into compiled callers."""
    if _njit is None:
        return func
    return _njit(**LEAF_OPTIONS)(func)


# ------------------------------------------------------------------ compile notifications
# Compiling a scene shape's kernel takes ~30 s once; the tools tell the user so. The core
# only notifies (no printing policy here): ``add_compile_hook(on_start, on_end)`` registers
# callbacks that run when the first compile (numba, or the sympy derivation) starts while none
# is running, and when the last one ends. Loads from numba's on-disk cache are not compiles.
_hooks: list[tuple[Callable[[], Any], Callable[[], Any]]] = []
_depth = [0]


def add_compile_hook(on_start: Callable[[], Any], on_end: Callable[[], Any]) -> Callable[[], Any]:
    """Register ``on_start()``/``on_end()`` around every outermost compile; returns a function
    that removes them."""
    _install_numba_listener()
    pair = (on_start, on_end)
    _hooks.append(pair)
    return lambda: pair in _hooks and _hooks.remove(pair)  # type: ignore[func-returns-value]


def compile_started() -> None:
    _depth[0] += 1
    if _depth[0] == 1:
        for on_start, _ in list(_hooks):
            on_start()


def compile_ended() -> None:
    _depth[0] = max(0, _depth[0] - 1)
    if _depth[0] == 0:
        for _, on_end in list(_hooks):
            on_end()


_listener: list[Any] = []


def _install_numba_listener():
    if _listener or _njit is None:
        return
    from numba.core import event

    class _CompileListener(event.Listener):
        def on_start(self, ev: Any) -> None:
            compile_started()

        def on_end(self, ev: Any) -> None:
            compile_ended()

    _listener.append(_CompileListener())
    event.register('numba:compile', _listener[0])
