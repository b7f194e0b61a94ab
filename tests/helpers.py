"""Independent reference solutions and problem tables for the tests.

Nothing here imports whiskerid's model code: these are separate transcriptions (NumPy) and
a separate discretisation (finite elements), so agreement means something.
"""

import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import scipy.linalg

from whiskerid.fit import RecordingModel

#: The paper whisker's derived values and natural frequencies (from its Section III geometry).
PAPER_EI = 3.436e-3
PAPER_C = 6.207
PAPER_RHO_A = 3.924e-2
PAPER_FREQS_HZ = (46.0, 288.2, 807.1, 1581.6, 2614.4)

#: shared/data/cantilever/README.md: aluminium beam, 50 x 2 mm, E 70 GPa, 2700 kg/m^3,
#: 5 g tip mass; Euler-Bernoulli theory values of f_1 stated there.
ALU = {"E": 70e9, "rho": 2700.0, "width": 0.05, "thickness": 0.002, "tip_mass": 0.005}
ALU_THEORY_F1 = {0.30: 16.36, 0.50: 6.14}


def paper_eq1_numpy(
    t, x, *, fb, hb, l, EI, rho_a, zeta, D=(1.8751, 4.6941, 7.8548, 10.9955, 14.137)
):
    """Eq. 1 typed in again from the paper, literally (overflows for long t; use t < 0.5 s).

    The printed symbols: a*rho is the line density, E*I the bending stiffness.
    """
    t = np.asarray(t, dtype=float)
    a_rho, E_I = rho_a, EI
    wb = 2 * np.pi * fb
    y = np.zeros_like(t)
    for Di in D:
        k = np.sqrt(E_I / a_rho)
        A = (
            2
            * a_rho
            * hb
            * l**4
            * wb**2
            * np.exp(-(Di**2) * t * zeta * k / l**2)
            * np.sin(wb * t)
            * (np.cos(Di) - 1)
            * (np.cosh(Di) - 1)
            * (np.cos(Di) + np.cosh(Di))
        )
        B = (
            np.sinh(Di * x / l)
            - np.sin(Di * x / l)
            + (np.cos(Di * x / l) - np.cosh(Di * x / l))
            * (np.sin(Di) + np.sinh(Di))
            / (np.cos(Di) + np.cosh(Di))
        )
        C = (
            zeta * np.sin(Di**2 * t * np.sqrt(1 - zeta**2) * k / l**2)
            - np.exp(Di**2 * t * zeta * k / l**2) * np.sqrt(1 - zeta**2)
            + np.cos(Di**2 * np.sqrt(E_I) * t * np.sqrt(1 - zeta**2) / (np.sqrt(a_rho) * l**2))
            * np.sqrt(1 - zeta**2)
        )
        Dd = (
            Di**4
            * E_I
            * np.sqrt(1 - zeta**2)
            * (
                3 * np.sinh(Di) * np.cos(Di) ** 2 * np.cosh(Di)
                - Di * np.cos(Di) ** 2
                - 3 * np.sin(Di) * np.cos(Di) * np.cosh(Di) ** 2
                + 3 * np.sinh(Di) * np.cos(Di)
                + Di * np.cosh(Di) ** 2
                - 3 * np.sin(Di) * np.cosh(Di)
                + 2 * Di * np.sin(Di) * np.sinh(Di)
            )
        )
        y += -(A * B * C) / Dd
    return y


