"""Sessions spread over a Ray cluster (the optional ``fleet`` extra: ``pip install
"whiskerid[fleet]"``).

Each task fits a chunk of sessions with :func:`whiskerid.fleet.fit_sessions`, the very
function and the same chunks the local run uses, so the numbers are the same either way. The
workers read the recordings by path (on a cluster of several machines the fleet's folder
must be mounted at the same path on each); the results come back to this process, which
alone writes the records and the table.
"""

import contextlib
import os
import sys
from collections.abc import Iterator

from ._calibrate import SESSION_CHUNK, FleetError, FleetSettings, fit_sessions
from ._layout import Session


def ray_runner(address: str = "auto", *, num_cpus: int | None = None, chunk: int = SESSION_CHUNK):
    """A runner for :func:`whiskerid.fleet.calibrate_fleet` that uses Ray.

    A cluster named by ``address`` (``auto`` or an address) is joined here, before anything
    is fitted or written, so that a cluster that is not there stops the run at once with one
    line.

    Args:
        address: ``auto`` (the cluster this machine belongs to, as ``ray start`` made it),
            ``local`` (a private cluster on this machine, stopped at the end) or a cluster's
            address (``ray://host:10001`` or ``host:6379``).
        num_cpus: Workers of a ``local`` cluster (all cores by default).
        chunk: Sessions per task (their single plucks are fitted in one batch; each worker
            compiles its programs once). With the default, the local run's chunks, the
            tables of both are the same to the last digit.

    Raises:
        RuntimeError: Ray is not installed.
        FleetError: No cluster answers at ``address`` (the message names ``--ray``).
    """
    try:
        import ray
    except ImportError:
        raise RuntimeError(
            'Ray is not installed: pip install "whiskerid[fleet]" (or leave out --ray)'
        ) from None
    state = {"started": False}
    if address != "local" and not ray.is_initialized():
        _join(ray, address)
        state["started"] = True

    def run(sessions: list[Session], settings: FleetSettings, keys: list[str]) -> Iterator[dict]:
        try:
            if not sessions:
                return
            if not ray.is_initialized():
                ray.init(address=None, num_cpus=num_cpus, include_dashboard=False,
                         log_to_driver=False, configure_logging=False)  # fmt: skip
                state["started"] = True
            task = ray.remote(fit_sessions)
            refs = [
                task.remote(sessions[i : i + chunk], settings, keys[i : i + chunk])
                for i in range(0, len(sessions), chunk)
            ]
            while refs:
                done, refs = ray.wait(refs, num_returns=1)
                yield from ray.get(done[0])
        finally:
            if state["started"]:
                ray.shutdown()
                state["started"] = False

    return run


def _join(ray, address: str) -> None:
    """Join the cluster at ``address``; Ray's own advice (its flags are not whiskerid's) and
    its retry warnings are kept off the terminal."""
    try:
        with _quiet_stderr():
            ray.init(address=address, log_to_driver=False, configure_logging=False)
    except Exception as err:  # ConnectionError, ValueError (a malformed address), …
        where = "on this machine" if address == "auto" else f"at {address}"
        # (Ray's own message advises a flag of its own, --address: not whiskerid's)
        why = " ".join(str(err).split()) if isinstance(err, ValueError) else "none running"
        raise FleetError(
            f"--ray {address}: no Ray cluster answers {where} ({why}); start one with "
            "'ray start --head' and give its address to --ray, or use --ray local for a "
            "private one on this machine"
        ) from None


@contextlib.contextmanager
def _quiet_stderr():
    """Send file descriptor 2 to /dev/null (Ray's C++ core writes there directly)."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
