"""The terrain simulator as the emulated chip's input, for ``whiskerid stream --simulate``."""

import threading
from collections.abc import Callable

import numpy as np

from ..terrain import AMPLIFIER, amplified_hall, base_acceleration, hall_voltage
from ._emulator import source_from_recording


def terrain_source(record, terrain: str, speed_mps: float, duration_s: float | None, *,
                   seed: int = 0, amplifier: float = AMPLIFIER, chunk_s: float = 60.0):  # fmt: skip
    """Hall-sensor voltage ``source(t_s)`` of a whisker driven over a simulated terrain.

    The terrain simulator's base motion, whisker and amplified Hall sensor
    (:func:`whiskerid.terrain.hall_voltage`, the chain the dataset synthesiser uses); the
    emulated ADS1115 then does the averaging, clipping and quantisation itself.

    With ``duration_s`` None the terrain never ends: it is made ``chunk_s`` seconds at a time,
    each chunk fresh terrain (its own seed), the next one made on a worker thread from the
    middle of the current one on, and successive chunks cross-faded over a second.
    """
    if duration_s is not None:
        return _terrain_chunk(record, terrain, speed_mps, duration_s, seed, amplifier)

    def chunk(k: int):
        return _terrain_chunk(record, terrain, speed_mps, chunk_s + 2 * _FADE_S, [seed, k],
                              amplifier)  # fmt: skip

    return _EndlessTerrain(chunk, chunk_s)


#: Cross-fade between chunks of an endless terrain, and the start-up transient each chunk's
#: whisker simulation drops (it starts at rest), in seconds.
_FADE_S = 1.0


def _terrain_chunk(record, terrain, speed_mps, duration_s, seed, amplifier):
    return source_from_recording(*terrain_signal(record, terrain, speed_mps, duration_s,
                                                 seed=seed, amplifier=amplifier))  # fmt: skip


def terrain_signal(
    record, terrain: str, speed_mps: float, duration_s: float, *, seed=0,
    amplifier: float = AMPLIFIER,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Times (s) and Hall-sensor voltages (V) of :func:`terrain_source` with a duration, as
    arrays (to hand to a sampling process as a recording)."""
    rng = np.random.default_rng([*np.atleast_1d(seed), 7919])
    t, acc = base_acceleration(terrain, speed_mps, duration_s + 1.0, rng)
    volts = np.asarray(hall_voltage(record.whisker(), amplified_hall(record, amplifier), t, acc))
    keep = t >= 0
    return t[keep], volts[keep]


class _EndlessTerrain:
    """Chunk ``k`` of the terrain plays over ``[k C, (k + 1) C]`` (``C = chunk_s``), taken
    from its own simulation after a second of start-up, and fades into chunk ``k + 1``
    over the first second of the latter."""

    def __init__(self, make: Callable[[int], Callable], chunk_s: float):
        self._make = make
        self.chunk_s = float(chunk_s)
        self._chunks: dict[int, Callable] = {}
        self._ahead: tuple[int, threading.Thread, list] | None = None

    def _chunk(self, k: int) -> Callable:
        if k not in self._chunks:
            if self._ahead is not None and self._ahead[0] == k:
                self._ahead[1].join()
                made = self._ahead[2]
                self._ahead = None
                # A worker that failed left nothing: make it here, where an error is seen.
                self._chunks[k] = made[0] if made else self._make(k)
            else:
                self._chunks[k] = self._make(k)
            for old in [j for j in self._chunks if j < k - 1]:
                del self._chunks[old]  # memory stays at two chunks
        return self._chunks[k]

    def _prefetch(self, k: int) -> None:
        """Start making chunk ``k + 1`` on a worker thread (halfway through chunk ``k``, so
        that the start-up, busy compiling, is left alone)."""
        if self._ahead is None and k + 1 not in self._chunks:
            box: list = []
            thread = threading.Thread(target=lambda: box.append(self._make(k + 1)), daemon=True)
            thread.start()
            self._ahead = (k + 1, thread, box)

    def _play(self, k: int, t: np.ndarray) -> np.ndarray:
        # Chunk k's own time 0 is at stream time k C - 2 FADE: its start-up from rest is
        # over a second before it fades in at k C.
        return np.asarray(self._chunk(k)(t - k * self.chunk_s + 2 * _FADE_S))

    def __call__(self, t_s):
        t = np.asarray(t_s, dtype=np.float64)
        k = int(np.floor(float(np.mean(t)) / self.chunk_s))
        v = self._play(k, t)
        if float(np.mean(t)) - k * self.chunk_s > self.chunk_s / 2:
            self._prefetch(k)
        into = (t - k * self.chunk_s) / _FADE_S
        if k > 0 and float(np.min(into)) < 1.0:
            w = np.clip(into, 0.0, 1.0)
            v = w * v + (1 - w) * self._play(k - 1, t)
        return float(v) if v.ndim == 0 else v
