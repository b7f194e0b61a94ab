"""Independent reference solutions and problem tables for the tests.

No response here is computed by whiskerid's model code (whiskerid gives only the paper
whisker's record and the fit's data types): these are separate transcriptions (NumPy, SciPy's
integrators) and a separate discretisation (finite elements), so agreement means something.
"""

import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import scipy.linalg
from scipy.integrate import solve_ivp

from whiskerid.fit import Observation, RecordingModel, nominal_gain
from whiskerid.fit._nonlinear import tip_per_sensor
from whiskerid.model import paper_record

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
    (and checkpointed to ``path``) through the sampler's checked backend:
    ``(backend, state)``, ready for a second step whose checkpoint a full disk or a
    file-size limit must stop."""
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


# Nonlinear plucks integrated by SciPy (not the project's model): the fit, posterior and
# free-mode tests share them. Mode 1 at F0 Hz, damping Z0, amplitude A0 (normalised).
F0, Z0, A0 = 38.0, 0.02, 2e-3


def scipy_decay(
    t,
    gamma=0.0,
    c=0.0,
    friction=0.0,
    u0=A0,
    v0=0.0,
    zeta0=Z0,
    f0=F0,
    kappa=0.0,
    *,
    acceleration=False,
):
    """u(t) by SciPy, restarted at each velocity zero (exact sign of the friction); with
    ``acceleration``, ü(t) instead: the right-hand side at the integrated (u, u̇)."""
    w0 = 2 * np.pi * f0

    def rhs(s, y, sgn):
        u, v = y
        return [v, -(2 * zeta0 * w0 * v + w0**2 * (u + kappa * u * abs(u) + gamma * u**3)
                     + c * abs(v) * v + friction * sgn)]  # fmt: skip

    def turn(s, y, sgn):
        return y[1]

    turn.terminal = True
    out = np.zeros((2, t.size))
    y, s0 = np.array([u0, v0]), t[0]
    sgn = np.sign(v0) if v0 else -np.sign(u0)
    while s0 < t[-1]:
        turn.direction = -sgn
        sol = solve_ivp(rhs, (s0, t[-1]), y, args=(sgn,), events=turn, rtol=1e-11,
                        atol=1e-16, method="DOP853", dense_output=True)  # fmt: skip
        sel = (t >= s0) & (t <= sol.t[-1])
        out[:, sel] = sol.sol(t[sel])
        y, s0 = sol.y[:, -1].copy(), sol.t[-1]
        if sol.status != 1:
            break
        y[1] = 0.0
        if abs(w0**2 * (y[0] + kappa * y[0] * abs(y[0]) + gamma * y[0] ** 3)) <= friction:
            out[:, t > s0] = [[y[0]], [0.0]]
            break
        sgn = -sgn
    if acceleration:  # ü from the equation itself (no friction: its sign is per segment)
        assert friction == 0.0
        return np.asarray(rhs(0.0, out, 0.0)[1])
    return out[0]


def nonlinear_pluck(rate=860.0, rise=0.004, zq=0.25, seed=0, duration=None, observable="voltage"):
    """A pluck of the paper whisker's first mode by SciPy (40 dB), read by the Hall sensor in
    volts or by an accelerometer at the tip in m/s² (``ü``, with a 0.2 m/s² bias)."""
    record = paper_record()
    w = record.whisker().with_modes(1)
    f0 = float(w.natural_frequencies_hz[0])
    acc = observable == "acceleration"
    x_m = record.structure.length_m if acc else record.sensor_position_m
    ratio = float(tip_per_sensor(w, x_m))
    a_s = 2e-3 / ratio
    zeta0 = 0.031
    gamma = rise * 8 / (3 * a_s**2)
    c = 3 * np.pi * zq * zeta0 / (4 * a_s)
    rng = np.random.default_rng(seed)
    duration = duration or 4.6 / (2 * np.pi * f0 * zeta0)
    t = np.arange(0, duration, 1 / rate) + rng.uniform(0, 1 / rate)
    u = scipy_decay(np.concatenate([[0.0], t]), gamma, c, u0=a_s, zeta0=zeta0, f0=f0,
                    acceleration=acc)[1:]  # fmt: skip
    gain = 1.0 if acc else nominal_gain(record, "voltage")
    y = (0.2 if acc else 1.65) + gain * u + rng.normal(0, np.std(gain * u) / 100, t.size)
    truth = {"f1_hz": f0, "zeta": zeta0, "gamma_per_m2": gamma / ratio**2,
             "quadratic_per_m": c / ratio}  # fmt: skip
    obs = Observation(t, y, observable=observable, gain=gain, x_m=x_m)
    return record, obs, truth
