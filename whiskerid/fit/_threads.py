"""One BLAS thread for the calibration's host-side linear algebra.

What a calibration computes in NumPy (the release finder's small least-squares fits, the
amplitude test's projections, the HAC sums) is many products and solves of a few thousand
rows by a few columns. OpenBLAS splits each over every core: on a machine whose cores are
busy (a robot's other processes, a shared workstation) the main thread then waits for its
helpers to be scheduled, and a 2240 × 11 ``lstsq`` took 27–113 ms instead of 1–2 ms on one
thread (2 cores, loaded). :func:`single_blas_thread` limits BLAS to one thread while the
function runs (with ``threadpoolctl``; without it, nothing changes) and restores the user's
setting after.
"""

import contextlib
import functools


@contextlib.contextmanager
def one_blas_thread():
    """BLAS (OpenBLAS, MKL, BLIS…) on one thread within the block."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - a dependency; the limit is only for speed
        yield
        return
    with threadpool_limits(1, user_api="blas"):
        yield


def single_blas_thread(fn):
    """``fn`` run under :func:`one_blas_thread`."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with one_blas_thread():
            return fn(*args, **kwargs)

    return wrapper
