"""The settings of the Gaussian-mixture bank (``estimator = "gaussian-mixture"``, a method's or
an IMM mode's ``[mixture]`` table): its mixtures, given or learned (offline, online), its
guards, and the coloured-noise variant's ``[mixture.colored]`` (mixnav.filters.colored).
Light to import (pydantic and units only): the registration of mixnav.filters.gmekf
names :class:`MixtureOptions` as its options.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, Field, model_validator

from .option_fields import STRICT, Duration


class MixtureSpec(BaseModel):
    """A 1-D mixture of a standardised noise: ``weights`` summing to 1,
    ``means`` (in units of the model's sigma; default zeros) and variance
    ``scales`` (multiples of the model's variance)."""

    model_config = STRICT

    weights: list[Annotated[float, Field(ge=0)]] = Field(min_length=1)
    means: list[float] | None = None
    scales: list[Annotated[float, Field(gt=0)]]

    @model_validator(mode="after")
    def _consistent(self):
        k = len(self.weights)
        if len(self.scales) != k or (self.means is not None and len(self.means) != k):
            raise ValueError("weights, means and scales need one entry per component")
        if abs(sum(self.weights) - 1.0) > 1e-6:
            raise ValueError(f"weights must sum to 1, got {sum(self.weights):.6g}")
        return self


class OnlineLearnOptions(BaseModel):
    """Online re-learning of the measurement mixtures (M4 beyond paper P1,
    ``mixture.learn.online``; see :mod:`mixnav.noise.learn.online`): per observable
    kind of ``learn.observables``, the last ``window`` rows' standardised
    innovations (rows, not epochs: 600 pseudorange rows are about 70 s of 8-9
    satellites at 1 Hz) are refitted by VB, warm-started from the mixture in
    use, every ``every`` measurement epochs once the window is full (default
    20: a third of a 600-row window is new at each refit; the window, not
    ``every``, sets how fast a change is tracked). Rows more than ``gate``
    standard deviations from every component of the mixture in use are left
    out of the fit (gross errors)."""

    model_config = STRICT

    window: int = Field(default=600, ge=20)
    every: int = Field(default=20, ge=1)
    gate: float = Field(default=10.0, ge=3)


class LearnOptions(BaseModel):
    """Mixtures learned offline from a training stretch (M4: ``method = "vb"``,
    M5: ``"gibbs"``; ``"em"`` too). In a scenario the training residuals are
    the scenario's own noise processes drawn over a separate stretch
    (``training_samples`` residuals per mixture, stream ``training``) and
    standardised by the sigma the filter is told.

    ``online`` (a table, :class:`OnlineLearnOptions`) also re-learns the
    ``observables``' mixtures online from the filter's innovations (VB only).
    ``offline = false`` skips the training stretch: the online learner then
    starts from the mixtures given under ``mixture.measurement`` (Gaussian for
    a kind not given), which also works on real data. ``process`` (learn the
    process-noise mixture offline) defaults to ``offline``."""

    model_config = STRICT

    method: Literal["vb", "gibbs", "em"]
    observables: list[Literal["pseudorange", "range_rate", "tdcp", "position", "velocity"]] = \
        Field(default_factory=lambda: ["pseudorange", "tdcp"])
    process: bool | None = None
    training_samples: int = Field(default=2000, ge=10)
    n_components: int = Field(default=4, ge=1)
    gibbs_samples: int = Field(default=1000, ge=10)
    prune: float = Field(default=0.01, ge=0, lt=1)
    offline: bool = True
    online: OnlineLearnOptions | None = None

    @model_validator(mode="after")
    def _online(self):
        if self.online is not None and self.method != "vb":
            raise ValueError(f"online re-learning uses the VB learner (warm starts): it needs "
                             f"method = \"vb\", got \"{self.method}\"")
        if not self.offline:
            if self.online is None:
                raise ValueError("offline = false learns nothing: add an 'online' table "
                                 "(or give the mixtures under mixture.measurement without 'learn')")
            if self.process:
                raise ValueError("process = true needs the training stretch (offline = true): the "
                                 "process-noise mixture is not re-learned online")
        if self.online is not None:
            if not self.observables:
                raise ValueError("online re-learning needs at least one kind in 'observables'")
            if self.online.window < 10 * self.n_components:
                raise ValueError(f"online.window = {self.online.window} rows is too short for "
                                 f"n_components = {self.n_components}: give at least 10 rows per "
                                 f"component ({10 * self.n_components})")
        return self

    @property
    def learn_process(self) -> bool:
        """Whether the process-noise mixture is learned (offline)."""
        return self.offline if self.process is None else self.process


_Psi = Annotated[float, Field(gt=-1, lt=1)]


class ColoredOptions(BaseModel):
    """Coloured noise (M6, paper P2): AR(1) coefficients of the process noise
    (``process``, per ``process_interval``, on the epoch's white IMU noise) and
    of each observable's measurement noise (``measurement``, per epoch, per
    channel), each ``|psi| < 1``. With a ``[mixture.colored]`` table the mixtures
    are those of the white driving noises (P2 eqs. 6-7). ``"fit"`` fits the
    coefficient to the training stretch (AR(1) per channel, median over channels;
    scenarios only). ``channels`` overrides the coefficient of single channels,
    ``"<observable>:<id>" = psi`` with ``id`` the PRN (tight) or axis 0-2 (loose).
    See mixnav.filters.colored."""

    model_config = STRICT

    process: _Psi | Literal["fit"] = 0.0
    measurement: dict[Literal["pseudorange", "range_rate", "position", "velocity"], _Psi | Literal["fit"]] = \
        Field(default_factory=dict)
    process_interval: Duration = 1.0
    channels: dict[str, _Psi] = Field(default_factory=dict)


class MixtureOptions(BaseModel):
    """Gaussian-mixture EKF (``estimator = "gaussian-mixture"``): prior,
    process-noise and per-observable measurement-noise mixtures, given or
    learned, and the bank size after reduction; with ``colored``, the
    coloured-noise variant M6. The update's guards (:mod:`mixnav.filters._bank_kernels`):
    ``gate`` (rows whose state share of the predicted variance exceeds ``gate`` times the
    noise's use the mixture's moment-matched Gaussian), ``outlier_mean`` (components
    whose standardised mean exceeds it leave the rows they explain unused); the
    divergence safeguard:
    ``divergence_window`` epochs in a row with the merged NIS per row above
    ``divergence_nis`` add the initial covariance back (0: off). ``inf``, ``inf`` and
    0 give P1's plain update."""

    model_config = STRICT

    max_components: int = Field(default=16, ge=1)
    gate: float = Field(default=2.0, gt=0)
    outlier_mean: float = Field(default=4.0, gt=0)
    divergence_window: int = Field(default=10, ge=0)
    divergence_nis: float = Field(default=9.0, gt=0)
    prior: MixtureSpec | None = None
    process: MixtureSpec | None = None
    measurement: dict[Literal["pseudorange", "range_rate", "tdcp", "position", "velocity"], MixtureSpec] = \
        Field(default_factory=dict)
    learn: LearnOptions | None = None
    colored: ColoredOptions | None = None

    def training_needs(self) -> list:
        """The training stretch these settings learn from (registry.TrainingNeed): the offline
        learner's residuals, and the coloured variant's series (its measurement kinds and
        the learner's; at least 2000 samples)."""
        from .registry import TrainingNeed
        learn = self.learn
        residuals = series = None
        if learn is not None and learn.offline:
            residuals = (tuple(learn.observables), learn.training_samples, learn.learn_process)
        if self.colored is not None:
            kinds = set(self.colored.measurement) | (set(learn.observables) if learn is not None else set())
            series = (tuple(sorted(kinds)), max(learn.training_samples, 2000) if learn is not None else 2000,
                      self.colored.process == "fit" or (learn is not None and learn.learn_process))
        return [TrainingNeed(residuals, series)] if residuals or series else []
