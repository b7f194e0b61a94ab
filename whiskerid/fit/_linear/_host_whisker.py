"""The record's whisker as host numbers, for a calibration's set-up, report and checks."""

import numpy as np

from ...model import WhiskerRecord
from ...model._modes import host_roots


def nominal_whisker(record: WhiskerRecord, n_modes: int) -> "HostWhisker":
    """``record.whisker().with_modes(n_modes)`` as host numbers (see :class:`HostWhisker`)."""
    zeta = np.asarray(record.zeta, dtype=float)
    if zeta.ndim == 0:  # as record.whisker(): one ζ for the record's modes
        zeta = np.full(record.n_modes, zeta)
    zeta = np.concatenate([zeta, np.full(max(0, n_modes - zeta.size), zeta[-1])])[:n_modes]
    return HostWhisker(record, zeta)


class HostWhisker:
    """What a calibration reads of the record's whisker (the start grid, the problem's
    constants, the report, the checks), as NumPy numbers computed once, with the same
    operations as :class:`whiskerid.model.Whisker`'s (``κ = EI/ρa``, ``μ = M_t/(ρa l)``,
    ``f_i = β_i² √κ / (2π l²)``). The record was checked when it was made; building the
    JAX whisker and reading its properties was a chain of eager JAX operations (a device
    transfer per field, its eigenvalues and frequencies): 2–3 ms of a 16 ms warm fit."""

    def __init__(self, record: WhiskerRecord, zeta: np.ndarray):
        s = record.structure
        self.length_m = np.asarray(float(s.length_m))
        self.EI = np.asarray(float(s.EI))
        self.rho_a = np.asarray(float(s.rho_a))
        self.zeta = zeta
        self.tip_mass_kg = np.asarray(float(record.tip_mass_kg))
        self.sensor_x_m = np.asarray(float(record.sensor_position_m))
        self.mu = self.tip_mass_kg / (self.rho_a * self.length_m)
        self.beta = host_roots(float(self.mu), zeta.size)  # no device round trip
        omega = self.beta**2 * np.sqrt(self.EI / self.rho_a) / self.length_m**2
        self.natural_frequencies_hz = omega / (2 * np.pi)
