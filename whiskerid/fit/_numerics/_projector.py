"""The linear fit's Jacobian, factored once for every score test that projects on it.

The amplitude tests (module ``_amplitude``) and the model-error term (module
``_model_error``) ask nine times, with different extra columns ``Z``, the same questions of
one Jacobian ``J`` at the linear optimum: ``Z`` less its fit by ``J``'s columns (``Z⊥``), and
the Gauss–Newton step along ``[J, Z]`` that minimises ``‖r + Jδ_J + Zδ_Z‖²`` with the
residuals it leaves. Each was a least-squares solve of ``n × (p + k)``. With ``J``'s SVD
(columns scaled to unit norm, singular values below ``max(n, p)·ε`` of the largest left out,
as :func:`numpy.linalg.lstsq` leaves them out) taken once, the step splits exactly into two
small solves, because ``[J, Z]`` spans what ``J`` and ``Z⊥`` span:

* ``δ_Z = −Z⊥⁺ r`` (``Z⊥`` is orthogonal to ``J``, so ``J`` cannot absorb any of it);
* ``δ_J = −J⁺ (r + Z δ_Z)``;
* the residuals left, ``r + Jδ_J + Zδ_Z = (I − P_J) r + Z⊥ δ_Z``.
"""

import numpy as np


class LinearPart:
    """``J`` (``n × p``) factored once (see the module docstring).

    Attributes:
        u: Left singular vectors of the column-scaled ``J`` that are kept (``n × rank``).
    """

    def __init__(self, jac: np.ndarray, svd=None):
        """``svd``: ``(scale, U, S, Vᵀ)`` of ``J`` with unit-norm columns when already taken
        (the calibration's program takes it for the covariance); the cut is applied here."""
        if svd is None:
            self._scale, self.u, s, vt = _scaled_svd(np.asarray(jac))
        else:
            self._scale, u, s, vt = (np.asarray(x) for x in svd)
            keep = s > (s[0] if s.size else 0.0) * max(*np.shape(jac)) * np.finfo(float).eps
            self.u, s, vt = u[:, keep], s[keep], vt[keep]
        self._vs = vt.T / s  # J⁺ = diag(1/scale) V S⁻¹ Uᵀ
        self._last = None

    def project(self, z: np.ndarray) -> np.ndarray:
        """``Z⊥``: ``z`` less its least-squares fit by ``J``'s columns."""
        return z - self.u @ (self.u.T @ z)

    def solve(self, y: np.ndarray) -> np.ndarray:
        """``J⁺ y``: the least-squares coefficients of ``y`` on ``J``'s columns."""
        out = self._vs @ (self.u.T @ y)
        return out / self._scale.reshape((-1,) + (1,) * (out.ndim - 1))

    def gauss_newton(self, r: np.ndarray, z: np.ndarray, zp: np.ndarray | None = None):
        """The step along ``[J, Z]`` from residuals ``r`` and the residuals it leaves.

        Args:
            r: Residuals ``(n,)``.
            z: Extra columns ``(n, k)``.
            zp: ``project(z)``, when already computed.

        Returns:
            ``(δ_J, δ_Z, r_alt)``.
        """
        zp = self.project(z) if zp is None else zp
        d_z, r_alt = self.alternative(r, zp)
        d_j = -self.solve(r + z @ d_z)
        return d_j, d_z, r_alt

    def alternative(self, r: np.ndarray, zp: np.ndarray):
        """``(δ_Z, r_alt)`` of :meth:`gauss_newton` (without ``δ_J``), from ``zp = Z⊥``."""
        d_z = -pinv_columns(zp) @ r
        return d_z, self.off(r) + zp @ d_z

    def off(self, r: np.ndarray) -> np.ndarray:
        """``(I − P_J) r``, kept for the last ``r`` (the tests ask it of one ``r`` nine times)."""
        if self._last is None or self._last[0] is not r:
            self._last = (r, r - self.u @ (self.u.T @ r))
        return self._last[1]


class ColumnSubsets:
    """``Z⊥`` (``n × k``) factored once as ``QR``, for the least-squares step of any subset
    ``S`` of its columns (the model-error term asks it of all seven).

    ``Z⊥_S = Q R_S`` with ``Q``'s columns orthonormal, so ``Z⊥_S⁺ y = R_S⁺ Qᵀy``: one QR
    of the ``n × k`` columns and a ``k × |S|`` pseudo-inverse per subset, instead of an
    ``n × |S|`` SVD each. ``R_S`` has ``Z⊥_S``'s column norms and singular values, so the
    cut of small singular values is the same (taken relative to ``max(n, |S|)``, as
    :func:`pinv_columns` takes it).
    """

    def __init__(self, zp: np.ndarray):
        self.zp = zp
        self.q, self.r = np.linalg.qr(zp)

    def step(self, idx, r: np.ndarray) -> np.ndarray:
        """``Z⊥_S⁺ r`` for the columns ``idx``."""
        scale, u, s, vt = _scaled_svd(self.r[:, list(idx)], rows=self.zp.shape[0])
        return (vt.T / s @ (u.T @ (self.q.T @ r))) / scale

    def steps(self, subsets, r: np.ndarray) -> np.ndarray:
        """:meth:`step` of every subset at once (``m × k``, zero outside each subset).

        Each ``R_S`` is ``R`` with the columns outside ``S`` set to zero: its SVD has
        ``R_S``'s singular values and zeros, which the cut leaves out (the cut is relative
        to the largest and to the ``n`` rows, as :meth:`step` takes it), so one batched SVD
        of ``k × k`` matrices serves every subset instead of an SVD call each.
        """
        k = self.r.shape[1]
        member = subset_mask(subsets, k)
        a = np.where(member[:, None, :], self.r[None, :, :], 0.0)
        scale = np.sqrt(np.einsum("mij,mij->mj", a, a))
        scale = np.where(scale > 0, scale, 1.0)
        u, s, vt = np.linalg.svd(a / scale[:, None, :])
        keep = s > s[:, :1] * max(k, self.zp.shape[0]) * np.finfo(float).eps
        inv = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
        coef = np.einsum("mji,j->mi", u, self.q.T @ r) * inv
        out = np.einsum("mij,mi->mj", vt, coef) / scale
        return np.where(member, out, 0.0)


def subset_mask(subsets, k: int) -> np.ndarray:
    """``(len(subsets), k)`` booleans: row ``j`` marks the columns of ``subsets[j]``."""
    member = np.zeros((len(subsets), k), dtype=bool)
    for j, idx in enumerate(subsets):
        member[j, list(idx)] = True
    return member


def pinv_columns(a: np.ndarray) -> np.ndarray:
    """``A⁺`` of a tall ``A`` (``k × n``) through its column-scaled SVD, with
    :func:`numpy.linalg.lstsq`'s cut of small singular values."""
    scale, u, s, vt = _scaled_svd(a)
    return (vt.T / s @ u.T) / scale[:, None]


def _scaled_svd(a: np.ndarray, rows: int | None = None):
    """``(scale, U, S, Vᵀ)`` of ``A`` with unit-norm columns (``A = U S Vᵀ diag(scale)``), the
    singular values below ``max(n, p)·ε`` of the largest left out, as
    :func:`numpy.linalg.lstsq` leaves them out (``n`` = ``rows`` where ``A`` is the ``R``
    of an ``n``-row matrix)."""
    scale = np.linalg.norm(a, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    u, s, vt = np.linalg.svd(a / scale, full_matrices=False)
    keep = s > (s[0] if s.size else 0.0) * max(*a.shape, rows or 0) * np.finfo(float).eps
    return scale, u[:, keep], s[keep], vt[keep]
