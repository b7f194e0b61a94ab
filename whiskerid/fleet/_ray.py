"""Sessions spread over a Ray cluster (the optional ``fleet`` extra: ``pip install
"whiskerid[fleet]"``).

Each task fits a chunk of sessions with :func:`whiskerid.fleet.fit_sessions`, the very
function and the same chunks the local run uses, so the numbers are the same either way. The
workers read the recordings by path (on a cluster of several machines the fleet's folder
must be mounted at the same path on each); the results come back to this process, which
alone writes the records and the table.
"""

from collections.abc import Iterator

from ._calibrate import SESSION_CHUNK, FleetSettings, fit_sessions
from ._layout import Session


def ray_runner(address: str = "auto", *, num_cpus: int | None = None, chunk: int = SESSION_CHUNK):
    """A runner for :func:`whiskerid.fleet.calibrate_fleet` that uses Ray.

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
    """
    try:
        import ray
    except ImportError:
        raise RuntimeError(
            'Ray is not installed: pip install "whiskerid[fleet]" (or leave out --ray)'
        ) from None

    def run(sessions: list[Session], settings: FleetSettings, keys: list[str]) -> Iterator[dict]:
        if not sessions:
            return
        started = not ray.is_initialized()
        if started:
            kwargs = {"address": None if address == "local" else address}
            if address == "local":
                kwargs.update(num_cpus=num_cpus, include_dashboard=False)
            ray.init(log_to_driver=False, configure_logging=False, **kwargs)
        try:
            task = ray.remote(fit_sessions)
            refs = [
                task.remote(sessions[i : i + chunk], settings, keys[i : i + chunk])
                for i in range(0, len(sessions), chunk)
            ]
            while refs:
                done, refs = ray.wait(refs, num_returns=1)
                yield from ray.get(done[0])
        finally:
            if started:
                ray.shutdown()

    return run
