"""Posteriors of a whisker's ζ, f_1 (κ) and EI or C with emcee.

Model. The calibration's residual model (:class:`whiskerid.fit.FitProblem`), jointly over one or
more recordings of one whisker: each recording is ``y = D(θ) c + g(θ) + ε`` in normalised
units (``y`` divided by its standard deviation), with shared nonlinear parameters ``θ``
(``log κ``, ``logit ζ``, a static test's ``log EI`` and offset, a sine's start time) and
per-recording linear coefficients ``c`` (offset, drift, modal amplitudes).

Likelihood. ``gaussian`` (default): ``ε ~ N(0, σ_j²)`` with an unknown σ per recording,
sampled as ``log σ_j``. The linear coefficients are *marginalised analytically*: with a
flat (improper) prior on ``c`` the integral is closed-form (variable projection),
``log L_j = −(n−k) log σ − ½ log|DᵀD| − RSS_min/(2σ²) − (n−k)/2 log 2π``, with ``RSS_min``
the least-squares residual at ``θ`` (normal equations, Jacobi-scaled Cholesky). ``student``: a
Student-t with ``ν`` (default 4) degrees of freedom and scale σ_j for outliers; there is no
closed form, so ``c`` is sampled with the other parameters (``marginalize=False`` does the
same for the Gaussian, e.g. for comparisons with samplers that cannot marginalise).

Priors. From the record's ``[prior]`` table, on physical quantities, with the Jacobian of
the sampled transform added: ``zeta``, ``f1_hz`` or ``kappa``, and ``sigma_rel`` (noise σ
relative to each recording's standard deviation). Distributions: ``uniform`` and
``loguniform`` (``low``, ``high``), ``normal`` (``mu``, ``sigma``), ``lognormal`` (``mu``,
``sigma`` of ``ln x``). Outside a bounded support the log-probability is ``−inf``.
Defaults when absent: ``zeta`` uniform on ``(0, 0.95)`` (the calibration's range),
``f1_hz`` log-uniform over ``[f̂/10, 10 f̂]`` around the calibrated ``f̂``, ``sigma_rel``
log-uniform on ``[1e-6, 10]``. A static test's ``log EI``, its offset and a sine's start
time have flat priors.

Sampler. ``emcee.EnsembleSampler(vectorize=True)`` on a jitted, vmapped log-probability
(free decays on near-uniform timestamps evaluated on a grid: two short tables of complex
exponentials and a Taylor factor for the timing jitter, equal to the direct evaluation to
rounding, which the batch falls back to where that factor would not be exact);
walkers start from the calibration's Laplace approximation (a draw from ``N(θ̂, Σ)``
in the sampled space: additive, so parameters at exactly 0 are no problem); reproducible
by seed (``emcee.State(p0, random_state=...)``); optional HDF5 backend with resume. The
proposal is emcee's differential-evolution move by default (``move="de"``; the stretch
move, emcee's and lmfit's default, on request): on these posteriors its autocorrelation
times are about a third of the stretch move's (:func:`emcee_moves`).

Diagnostics. Integrated autocorrelation time τ per sampled coordinate and per reported
quantity (``quiet=True``), burn-in ``2 max τ``, thinning ``min τ / 2``, effective sample
size ``walkers (steps − burn)/τ``; a run shorter than ``50 max τ`` is reported as
``converged = False`` with the number of steps needed.

Modules, along a run: ``_prior`` (the ``[prior]`` table), ``_grid`` (free decays on a time
grid), ``_likelihood`` (the log-posterior and the compiled batch function), ``_problem``
(:class:`Problem`, shared by the linear and nonlinear set-ups), ``_nonlinear`` (a nonlinear
calibration's posterior), ``_setup``
(:func:`setup_posterior`: the calibration's Laplace approximation), ``_sample`` (emcee),
``_summary`` (diagnostics and the reported quantities), ``_predictive`` (simulated recordings at
posterior draws), ``_arviz`` (``InferenceData`` and R-hat/ESS across independent ensembles, with
the optional ArviZ), ``_agreement`` (the calibration's warnings repeated, and the posterior's
widths against its 1σ).
"""

from .. import _jax_setup as _jax_setup
from ._agreement import calibration_agreement as calibration_agreement
from ._arviz import import_arviz as import_arviz
from ._prior import PosteriorError as PosteriorError
from ._prior import parse_prior as parse_prior
from ._problem import Problem as Problem
from ._sample import run_sampler as run_sampler
from ._sample import sample_posterior as sample_posterior
from ._setup import setup_posterior as setup_posterior
from ._summary import Posterior as Posterior
from ._summary import derived_quantities as derived_quantities
from ._summary import summarize as summarize