class FEMBeam:
    """Euler-Bernoulli cantilever by Hermite-cubic finite elements, with modal damping.

    DOFs per node: deflection and slope; node 0 is clamped. A tip mass adds to the last
    node's deflection DOF. Damping: C = M Phi diag(2 zeta w) Phi^T M over ALL FE modes.
    Base excitation in relative coordinates: M w'' + C w' + K w = -M r y_b''.
    """

    def __init__(self, *, length, EI, rho_a, zeta, tip_mass=0.0, n_el=40):
        self.length, self.n_el = length, n_el
        h = length / n_el
        k = (
            EI
            / h**3
            * np.array(
                [
                    [12, 6 * h, -12, 6 * h],
                    [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                    [-12, -6 * h, 12, -6 * h],
                    [6 * h, 2 * h * h, -6 * h, 4 * h * h],
                ]
            )
        )
        m = (
            rho_a
            * h
            / 420
            * np.array(
                [
                    [156, 22 * h, 54, -13 * h],
                    [22 * h, 4 * h * h, 13 * h, -3 * h * h],
                    [54, 13 * h, 156, -22 * h],
                    [-13 * h, -3 * h * h, -22 * h, 4 * h * h],
                ]
            )
        )
        n = 2 * (n_el + 1)
        K, M = np.zeros((n, n)), np.zeros((n, n))
        for e in range(n_el):
            s = slice(2 * e, 2 * e + 4)
            K[s, s] += k
            M[s, s] += m
        M[-2, -2] += tip_mass
        self.K, self.M = K[2:, 2:], M[2:, 2:]
        self.r = np.zeros(n - 2)
        self.r[0::2] = 1.0
        w2, phi = scipy.linalg.eigh(self.K, self.M)
        self.omega = np.sqrt(w2)
        MP = self.M @ phi
        self.C = MP @ np.diag(2 * zeta * self.omega) @ MP.T

    def frequencies_hz(self, n):
        return self.omega[:n] / (2 * np.pi)

    def interpolation(self, x):
        """Row vector N with w(x) = N @ dofs (Hermite shape functions)."""
        h = self.length / self.n_el
        e = min(int(x / h), self.n_el - 1)
        s = (x - e * h) / h
        N = np.array(
            [
                1 - 3 * s**2 + 2 * s**3,
                h * (s - 2 * s**2 + s**3),
                3 * s**2 - 2 * s**3,
                h * (-(s**2) + s**3),
            ]
        )
        row = np.zeros(2 * (self.n_el + 1))
        row[2 * e : 2 * e + 4] = N
        return row[2:]

    def steady_amplitude(self, x, fb, hb):
        """|relative deflection| at x for y_b = hb sin(2 pi fb t)."""
        w = 2 * np.pi * fb
        A = self.K - w**2 * self.M + 1j * w * self.C
        W = np.linalg.solve(A, w**2 * hb * (self.M @ self.r))
        return abs(self.interpolation(x) @ W)

    def static_tip_shape(self, tip_deflection):
        f = np.zeros(self.K.shape[0])
        f[-2] = 1.0
        w = np.linalg.solve(self.K, f)
        return w * tip_deflection / w[-2]

    def integrate(self, t_eval, *, n_modes, w0=None, base_acc=None):
        """Direct integration (scipy DOP853) of the FE model reduced to its first n_modes modes.

        Starts from the deflection w0 at rest, or from rest under the base acceleration
        base_acc(t). Returns nodal deflections and slopes at t_eval, shape (len(t), dofs).
        """
        from scipy.integrate import solve_ivp

        w2, phi = scipy.linalg.eigh(self.K, self.M, subset_by_index=[0, n_modes - 1])
        phi = phi / np.sqrt(np.einsum("ij,jk,ki->i", phi.T, self.M, phi))  # mass-normalised
        omega = np.sqrt(w2)
        c = phi.T @ self.C @ phi
        force = phi.T @ self.M @ self.r
        q0 = np.zeros(2 * n_modes)
        if w0 is not None:
            q0[:n_modes] = phi.T @ self.M @ w0

        def rhs(t, y):
            q, v = y[:n_modes], y[n_modes:]
            a = -(omega**2) * q - c @ v
            if base_acc is not None:
                a = a - force * base_acc(t)
            return np.concatenate([v, a])

        sol = solve_ivp(
            rhs,
            (t_eval[0], t_eval[-1]),
            q0,
            t_eval=t_eval,
            method="DOP853",
            rtol=1e-10,
            atol=1e-16,
            max_step=float(np.min(np.diff(t_eval))),
        )
        assert sol.success, sol.message
        return sol.y[:n_modes].T @ phi.T


def decay_recording(t, modes, offsets=None):
    """A free decay's recording model at times ``t`` (data zero), as the fit builds it."""
    t = jnp.asarray(t)
    return RecordingModel(
        t=t, y=jnp.zeros_like(t), weight=jnp.asarray(1.0), scale=jnp.asarray(1.0),
        hb_m=jnp.asarray(1e-3), x_m=jnp.asarray(0.005), fb_hz=jnp.asarray(0.0),
        avg_offsets=None if offsets is None else jnp.asarray(offsets), base_acc=None,
        excitation="decay", observable="deflection", forced="none", n_cols=2 + 2 * modes,
    )  # fmt: skip


def one_step_chain(path):
    """An HDF5 chain of 4 walkers in 2 dimensions, grown for two steps, with one step saved
    through the sampler's checked backend: ``(backend, state)``, ready for a second
    ``save_step`` that a full disk or a file-size limit must stop."""
    import emcee

    from whiskerid.posterior import _sample

    be = _sample._checked_backend(emcee)(str(path), name="whiskerid")
    be.reset(4, 2)
    be.grow(2, None)
    state = emcee.State(np.ones((4, 2)), log_prob=np.zeros(4),
                        random_state=np.random.RandomState(0).get_state())  # fmt: skip
    be.save_step(state, np.ones(4, bool))
    return be, state


def start_child(script: str, argv: list[str], marker: str):
    """A Python child running ``script`` with ``argv``, read on stderr up to the line
    ``marker`` (the stage a test signals at). Returns ``(child, lines before the marker,
    whether the marker came)``; the child's stderr is left open, read past the marker."""
    child = subprocess.Popen([sys.executable, "-c", script, *argv], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)  # fmt: skip
    lines = []
    for line in child.stderr:
        if line.strip() == marker:
            return child, lines, True
        lines.append(line)
    return child, lines, False
