"""One switch for compilation: numba's ``njit(cache=True)`` when available, else plain Python.

The hot path (contact laws, generated equations, the integrator kernel) is written once in a
numba-compatible subset of Python, so the same source runs compiled or interpreted; there is no
slow twin to keep in step. Set ``IMPACT_ARM_JIT=0`` to force the interpreter (debugging,
platforms without numba). Compiled code is cached on disk, so only the first run of a scene
shape pays for compilation.
"""
import os

ENABLED = os.environ.get('IMPACT_ARM_JIT', '1') != '0'

try:
    if not ENABLED:
        raise ImportError
    from numba import njit as _njit
    AVAILABLE = True
except ImportError:  # interpreter fallback: identical code, slower
    _njit = None
    AVAILABLE = False


def jit(func):
    """Compile ``func`` in nopython mode with an on-disk cache (identity without numba)."""
    if _njit is None:
        return func
    return _njit(cache=True, nogil=True)(func)
