"""A method entry (``[[methods]]``) and its estimator tables: the robust EKF's, the
Gaussian-mixture bank's (given, learned offline or online, coloured), the EM bias removal's
and the IMM's; and the checks, against the estimator registry
(:mod:`mixnav.filters.registry`), of an estimator's name and ``[options]`` that every kind of
file uses.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Union

from pydantic import Field, field_validator, model_validator

from ..errors import ArgumentError
from ..markov import check_transition
from ..names import safe_name
from .fields import Duration, PosLength, Strict


class RobustConfig(Strict):
    """Robust adaptive EKF (``estimator = "robust-adaptive"``): IGG-III
    thresholds ``k0 < k1`` on standardised innovations and the adaptive-factor
    threshold ``c`` (see mixnav.filters.robust)."""

    k0: float = Field(default=2.5, gt=0)
    k1: float = Field(default=5.0, gt=0)
    c: float = Field(default=1.5, gt=0)

    @model_validator(mode="after")
    def _order(self):
        if not self.k0 < self.k1:
            raise ValueError(f"need k0 < k1, got k0 = {self.k0}, k1 = {self.k1}")
        return self


class MixtureSpec(Strict):
    """A 1-D mixture of a standardised noise: ``weights`` summing to 1,
    ``means`` (in units of the model's sigma; default zeros) and variance
    ``scales`` (multiples of the model's variance)."""

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


class OnlineLearnConfig(Strict):
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

    window: int = Field(default=600, ge=20)
    every: int = Field(default=20, ge=1)
    gate: float = Field(default=10.0, ge=3)


class LearnConfig(Strict):
    """Mixtures learned offline from a training stretch (M4: ``method = "vb"``,
    M5: ``"gibbs"``; ``"em"`` too). In a scenario the training residuals are
    the scenario's own noise processes drawn over a separate stretch
    (``training_samples`` residuals per mixture, stream ``training``) and
    standardised by the sigma the filter is told.

    ``online`` (a table, :class:`OnlineLearnConfig`) also re-learns the
    ``observables``' mixtures online from the filter's innovations (VB only).
    ``offline = false`` skips the training stretch: the online learner then
    starts from the mixtures given under ``mixture.measurement`` (Gaussian for
    a kind not given), which also works on real data. ``process`` (learn the
    process-noise mixture offline) defaults to ``offline``."""

    method: Literal["vb", "gibbs", "em"]
    observables: list[Literal["pseudorange", "range_rate", "tdcp", "position", "velocity"]] = \
        Field(default_factory=lambda: ["pseudorange", "tdcp"])
    process: bool | None = None
    training_samples: int = Field(default=2000, ge=10)
    n_components: int = Field(default=4, ge=1)
    gibbs_samples: int = Field(default=1000, ge=10)
    prune: float = Field(default=0.01, ge=0, lt=1)
    offline: bool = True
    online: OnlineLearnConfig | None = None

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


class ColoredConfig(Strict):
    """Coloured noise (M6, paper P2): AR(1) coefficients of the process noise
    (``process``, per ``process_interval``, on the epoch's white IMU noise) and
    of each observable's measurement noise (``measurement``, per epoch, per
    channel), each ``|psi| < 1``. With a ``[mixture.colored]`` table the mixtures
    are those of the white driving noises (P2 eqs. 6-7). ``"fit"`` fits the
    coefficient to the training stretch (AR(1) per channel, median over channels;
    scenarios only). ``channels`` overrides the coefficient of single channels,
    ``"<observable>:<id>" = psi`` with ``id`` the PRN (tight) or axis 0-2 (loose).
    See mixnav.filters.colored."""

    process: _Psi | Literal["fit"] = 0.0
    measurement: dict[Literal["pseudorange", "range_rate", "position", "velocity"], _Psi | Literal["fit"]] = \
        Field(default_factory=dict)
    process_interval: Duration = 1.0
    channels: dict[str, _Psi] = Field(default_factory=dict)


class MixtureConfig(Strict):
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

    max_components: int = Field(default=16, ge=1)
    gate: float = Field(default=2.0, gt=0)
    outlier_mean: float = Field(default=4.0, gt=0)
    divergence_window: int = Field(default=10, ge=0)
    divergence_nis: float = Field(default=9.0, gt=0)
    prior: MixtureSpec | None = None
    process: MixtureSpec | None = None
    measurement: dict[Literal["pseudorange", "range_rate", "tdcp", "position", "velocity"], MixtureSpec] = \
        Field(default_factory=dict)
    learn: LearnConfig | None = None
    colored: ColoredConfig | None = None


class EmBiasConfig(Strict):
    """The EM multipath-bias removal of an EM-IMM mode (``[methods.imm.modes.em]``,
    :mod:`mixnav.filters.em_bias`): the sliding ``window`` [s], ``min_samples`` in it before
    a fit (at least the two components), ``min_separation`` [m] (also at least
    ``min_separation_sigmas`` of the biased component's spread) and ``min_weight`` of the
    biased component before a bias is declared, ``max_state_sigma`` [m] (innovations enter
    the window only while the state's position sigma is at most this; default a third of
    ``min_separation``) and ``gate`` (chi-square probability above which position rows the
    current noise model cannot explain are kept out of the update), ``refit_every`` (epochs
    between EM fits, each warm-started from the last)."""

    window: Duration = 60.0  # type: ignore[valid-type]
    min_samples: int = Field(default=20, ge=2, description="at least one sample per component")
    min_separation: PosLength = 3.0  # type: ignore[valid-type]
    min_weight: float = Field(default=0.05, ge=0.0, lt=0.5)
    min_separation_sigmas: float = Field(default=2.0, ge=0.0)
    max_state_sigma: PosLength | None = None  # type: ignore[valid-type]
    gate: float = Field(default=0.9999, gt=0.5, lt=1.0)
    refit_every: int = Field(default=5, ge=1)


class ImmModeConfig(Strict):
    """One mode of an IMM (``[[methods.imm.modes]]``): its name, the measurements that update
    it (``"gnss"``, the method type's GNSS model, and any of the method's ``aiding``) and
    its estimator: ``"ekf"``, ``"robust-adaptive"`` (optional ``[robust]`` table),
    ``"em-bias"`` (the EM-IMM's GNSS mode: the EKF with the EM multipath-bias removal on its
    GNSS rows, optional ``[em]`` table) or ``"gaussian-mixture"`` (a bank, optional
    ``[mixture]`` table as a method's, learned offline or online; not coloured)."""

    name: str = Field(min_length=1)
    measurements: list[Literal["gnss", "nhc", "odometer", "zupt", "zaru"]] = Field(
        min_length=1, description="a mode with no measurements is pure inertial navigation, never told apart")
    #: a registered estimator that can be a mode (``imm_mode`` in mixnav.filters.registry)
    estimator: str = "ekf"
    robust: RobustConfig | None = None
    em: EmBiasConfig | None = None
    mixture: MixtureConfig | None = None

    @field_validator("estimator")
    @classmethod
    def _mode_estimator(cls, v):
        from ..filters.registry import estimator_names, estimator_spec
        try:
            ok = estimator_spec(v).imm_mode
        except ArgumentError:
            ok = False
        if not ok:
            modes = [n for n in estimator_names(standalone_only=False) if estimator_spec(n).imm_mode]
            raise ValueError(f"estimator '{v}' cannot be a mode of an IMM (these can: {', '.join(modes)})")
        return v

    @model_validator(mode="after")
    def _unique(self):
        if len(set(self.measurements)) != len(self.measurements):
            raise ValueError(f"a measurement is listed twice: {self.measurements}")
        if self.robust is not None and self.estimator != "robust-adaptive":
            raise ValueError("a [robust] table needs estimator = \"robust-adaptive\"")
        if self.em is not None and self.estimator != "em-bias":
            raise ValueError("an [em] table needs estimator = \"em-bias\"")
        if self.mixture is not None and self.estimator != "gaussian-mixture":
            raise ValueError("a [mixture] table needs estimator = \"gaussian-mixture\"")
        if self.mixture is not None and self.mixture.colored is not None:
            raise ValueError("a mode cannot be the coloured-noise bank (M6: it differences the measurements "
                             "and carries AR(1) states the other modes do not have)")
        if self.estimator == "em-bias" and "gnss" not in self.measurements:
            raise ValueError("an em-bias mode removes a bias from the GNSS: list \"gnss\" in its measurements")
        return self


class ImmConfig(Strict):
    """Interacting multiple models (``estimator = "imm"``, :mod:`mixnav.filters.imm`).

    ``transition[i][j]``: probability of mode j one ``transition_interval`` after mode i
    (rows sum to one; default interval 1 s, or ``"epoch"`` to apply it once per
    measurement epoch as P4 does); ``initial_probabilities`` default uniform; ``output``
    ``"combined"`` (P4, default) or ``"most-probable"`` (the likeliest mode fed back and
    recorded).
    """

    modes: list[ImmModeConfig] = Field(min_length=2)
    transition: list[list[float]]
    transition_interval: Union[Duration, Literal["epoch"]] = 1.0  # type: ignore[valid-type]
    initial_probabilities: list[float] | None = None
    output: Literal["combined", "most-probable"] = "combined"

    @field_validator("transition")
    @classmethod
    def _stochastic(cls, v):
        try:
            check_transition(v)
        except ArgumentError as e:
            raise ValueError(e.message) from None
        return v

    @model_validator(mode="after")
    def _shapes(self):
        r = len(self.modes)
        if len(self.transition) != r:
            raise ValueError(f"transition must be {r} x {r} (one row and column per mode), got "
                             f"{len(self.transition)} rows")
        if self.initial_probabilities is not None:
            p = self.initial_probabilities
            if len(p) != r or any(x < 0 for x in p) or abs(sum(p) - 1.0) > 1e-9:
                raise ValueError(f"initial_probabilities must be {r} non-negative numbers summing to 1, got {p}")
        names = [m.name for m in self.modes]
        if len(set(names)) != len(names):
            raise ValueError(f"mode names must be unique, got {names}")
        return self


def method_file_name(name: str) -> str:
    """``name`` if it can be one file-name component (it becomes ``solution_<name>.csv``,
    docs/validation.md); otherwise a ValueError saying why."""
    try:
        return safe_name(name, "method name")
    except ArgumentError as exc:
        raise ValueError(exc.message) from None


def registered_estimator(name: str, motion: str) -> str:
    """``name`` if the estimator registry (:mod:`mixnav.filters.registry`) knows it and it runs
    on ``motion``; otherwise a ValueError saying which are registered or where it runs."""
    from ..filters.registry import check_motion
    try:
        check_motion(name, motion)
    except ArgumentError as exc:
        raise ValueError(exc.message) from None
    return name


def registered_options(name: str | None, options: dict) -> dict:
    """A method's ``[methods.options]`` checked against the options model the estimator
    registered: the same keys, validated values. The message starts with the option's key
    (``options.<key>: ...``), which the loader makes the error's key."""
    from ..filters.registry import estimator_spec
    if name is None or not options:
        return options
    try:
        spec = estimator_spec(name)
    except ArgumentError:
        return options          # the estimator's own check says it
    if spec.table is not None:
        raise ValueError(f"estimator \"{name}\" takes its settings from its own table ([{spec.table}]), "
                         "not [options]")
    try:
        checked = spec.parse_options(options)
    except ArgumentError as exc:
        raise ValueError(f"options.{exc.argument}: {exc.message}") from None
    return {k: getattr(checked, k) for k in options}


class MethodConfig(Strict):
    name: str
    type: Literal["loose-ekf", "tight-ekf", "tdcp-ekf"]
    #: a registered estimator (mixnav.filters.registry) that runs on the strapdown INS: "ekf" (M1),
    #: "robust-adaptive" (M2), "gaussian-mixture" (M3; M4/M5 with mixture.learn), "sage-husa", ...
    estimator: str = "ekf"
    robust: RobustConfig | None = None
    mixture: MixtureConfig | None = None
    imm: ImmConfig | None = None
    #: the settings of an estimator without a table of its own (its registered options model)
    options: dict[str, Any] = Field(default_factory=dict)
    states: Literal[15, 17, 21, 23] = 15
    covariance_interval: Duration = 1.0
    imu_grade: str | None = None
    imu_errors: dict[str, str | list[str]] | None = None
    use_range_rate: bool = True
    #: tdcp-ekf: "clone" (stochastic cloning of the previous antenna position and
    #: clock) or "known" (the shortcut that takes the previous estimate as exact)
    tdcp_previous: Literal["clone", "known"] = "clone"
    #: land-vehicle aiding this method uses (each configured in the file's [aiding] table)
    aiding: list[Literal["nhc", "odometer", "zupt", "zaru"]] = Field(default_factory=list)
    #: installation states this method estimates: "mounting" (pitch/yaw in the vehicle),
    #: "odometer_scale", "gnss_lever" (antenna lever-arm correction), "imu_time_offset"
    estimate: list[Literal["mounting", "odometer_scale", "gnss_lever", "imu_time_offset"]] = \
        Field(default_factory=list)
    #: also run the fixed-interval RTS smoother: adds a method "<name>-smoothed"
    smooth: bool = False

    @field_validator("name")
    @classmethod
    def _file_name(cls, v):
        return method_file_name(v)

    @field_validator("estimator")
    @classmethod
    def _known_estimator(cls, v):
        return registered_estimator(v, "strapdown")

    @field_validator("options")
    @classmethod
    def _typed_options(cls, v, info):
        return registered_options(info.data.get("estimator"), v)

    @model_validator(mode="after")
    def _estimator_tables(self):
        if self.options and self.estimator == "robust-adaptive":
            raise ValueError("estimator \"robust-adaptive\" takes its settings from its own table ([robust]), "
                             "not [options]")
        if self.robust is not None and self.estimator != "robust-adaptive":
            raise ValueError("a [robust] table needs estimator = \"robust-adaptive\"")
        if self.mixture is not None and self.estimator != "gaussian-mixture":
            raise ValueError("a [mixture] table needs estimator = \"gaussian-mixture\"")
        if (self.imm is not None) != (self.estimator == "imm"):
            raise ValueError("estimator = \"imm\" and an [imm] table go together")
        if self.imm is not None:
            for k, mode in enumerate(self.imm.modes):
                missing = [x for x in mode.measurements if x != "gnss" and x not in self.aiding]
                if missing:
                    raise ValueError(f"imm.modes[{k}] ('{mode.name}') uses {missing}, which the method's "
                                     f"aiding does not list ({self.aiding})")
        return self


