"""Noise mixtures learned offline from training residuals (P1's M4/M5 set-up).

A filter's noise mixtures are *standardised* (:class:`~mixnav.noise.mixture.StandardMixture`):
each is fitted to residuals already divided by the model's sigma. The
settings are plain arguments; the experiment layer maps a scenario's
``[mixture.learn]`` table onto them.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import numpy as np

from ...errors import ArgumentError
from ..mixture import BankMixtures, StandardMixture
from . import ConvergenceWarning

__all__ = ["LearnedMixtures", "learn_mixture", "learn_mixtures"]


@dataclass(frozen=True)
class LearnedMixtures:
    """The mixtures a filter uses, how long learning them took [s], and how many
    of the fits stopped before converging (counted in the filter's ``recoveries``
    as ``learner_not_converged``; such a fit is still a usable mixture)."""

    mixtures: BankMixtures
    learning_time_s: float
    not_converged: int


def _fit(samples, method, n_components, gibbs_samples, prune, seed):
    """``(StandardMixture, converged)`` of one fit."""
    from . import EMGaussianMixture, GibbsGaussianMixture, VariationalGaussianMixture
    x = np.asarray(samples, dtype=float).reshape(-1, 1)
    if method == "vb":
        est = VariationalGaussianMixture(n_components=n_components, alpha0=1.0, beta0=1.0, nu0=1.0,
                                         W0=np.array([[2.0]]), tol=1e-6, prune_threshold=prune,
                                         random_state=seed)
    elif method == "gibbs":
        est = GibbsGaussianMixture(n_components=n_components, n_samples=gibbs_samples, alpha0=1.0,
                                   beta0=1.0, nu0=1.0, W0=np.array([[2.0]]), prune_threshold=prune,
                                   random_state=seed)
    elif method == "em":
        est = EMGaussianMixture(n_components=n_components, random_state=seed)
    else:
        raise ArgumentError(f"unknown learner '{method}' (vb, gibbs, em)", argument="method")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")  # recorded, not shown: non-convergence is counted instead
        est.fit(x)
    converged = not any(issubclass(w.category, ConvergenceWarning) for w in caught)
    gm = est.mixture_
    if method == "em":  # EM has no pruning of its own
        gm = gm.prune(prune)
    return StandardMixture.from_mixture(gm), converged


def learn_mixture(samples: np.ndarray, method: str, n_components: int = 4, gibbs_samples: int = 1000,
                  prune: float = 0.01, seed: int = 0) -> StandardMixture:
    """Fit a standardised 1-D noise mixture to training residuals (in units of the model's sigma).

    ``"vb"`` uses P1's settings (alpha0 = 1, beta0 = 1, nu0 = 1, W0 = 2,
    m0 = the sample mean, K = ``n_components``, stop at a lower-bound change
    below 1e-6, prune below ``prune``); ``"gibbs"`` the same conjugate model
    sampled ``gibbs_samples`` times (P1 schemes 3-4); ``"em"`` maximum
    likelihood. A fit that does not converge is returned as it stands
    (:func:`learn_mixtures` counts them).
    """
    return _fit(samples, method, n_components, gibbs_samples, prune, seed)[0]


def learn_mixtures(training: dict, observables, method: str, given: BankMixtures | None = None, *,
                   n_components: int = 4, gibbs_samples: int = 1000, prune: float = 0.01,
                   training_samples: int | None = None, learn_process: bool = False,
                   seed: int = 0) -> LearnedMixtures:
    """Learn the measurement mixtures of ``observables`` (and optionally the process
    mixture) from training residuals; mixtures not learned are taken from ``given``.

    Parameters
    ----------
    training : dict
        Observable kind name (and ``"process"``) -> standardised residuals (N,).
    observables : sequence of str
        Kinds whose measurement mixture is learned.
    method : {"vb", "gibbs", "em"}
    given : BankMixtures, optional
        The mixtures given explicitly (kept where not learned).
    n_components, gibbs_samples, prune, seed
        As :func:`learn_mixture`.
    training_samples : int, optional
        Use at most this many residuals per fit.
    learn_process : bool
        Also learn the process-noise mixture (its means forced to zero, the
        scales taken about zero: ``E[x^2]`` per component).
    """
    t0 = time.perf_counter()
    given = given or BankMixtures()
    n = training_samples
    meas = dict(given.measurement)
    failed = 0
    for kind in observables:
        if kind not in training:
            raise ArgumentError(f"no training residuals of '{kind}'", argument=f"observables.{kind}")
        meas[kind], ok = _fit(training[kind][:n], method, n_components, gibbs_samples, prune, seed)
        failed += not ok
    process = given.process
    if learn_process:
        p, ok = _fit(training["process"][:n], method, n_components, gibbs_samples, prune, seed)
        failed += not ok
        process = StandardMixture(p.weights, (0.0,) * p.n_components,
                                  tuple(np.asarray(p.scales) + np.asarray(p.means) ** 2))
    return LearnedMixtures(BankMixtures(meas, process, given.prior), time.perf_counter() - t0, failed)
