"""One BLAS thread for the calibration's host-side linear algebra.

What a calibration computes in NumPy (the release finder's small least-squares fits, the
amplitude test's projections, the HAC sums) is many products and solves of a few thousand
rows by a few columns. OpenBLAS splits each over every core: on a machine whose cores are
busy (a robot's other processes, a shared workstation) the main thread then waits for its
helpers to be scheduled, and a 2240 × 11 ``lstsq`` took 27–113 ms instead of 1–2 ms on one
thread (2 cores, loaded); the compiled calibration's LAPACK calls (through SciPy's OpenBLAS,
which jaxlib uses on the CPU) suffered the same. :func:`single_blas_thread` limits BLAS to one
thread while the function runs (with ``threadpoolctl``; without it, nothing changes) and
restores the user's setting after.
"""

import contextlib
import functools
import sys

_CONTROLLER: dict = {}


@contextlib.contextmanager
def one_blas_thread(*, jax_lapack: bool = False):
    """BLAS (OpenBLAS, MKL, BLIS…) on one thread within the block.

    Args:
        jax_lapack: Also the BLAS under JAX's LAPACK on the CPU (SciPy's, which jaxlib calls
            for the compiled programs' SVDs and solves): loaded first, since a limit only
            reaches the libraries already loaded. A calibration's program spent 0.26–0.70 s
            of CPU with it on two threads on a busy machine, 0.045 s on one.
    """
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:  # pragma: no cover - a dependency; the limit is only for speed
        yield
        return
    if jax_lapack:
        with contextlib.suppress(ImportError):
            import scipy.linalg.cython_lapack  # noqa: F401  (what jaxlib loads its LAPACK from)
    # Finding the loaded libraries takes milliseconds (a tenth of a warm calibration): the
    # controller is kept while no module has been imported since (a new BLAS comes with one).
    key = len(sys.modules)
    if _CONTROLLER.get("key") != key:
        _CONTROLLER.update(key=key, controller=ThreadpoolController())
    with _CONTROLLER["controller"].limit(limits=1, user_api="blas"):
        yield


def single_blas_thread(fn=None, *, jax_lapack: bool = False):
    """``fn`` run under :func:`one_blas_thread` (a decorator, with or without options)."""
    if fn is None:
        return functools.partial(single_blas_thread, jax_lapack=jax_lapack)

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with one_blas_thread(jax_lapack=jax_lapack):
            return fn(*args, **kwargs)

    return wrapper
