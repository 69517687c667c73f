"""One switch for compilation: numba's ``njit(cache=True)`` when available, else plain Python.

The hot path (contact laws, generated equations, the integrator kernel) is written once in a
numba-compatible subset of Python, so the same source runs compiled or interpreted; there is no
slow twin to keep in step. Set ``IMPACT_ARM_JIT=0`` to force the interpreter (debugging,
platforms without numba). Compiled code is cached on disk, so only the first run of a scene
shape pays for compilation.
"""
import os
import sys

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
    sys.modules['scipy.linalg'] = None
    try:
        import numba.np.arraymath  # noqa: F401
    except ImportError:     # a numba that needs it after all: imported normally later
        pass
    finally:
        del sys.modules['scipy.linalg']


COMPILED = set()     # generated kernel modules compiled (not loaded from cache) in this process


def _announce_compilation(func):
    """One line on stderr when a scene shape's kernel is compiled rather than loaded: the
    first run of a new arm shape otherwise sits silent for tens of seconds."""
    module = sys.modules.get(getattr(func, '__module__', ''))
    if module is None or not module.__name__.startswith('impact_arm_kernel_') \
            or module.__name__ in COMPILED:
        return
    COMPILED.add(module.__name__)
    features = [name for flag, name in ((module.HAS_CONTACT, 'contact'),
                                        (module.HAS_FRICTION, 'friction')) if flag]
    sys.stderr.write(f'impact_arm: compiling the simulation kernel for a {module.N}-link arm'
                     f'{" with " + " and ".join(features) if features else ""} (first use of '
                     f'this shape: ~10-30 s; cached in {os.path.dirname(module.__file__)})\n')
    sys.stderr.flush()


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

    def load_overload(self, sig, target_context):
        if not getattr(self._py_func, '__module__', '').startswith('impact_arm'):
            return original(self, sig, target_context)    # other packages' functions
        loaded = None
        with self._guard_against_spurious_io_errors():
            loaded = self._load_overload(sig, target_context)
        if loaded is None:      # a compilation follows
            _load_numba_without_blas()
            _announce_compilation(self._py_func)
        return loaded
    load_overload._impact_arm = True
    caching.Cache.load_overload = load_overload


UNAVAILABLE = ''     # why the kernel runs interpreted (empty when compiled)
FIX = ''             # what the user does about it
try:
    if not ENABLED:
        raise ImportError('IMPACT_ARM_JIT=0 is set')
    from numba import njit as _njit
    _load_cached_without_refresh()
    AVAILABLE = True
except ImportError as exc:  # interpreter fallback: identical code, ~100x slower
    _njit = None
    AVAILABLE = False
    UNAVAILABLE = str(exc) if not ENABLED else f'numba cannot be imported ({exc})'
    FIX = ('unset IMPACT_ARM_JIT' if not ENABLED else
           'install numba (rosdep install --from-paths src -y, or pip install numba)')


# No numba reference counting (NRT) in the hot path: with it, every array a compiled function
# handles is counted up and down with atomic instructions around each inlined call, and the
# pruning pass removes those pairs only in branch-free code. In the right-hand side (early
# returns, phase branches) they cost 4/5 of each evaluation (0.49 -> 0.09 us measured, two
# links). Functions built this way must not allocate (np.empty & co. fail to compile): the
# kernel's scratch comes from its caller (``integrator.scratch_arrays``), so no function of
# this package needs numba's runtime at all, and loading one never initialises it.
OPTIONS = dict(cache=True, nogil=True, _nrt=False)
# Small leaf functions (force laws, control laws, generated equations) are inlined at the IR
# level into their callers: calls between compiled functions otherwise cost more than the
# arithmetic of a two-link right-hand side (measured 0.36 -> 0.21 us per call). Inlining the
# big kernel functions too would make compilation explode, so they stay plain calls.
LEAF_OPTIONS = dict(OPTIONS, inline='always')


def jit(func):
    """Compile ``func`` in nopython mode with an on-disk cache (identity without numba).
    ``func`` must not allocate arrays (see OPTIONS)."""
    if _njit is None:
        return func
    return _njit(**OPTIONS)(func)


def jit_leaf(func):
    """Like ``jit``, and inlined into compiled callers."""
    if _njit is None:
        return func
    return _njit(**LEAF_OPTIONS)(func)

