"""The whisker and its sensors (stage 5 of the simulator): the modal model driven by the
base acceleration, the amplified Hall sensor(s), the two bending planes, and the ADS1115's
averaging over a conversion, vmapped over a batch of runs.
"""

from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..model import HallSensor, Whisker, WhiskerRecord, base_motion_response, observe

AMPLIFIER = 20.0  # gain of the paper's sensor amplifier, on top of the bare Hall gain


def amplified_hall(record: WhiskerRecord, amplifier: float = AMPLIFIER) -> HallSensor:
    """The record's Hall sensor behind an amplifier of gain ``amplifier`` (offset unchanged)."""
    return HallSensor(
        gain_v_per_m=record.hall.gain_v_per_m * amplifier,
        offset_v=record.hall.offset_v,
        quadratic_v_per_m2=record.hall.quadratic_v_per_m2 * amplifier,
    )


def _deflection(whisker: Whisker, grid_t, acc):
    """Relative deflection at the sensor (m), the whisker starting from rest at ``grid_t[0]``."""
    state = base_motion_response(whisker, grid_t, acc, uniform=True)
    return observe(whisker, state, "deflection")


@eqx.filter_jit
def hall_voltage(whisker: Whisker, hall: HallSensor, grid_t, acc):
    """Hall-sensor voltage of a whisker whose base moves with acceleration ``acc``.

    The exact modal model from rest, then the sensor: the signal at the ADS1115's input,
    before its averaging over a conversion. Compiled once per grid length: the whisker's and
    the sensor's parameters are traced, not baked in.

    Args:
        whisker: The whisker.
        hall: The Hall sensor (with its amplifier, see :func:`amplified_hall`).
        grid_t: Uniform time grid (s), e.g. from :func:`base_acceleration`.
        acc: Base acceleration on the grid (m/s²).

    Returns:
        Volts on the grid.
    """
    return hall.voltage(_deflection(whisker, grid_t, acc))


#: Column names of a two-sensor recording: sensor A reads the vertical plane, B the lateral.
PLANE_COLUMNS = ("hall_a", "hall_b")
_PLANE_KEYS = {"lateral_frequency_ratio", "lateral_zeta", "gain_ratio_b", "offset_b_v",
               "cross_talk"}  # fmt: skip


