"""Training stretches for learned noise mixtures (methods M4, M5).

P1 learns its mixtures offline "from a training stretch of residuals". In a
simulation the residuals of a stretch against the truth are exactly draws of
the scenario's noise processes, so the training set is those processes
sampled over a separate stretch (stream ``training`` of the run's seed: the
filter never sees the noise it is scored on), standardised by the sigma the
filter is told. For TDCP the residual is the difference of the carrier noise
of consecutive epochs, standardised by ``sqrt(2) sigma_cp``.
"""

from __future__ import annotations

import math

import numpy as np

from ..config.loader import gnss_noise, imu_white_noise, observable_noise
from ..config.scenario_schema import Scenario
from ..errors import ConfigError
from ..noise.processes import Gaussian
from .rng import Streams

#: Satellites (channels) drawn per training epoch.
TRAINING_CHANNELS = 12


def training_residuals(sc: Scenario, seed: int, observables, n_samples: int, process: bool,
                       source: str | None = None) -> dict[str, np.ndarray]:
    """Standardised training residuals per observable (and ``"process"``).

    Returns ``{kind: ndarray (n_samples,)}``; ``"process"`` holds the IMU
    white-noise multipliers (already standardised: the scenario's
    ``imu.white_noise`` process, or N(0, 1) when it has none), drawn like the
    simulation draws them: one value per IMU sample, or with
    ``imu.white_noise_hold`` one per hold interval (6 channels, epochs T apart).
    """
    rng = Streams(seed).get("training")
    out = {}
    sat = sc.gnss.satellites
    pr, rr, cp = observable_noise(sc, source)
    pos, vel = gnss_noise(sc, source)
    rate = sc.gnss.rate
    for kind in observables:
        if kind in ("pseudorange", "range_rate", "tdcp") and sat is None:
            raise ConfigError(f"cannot learn a {kind} mixture: the scenario has no [gnss.satellites]",
                              file=source, key="methods.mixture.learn.observables")
        c = TRAINING_CHANNELS
        epochs = math.ceil(n_samples / c) + 1
        t = np.arange(epochs) / rate
        if kind == "pseudorange":
            x = (pr or Gaussian(sat.pseudorange_sigma)).sample(t, c, rng) / sat.pseudorange_sigma
        elif kind == "range_rate":
            x = (rr or Gaussian(sat.range_rate_sigma)).sample(t, c, rng) / sat.range_rate_sigma
        elif kind == "tdcp":
            x = np.diff((cp or Gaussian(sat.carrier_sigma)).sample(t, c, rng), axis=0) / \
                (math.sqrt(2.0) * sat.carrier_sigma)
        else:
            c = 3
            t = np.arange(math.ceil(n_samples / c) + 1) / rate
            sig = np.asarray(sc.gnss.position_sigma if kind == "position" else
                             (sc.gnss.velocity_sigma or (1.0, 1.0, 1.0)), dtype=float)
            proc = (pos if kind == "position" else vel) or Gaussian(1.0)
            x = proc.sample(t, c, rng) / (sig if (pos if kind == "position" else vel) else 1.0)
        out[kind] = np.ravel(x)[:n_samples]
    if process:
        white = imu_white_noise(sc, source)
        hold = sc.imu.white_noise_hold
        k = np.arange(math.ceil(n_samples / 6) + 1)
        t = k / sc.imu.rate if hold is None else (k + 1) * hold
        out["process"] = np.ravel((white or Gaussian(1.0)).sample(t, 6, rng))[:n_samples]
    return out


def training_series(sc: Scenario, seed: int, kinds, n_epochs: int, process: bool,
                    source: str | None = None) -> dict[str, np.ndarray]:
    """Standardised training *time series* per observable (and ``"process"``), for
    the AR(1) fits and the whitened mixtures of the coloured-noise filter (M6).

    Returns ``{kind: ndarray (n_epochs, channels)}``: ``TRAINING_CHANNELS``
    satellites per epoch at the GNSS rate for ``"pseudorange"`` and
    ``"range_rate"``, and for ``"process"`` the 6 IMU white-noise multipliers
    sampled once per ``imu.white_noise_hold`` (or per IMU sample without one).
    Stream ``training-series`` of the run's seed (independent of the
    ``training`` stream of :func:`training_residuals`).
    """
    rng = Streams(seed).get("training-series")
    sat = sc.gnss.satellites
    pr, rr, _ = observable_noise(sc, source)
    t = np.arange(n_epochs) / sc.gnss.rate
    out = {}
    for kind in kinds:
        if sat is None or kind not in ("pseudorange", "range_rate"):
            raise ConfigError(f"cannot fit a {kind} AR(1) coefficient: a training series exists for the "
                              "pseudoranges and range rates of a scenario with [gnss.satellites]",
                              file=source, key="methods.mixture.colored.measurement")
        proc, sig = (pr, sat.pseudorange_sigma) if kind == "pseudorange" else (rr, sat.range_rate_sigma)
        out[kind] = (proc or Gaussian(sig)).sample(t, TRAINING_CHANNELS, rng) / sig
    if process:
        white = imu_white_noise(sc, source)
        hold = getattr(sc.imu, "white_noise_hold", None)
        tp = np.arange(n_epochs) * (hold if hold else 1.0 / sc.imu.rate)
        out["process"] = (white or Gaussian(1.0)).sample(tp, 6, rng)
    return out
