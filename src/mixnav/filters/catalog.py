"""The estimators a scenario or dataset file can name (``estimator = "..."``).

One line per estimator: its name, where its filter class lives (imported only
when a method uses it, so listing the catalogue imports no kernel) and what it
is. Adding an estimator is one new file and one line here; the experiment
layer (:mod:`mixnav.experiment.methods`) builds it from a method's
``[methods.options]`` table, which are its keyword arguments.
"""

from __future__ import annotations

from importlib import import_module

from ..errors import ArgumentError

#: name -> ("module:FilterClass", one-line description)
ESTIMATORS = {
    "ekf": ("mixnav.filters.ekf:ErrorStateEkf", "M1 extended Kalman filter (the default)"),
    "robust-adaptive": ("mixnav.filters.robust:RobustAdaptiveEkf",
                        "M2 robust adaptive EKF: IGG-III equivalent weights + Yang's adaptive factor"),
    "gaussian-mixture": ("mixnav.filters.gmekf:GaussianMixtureEkf",
                         "M3 Gaussian-mixture EKF (bank of components); M4/M5 when [mixture.learn] uses vb/gibbs; "
                         "M4 re-learned online with mixture.learn.online; M6 (coloured noise, paper P2) with "
                         "[mixture.colored]"),
    "imm": ("mixnav.filters.imm:ImmEkf",
            "M9 interacting multiple models (paper P4): EKF or robust modes with their own measurement "
            "sets ([methods.imm])"),
    "sage-husa": ("mixnav.filters.sage_husa:SageHusaEkf",
                  "Sage-Husa adaptive EKF: a measurement-noise variance scale per observable kind, learned "
                  "online with a fading memory (options: fading, scale0)"),
    "ukf": ("mixnav.filters.ukf:UnscentedKalmanFilter",
            "M7 unscented Kalman filter: sigma points mechanized as full states, loose or tight GNSS "
            "through predict_batch (options: alpha, beta, kappa, substeps)"),
    "vb-aukf": ("mixnav.filters.ukf:VbAdaptiveUkf",
                "M7 variational-Bayes adaptive UKF (paper P5): an inverse-Gamma noise variance per "
                "measurement channel with forgetting (options: rho, prior_shape, prior_scale, iterations, "
                "tolerance and the UKF's)"),
    "vb-akf": ("mixnav.filters.vb:VbAdaptiveEkf",
               "variational-Bayes adaptive EKF: the VB-AUKF's noise step on the EKF (options: rho, "
               "prior_shape, prior_scale, iterations, tolerance)"),
    "epoch-mixture": ("mixnav.filters.epoch_mixture:EpochMixtureEkf",
                      "whole-epoch LOS/NLOS mixture update (issue 21): responsibilities of every pseudorange "
                      "of an epoch against one state, the delay distribution learned online (options: "
                      "los_weight, delay_mean, delay_sd, learn, learn_scale, forget, prior_rows, iterations)"),
    "pf": ("mixnav.filters.particle:ParticleFilter",
           "SIR particle filter (issue 19): particles as full states mechanized over each IMU block, "
           "Gaussian log-weights through predict_batch, systematic resampling (options: particles, "
           "resample_threshold, roughening, substeps, parallel)"),
    "dd2": ("mixnav.filters.dd2:Dd2Filter",
            "second-order divided-difference filter (Norgaard et al. 2000; issue 19): 2n+1 points "
            "mechanized as full states, loose or tight GNSS through predict_batch (options: dd2_step, "
            "substeps)"),
    "gmpf": ("mixnav.filters.gmpf:GaussianMixtureParticleFilter",
             "M8 Gaussian-mixture particle filter (paper P3): DD2 per mixture component builds the "
             "importance density from the newest measurement, weighted EM refit instead of resampling "
             "(options: particles, components, em_iterations, dd2_step, sampling, substeps)"),
}

#: measurement types (``type = "..."``) -> one-line description
METHOD_TYPES = {
    "loose-ekf": "GNSS position/velocity (loose coupling)",
    "tight-ekf": "pseudorange + Doppler (tight coupling, 17 states)",
    "tdcp-ekf": "pseudorange + TDCP (P1 eqs. 1-4; stochastic cloning of the previous antenna position and clock)",
}


def filter_class(name: str):
    """The filter class registered as ``name`` (imported now)."""
    try:
        target = ESTIMATORS[name][0]
    except KeyError:
        raise ArgumentError(f"unknown estimator '{name}' (known: {', '.join(ESTIMATORS)})",
                            argument="estimator") from None
    module, _, attr = target.partition(":")
    return getattr(import_module(module), attr)