@dataclass(frozen=True)
class SensorPlanes:
    """The whisker's two bending planes and its two orthogonal Hall sensors.

    A record's optional ``[planes]`` table holds these (:meth:`from_record`); an
    axisymmetric coil without one has the same modes in both planes.

    Attributes:
        lateral_frequency_ratio: Natural frequencies in the lateral plane over those in the
            vertical one (a slightly flattened coil: a few per cent off 1); the lateral
            ``κ`` is the vertical one times its square.
        lateral_zeta: Modal damping in the lateral plane (one value or one per mode); the
            record's ``[damping] zeta`` when None.
        gain_ratio_b: Gain of sensor B (lateral) over sensor A's (the record's Hall gain).
        offset_b_v: Output of sensor B at rest (V); sensor A's when None.
        cross_talk: Fraction of the other plane's deflection each sensor reads (a sensor
            tilted by an angle θ off its plane reads ``sin θ`` of the other one).
    """

    lateral_frequency_ratio: float = 1.0
    lateral_zeta: float | tuple[float, ...] | None = None
    gain_ratio_b: float = 1.0
    offset_b_v: float | None = None
    cross_talk: float = 0.0

    def __post_init__(self):
        if not (np.isfinite(self.lateral_frequency_ratio) and
                0.2 < self.lateral_frequency_ratio < 5):  # fmt: skip
            raise ValueError(
                f"planes.lateral_frequency_ratio = {self.lateral_frequency_ratio!r} must lie "
                "between 0.2 and 5"
            )
        if not (np.isfinite(self.gain_ratio_b) and self.gain_ratio_b != 0):
            raise ValueError(f"planes.gain_ratio_b = {self.gain_ratio_b!r} must be non-zero")
        if not (np.isfinite(self.cross_talk) and abs(self.cross_talk) < 0.5):
            raise ValueError(f"planes.cross_talk = {self.cross_talk!r} must lie within ±0.5")
        zetas = np.atleast_1d(np.asarray(
            0.0 if self.lateral_zeta is None else self.lateral_zeta, dtype=float))  # fmt: skip
        if not (np.isfinite(zetas).all() and (zetas >= 0).all() and (zetas < 1).all()):
            raise ValueError(
                f"planes.lateral_zeta = {self.lateral_zeta!r} must satisfy 0 <= zeta < 1"
            )

    @classmethod
    def from_record(cls, record: WhiskerRecord) -> "SensorPlanes":
        """The record's ``[planes]`` table (defaults where it has none).

        Raises:
            ValueError: Unknown keys or values out of range, named.
        """
        table = dict(record.extra.get("planes", {}))
        unknown = sorted(set(table) - _PLANE_KEYS)
        if unknown:
            raise ValueError(f"[planes]: unknown key(s) {unknown}; known: {sorted(_PLANE_KEYS)}")
        if isinstance(table.get("lateral_zeta"), list):
            table["lateral_zeta"] = tuple(float(z) for z in table["lateral_zeta"])
        return cls(**table)

    def to_table(self) -> dict:
        """The ``[planes]`` table (None values left out)."""
        out = {k: getattr(self, k) for k in sorted(_PLANE_KEYS) if getattr(self, k) is not None}
        if isinstance(out.get("lateral_zeta"), tuple):
            out["lateral_zeta"] = list(out["lateral_zeta"])
        return out

    def whiskers(self, record: WhiskerRecord) -> tuple[Whisker, Whisker]:
        """The vertical and lateral :class:`Whisker` of ``record``."""
        vertical = record.whisker()
        zeta = vertical.zeta if self.lateral_zeta is None else jnp.broadcast_to(
            jnp.asarray(self.lateral_zeta, dtype=float), vertical.zeta.shape)  # fmt: skip
        lateral = eqx.tree_at(lambda w: (w.EI, w.zeta), vertical,
                              (vertical.EI * self.lateral_frequency_ratio**2, zeta))  # fmt: skip
        return vertical, lateral

    def halls(self, record: WhiskerRecord, amplifier: float = AMPLIFIER) -> tuple[HallSensor, ...]:
        """Sensors A and B, amplifier included."""
        a = amplified_hall(record, amplifier)
        b = HallSensor(
            gain_v_per_m=a.gain_v_per_m * self.gain_ratio_b,
            offset_v=a.offset_v if self.offset_b_v is None else self.offset_b_v,
            quadratic_v_per_m2=a.quadratic_v_per_m2 * self.gain_ratio_b,
        )
        return a, b

    def mixing(self) -> np.ndarray:
        """What each sensor reads of each plane's deflection: rows A, B; columns vertical,
        lateral."""
        c = self.cross_talk
        return np.array([[1.0, c], [c, 1.0]])


@eqx.filter_jit
def _sensor_chain_planes(whiskers, halls, mix, grid_t, acc, t_samples, conv_time, n_avg: int):
    """Two sensors' voltages averaged over each conversion, for a batch of runs (vmapped).

    ``acc`` is ``(runs, 2, grid)``: vertical and lateral base acceleration.
    """

    def one(acc, t_samples, conv_time):
        w = jnp.stack([_deflection(wk, grid_t, a) for wk, a in zip(whiskers, acc, strict=True)])
        field = mix @ w
        offsets = -(jnp.arange(n_avg) + 0.5) / n_avg * conv_time
        tt = t_samples[:, None] + offsets[None, :]
        return jnp.stack([jnp.mean(h.voltage(jnp.interp(tt, grid_t, f)), axis=1)
                          for h, f in zip(halls, field, strict=True)])  # fmt: skip

    return jax.vmap(one)(acc, t_samples, conv_time)


@eqx.filter_jit
def _sensor_chain(whisker, hall, grid_t, acc, t_samples, conv_time, n_avg: int):
    """Hall voltage averaged over each conversion, for a batch of runs (vmapped)."""

    def one(acc, t_samples, conv_time):
        w = _deflection(whisker, grid_t, acc)
        offsets = -(jnp.arange(n_avg) + 0.5) / n_avg * conv_time
        tt = t_samples[:, None] + offsets[None, :]
        return jnp.mean(hall.voltage(jnp.interp(tt, grid_t, w)), axis=1)

    return jax.vmap(one)(acc, t_samples, conv_time)
