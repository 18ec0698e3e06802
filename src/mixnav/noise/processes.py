"""Composable, seeded noise processes to inject into any observable series.

Every process is a small frozen dataclass with

``sample(times, n_channels, rng) -> ndarray (n, n_channels)``
    Additive noise at the epochs ``times`` (n,) [s] for ``n_channels``
    independent (or, for a matrix AR(1), coupled) channels, e.g. the
    satellites of a pseudorange series or the three axes of a position fix.
    Values are SI in the observable's unit (m for pseudorange, m/s for
    Doppler, ...). Randomness comes only from the ``numpy.random.Generator``
    passed in; the same generator state gives the same numbers.
``sample_with_mask(times, n_channels, rng) -> (values, mask)``
    The same values plus a boolean (n, n_channels) mask of the gross errors
    injected (all False for processes without gross errors; :class:`Sum`
    combines the masks of its parts with OR).
``variance``
    The stationary marginal variance per sample [unit^2] (float, or (c,)
    ndarray when it differs per channel), ``None`` when the process is not
    stationary (bias segments, variance profiles, gross errors every N).
``describe()``
    One line of text for logs and reports.

Processes:

- :class:`Gaussian` white noise, :class:`Mixture` white Gaussian-mixture
  noise (1-D mixture per channel),
- :class:`GrossErrors` of a given size every N epochs or with probability p,
- :class:`AR1` coloured noise ``x_k = Psi x_{k-1} + w_k`` with scalar,
  per-channel or (c, c) matrix ``Psi`` and Gaussian or mixture innovation,
- :class:`BiasSegments` (multipath-like bias over time windows),
- :class:`VarianceProfile` scaling another process's standard deviation over
  time (jumps and slow drifts up and back),
- :class:`Sum` of any of the above,
- :class:`Outages`, not additive: a boolean availability mask.

The configuration layer builds any of them from a scenario's tables
(:func:`mixnav.config.noise_spec.from_config`: units parsed, errors naming
the key path). Errors in direct construction are
:class:`~mixnav.errors.ArgumentError` naming the argument; the config layer
re-raises them with the full key path and file.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import linalg as sla

from ..errors import ArgumentError
from ..linalg import ar1_recursion
from .mixture import GaussianMixture

__all__ = [
    "NoiseProcess", "Gaussian", "Mixture", "GrossErrors", "AR1", "BiasSegments",
    "VarianceProfile", "Sum", "Outages",
]


# --------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------
def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def _real_array(value, key: str, *, ndim_max: int = 1, nonnegative: bool = False,
                positive: bool = False) -> np.ndarray:
    """A finite float array of at most ``ndim_max`` dimensions, checked."""
    if isinstance(value, bool):
        raise ArgumentError(f"expected a number, got {value!r}", argument=key)
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ArgumentError(f"expected a number or a list of numbers, got {value!r}", argument=key) from None
    if a.ndim > ndim_max:
        raise ArgumentError(f"expected at most {ndim_max} dimension(s), got shape {a.shape}", argument=key)
    if a.size == 0:
        raise ArgumentError("must not be empty", argument=key)
    if not np.all(np.isfinite(a)):
        raise ArgumentError(f"must be finite, got {value!r}", argument=key)
    if nonnegative and np.any(a < 0):
        raise ArgumentError(f"must not be negative, got {value!r}", argument=key)
    if positive and np.any(a <= 0):
        raise ArgumentError(f"must be positive, got {value!r}", argument=key)
    a.setflags(write=False)
    return a


def _check_call(times, n_channels, rng) -> np.ndarray:
    """Validate the arguments of ``sample``; return ``times`` as a float (n,) array."""
    t = np.asarray(times, dtype=float)
    if t.ndim != 1:
        raise ValueError(f"times must be a 1-D array (n,) [s], got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("times must be finite")
    if isinstance(n_channels, bool) or not isinstance(n_channels, numbers.Integral) or n_channels < 1:
        raise ValueError(f"n_channels must be a positive integer, got {n_channels!r}")
    if not isinstance(rng, np.random.Generator):
        raise TypeError("pass an explicit numpy Generator (np.random.default_rng(seed)), "
                        f"got {type(rng).__name__}")
    return t


def _per_channel(a: np.ndarray, n_channels: int, what: str) -> np.ndarray:
    """Broadcast a scalar or (c,) parameter to (n_channels,)."""
    if a.ndim == 0:
        return np.full(n_channels, float(a))
    if a.shape != (n_channels,):
        raise ValueError(f"{what} has {a.shape[0]} values, one per channel, but n_channels={n_channels}")
    return a


def _fmt(a) -> str:
    a = np.asarray(a)
    if a.ndim == 0:
        return f"{float(a):.6g}"
    return np.array2string(a, precision=4, separator=", ")


class NoiseProcess:
    """Base class of additive noise processes (see the module docstring)."""

    def sample(self, times, n_channels: int, rng: np.random.Generator) -> np.ndarray:
        """Noise at ``times``.

        Parameters
        ----------
        times : array_like (n,)
            Epochs [s].
        n_channels : int
            Number of channels c.
        rng : numpy.random.Generator
            The only source of randomness.

        Returns
        -------
        ndarray (n, c)
            Additive noise in the observable's SI unit.
        """
        return self.sample_with_mask(times, n_channels, rng)[0]

    def sample_with_mask(self, times, n_channels: int, rng: np.random.Generator):
        """Noise and the (n, c) boolean mask of injected gross errors."""
        t = _check_call(times, n_channels, rng)
        x = self._sample(t, n_channels, rng)
        return x, np.zeros(x.shape, dtype=bool)

    def sample_detail(self, times, n_channels: int, rng: np.random.Generator):
        """Noise, gross-error mask and the *systematic* part (n, c) of the noise drawn: the
        mean of the component each sample came from (a multipath bias), a bias segment's
        value, zero for zero-mean white or coloured noise. The same draws as
        :meth:`sample_with_mask` (the same numbers from the same generator): the truth
        a bias estimator is scored against in simulation."""
        x, mask = self.sample_with_mask(times, n_channels, rng)
        return x, mask, np.zeros(x.shape)

    def _sample(self, t, n_channels, rng):  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def variance(self):
        """Stationary marginal variance [unit^2], or None when not stationary."""
        return None

    def sd(self, times, n_channels: int):
        """The marginal standard deviation at ``times`` (n, c) [unit], about the process's
        mean, or None when it is not known in closed form. Stationary processes give
        ``sqrt(variance)``; :class:`VarianceProfile` scales its base's; :class:`Sum`
        adds variances. The truth a noise-tracking filter (VB-AUKF) is scored against."""
        v = self.variance
        if v is None:
            return None
        t = np.asarray(times, dtype=float)
        return np.broadcast_to(np.sqrt(_per_channel(np.asarray(v, dtype=float), n_channels, "variance")),
                               (t.size, n_channels)).copy()

    def describe(self) -> str:
        return repr(self)


# --------------------------------------------------------------------------
# white noise
# --------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Gaussian(NoiseProcess):
    """White Gaussian noise ``N(0, sigma^2)``, independent over epochs and channels.

    Parameters
    ----------
    sigma : float or array_like (c,)
        Standard deviation [unit], >= 0; one per channel if a vector.
    """

    sigma: Any

    def __post_init__(self):
        object.__setattr__(self, "sigma", _real_array(self.sigma, "sigma", nonnegative=True))

    def _sample(self, t, c, rng):
        s = _per_channel(self.sigma, c, "sigma")
        return rng.standard_normal((t.size, c)) * s

    @property
    def variance(self):
        v = self.sigma ** 2
        return float(v) if v.ndim == 0 else v

    def describe(self) -> str:
        return f"white Gaussian, sigma={_fmt(self.sigma)}"


@dataclass(frozen=True, eq=False)
class Mixture(NoiseProcess):
    """White 1-D Gaussian-mixture noise, drawn independently per epoch and channel.

    Each sample picks component k with probability ``weights[k]`` and is then
    ``N(means[k], sigmas[k]^2)``.

    Parameters
    ----------
    weights : array_like (K,) or GaussianMixture
        Non-negative, summing to 1 (within 1e-6). A
        :class:`~mixnav.noise.mixture.GaussianMixture` of dimension 1 may be
        passed instead, with ``sigmas`` and ``means`` left out.
    sigmas : array_like (K,)
        Component standard deviations [unit], >= 0.
    means : float or array_like (K,), default 0
        Component means [unit]. Non-zero means make the noise biased.
    joint : bool, default False
        One component per epoch for all channels (a multipath episode biases every
        axis of a fix at once) instead of one per epoch and channel.
    """

    weights: Any
    sigmas: Any = None
    means: Any = 0.0
    joint: bool = False

    def __post_init__(self):
        w = self.weights
        if isinstance(w, GaussianMixture):
            if w.dim != 1:
                raise ArgumentError(f"a GaussianMixture of dimension {w.dim} was given; "
                                  "Mixture noise needs dimension 1 (one scalar per channel)", argument="weights")
            if self.sigmas is not None:
                raise ArgumentError("give either a GaussianMixture or sigmas, not both", argument="sigmas")
            gm = w
            w, sig, mu = gm.weights, np.sqrt(gm.covariances[:, 0, 0]), gm.means[:, 0]
        else:
            if self.sigmas is None:
                raise ArgumentError("sigmas are required (one per component)", argument="sigmas")
            sig, mu = self.sigmas, self.means
        w = _real_array(w, "weights", nonnegative=True)
        sig = _real_array(sig, "sigmas", nonnegative=True)
        mu = _real_array(mu, "means")
        if w.ndim != 1:
            w = _readonly(np.atleast_1d(w))
        if sig.shape != w.shape:
            raise ArgumentError(f"{sig.size} sigmas for {w.size} weights; give one per component",
                              argument="sigmas")
        if mu.ndim == 0:
            mu = _readonly(np.full(w.shape, float(mu)))
        elif mu.shape != w.shape:
            raise ArgumentError(f"{mu.size} means for {w.size} weights; give one per component", argument="means")
        if abs(w.sum() - 1.0) > 1e-6:
            raise ArgumentError(f"weights sum to {w.sum():.9g}, not 1", argument="weights")
        w = _readonly(w / w.sum())
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "sigmas", sig)
        object.__setattr__(self, "means", mu)

    def _sample(self, t, c, rng):
        return self._draw(t, c, rng)[0]

    def _draw(self, t, c, rng):
        """The samples and the mean of each sample's component."""
        if self.joint:
            labels = np.repeat(rng.choice(self.weights.size, size=(t.size, 1), p=self.weights), c, axis=1)
        else:
            labels = rng.choice(self.weights.size, size=(t.size, c), p=self.weights)
        z = rng.standard_normal((t.size, c))
        mu = self.means[labels]
        return mu + self.sigmas[labels] * z, mu

    def sample_detail(self, times, n_channels, rng):
        t = _check_call(times, n_channels, rng)
        x, mu = self._draw(t, n_channels, rng)
        return x, np.zeros(x.shape, dtype=bool), mu

    @property
    def mean(self) -> float:
        """Mixture mean [unit]."""
        return float(self.weights @ self.means)

    @property
    def variance(self) -> float:
        """``sum_k w_k (sigma_k^2 + (mu_k - mu)^2)`` [unit^2]."""
        d = self.means - self.mean
        return float(self.weights @ (self.sigmas ** 2 + d ** 2))

    @property
    def excess_kurtosis(self) -> float:
        """``m4 / m2^2 - 3`` with ``m4 = sum_k w_k (3 s^4 + 6 s^2 d^2 + d^4)``, d = mu_k - mu."""
        d = self.means - self.mean
        s2 = self.sigmas ** 2
        m4 = float(self.weights @ (3 * s2 ** 2 + 6 * s2 * d ** 2 + d ** 4))
        return m4 / self.variance ** 2 - 3.0

    def describe(self) -> str:
        s = f"Gaussian mixture, weights={_fmt(self.weights)}, sigmas={_fmt(self.sigmas)}"
        if np.any(self.means != 0):
            s += f", means={_fmt(self.means)}"
        if self.joint:
            s += ", one component per epoch for all channels"
        return s


# --------------------------------------------------------------------------
# gross errors
# --------------------------------------------------------------------------
_SIGNS = {"random": 0, "+": 1, "positive": 1, 1: 1, "-": -1, "negative": -1, -1: -1}


@dataclass(frozen=True, eq=False)
class GrossErrors(NoiseProcess):
    """Gross errors (outliers) of fixed magnitude at chosen or random epochs.

    Exactly one of ``every`` and ``probability`` is given:

    - ``every=N``: at epoch indices ``start, start+N, start+2N, ...`` every
      selected channel gets a gross error;
    - ``probability=p``: from epoch index ``start`` on, each (epoch, channel)
      of the selected channels independently gets one with probability p.

    Elsewhere the process is exactly zero. Use :meth:`sample_with_mask` to
    learn where they occurred.

    Parameters
    ----------
    size : float
        Magnitude s [unit], >= 0.
    every : int, optional
        Period N >= 1 in epochs.
    probability : float, optional
        Rate p in [0, 1].
    start : int, default 0
        First epoch index (not a time) that may carry a gross error.
    sign : {"random", "+", "-"} or {1, -1}, default "random"
        "random": +s or -s with probability 1/2 each, drawn independently for
        every gross error; "+"/1 always +s; "-"/-1 always -s.
    channels : sequence of int, optional
        Channel indices affected; default all.
    """

    size: float
    every: int | None = None
    probability: float | None = None
    start: int = 0
    sign: Any = "random"
    channels: Any = None

    def __post_init__(self):
        size = float(_real_array(self.size, "size", ndim_max=0, nonnegative=True))
        object.__setattr__(self, "size", size)
        if (self.every is None) == (self.probability is None):
            raise ArgumentError("give exactly one of 'every' (epochs) and 'probability'", argument="every")
        if self.every is not None:
            _int(self.every, "every", minimum=1)
        if self.probability is not None:
            p = float(_real_array(self.probability, "probability", ndim_max=0, nonnegative=True))
            if p > 1:
                raise ArgumentError(f"must be in [0, 1], got {p:g}", argument="probability")
            object.__setattr__(self, "probability", p)
        _int(self.start, "start", minimum=0)
        if isinstance(self.sign, bool) or not isinstance(self.sign, (str, int)) or self.sign not in _SIGNS:
            raise ArgumentError(f"sign must be 'random', '+' or '-', got {self.sign!r}", argument="sign")
        if self.channels is not None:
            ch = [_int(v, f"channels[{i}]", minimum=0) for i, v in enumerate(np.atleast_1d(self.channels))]
            object.__setattr__(self, "channels", tuple(ch))

    def _channel_mask(self, c: int) -> np.ndarray:
        sel = np.ones(c, dtype=bool)
        if self.channels is not None:
            if max(self.channels) >= c:
                raise ValueError(f"gross-error channel {max(self.channels)} does not exist "
                                 f"(n_channels={c})")
            sel[:] = False
            sel[list(self.channels)] = True
        return sel

    def sample_with_mask(self, times, n_channels, rng):
        t = _check_call(times, n_channels, rng)
        n, c = t.size, n_channels
        k = np.arange(n)
        eligible = (k >= self.start)[:, None] & self._channel_mask(c)[None, :]
        if self.every is not None:
            mask = eligible & ((k - self.start) % self.every == 0)[:, None]
        else:
            mask = eligible & (rng.random((n, c)) < self.probability)
        s = _SIGNS[self.sign]
        if s == 0:
            signs = np.where(rng.random((n, c)) < 0.5, -1.0, 1.0)
        else:
            signs = float(s)
        return np.where(mask, signs * self.size, 0.0), mask

    @property
    def variance(self):
        # stationary only in the random-rate case (E x^2 = p s^2)
        if self.probability is None:
            return None
        return self.probability * self.size ** 2

    def describe(self) -> str:
        when = f"every {self.every} epochs" if self.every is not None else f"with probability {self.probability:g}"
        sign = {0: "random sign", 1: "positive", -1: "negative"}[_SIGNS[self.sign]]
        return f"gross errors of {self.size:g} ({sign}) {when} from epoch {self.start}"


def _int(v, key: str, minimum: int | None = None) -> int:
    if isinstance(v, bool) or not isinstance(v, (numbers.Integral, float, np.floating)) \
            or (isinstance(v, (float, np.floating)) and not float(v).is_integer()):
        raise ArgumentError(f"expected an integer, got {v!r}", argument=key)
    v = int(v)
    if minimum is not None and v < minimum:
        raise ArgumentError(f"must be at least {minimum}, got {v}", argument=key)
    return v


def _is_white(p) -> bool:
    """True for stationary white processes (usable as an AR(1) innovation)."""
    if isinstance(p, Sum):
        return all(_is_white(q) for q in p.processes)
    return isinstance(p, (Gaussian, Mixture)) or (isinstance(p, GrossErrors) and p.probability is not None)


# --------------------------------------------------------------------------
# AR(1)
# --------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class AR1(NoiseProcess):
    """First-order autoregressive (coloured) noise ``x_k = Psi x_{k-1} + w_k``.

    The recursion runs per epoch (index k), whatever the spacing of
    ``times``; for a correlation time tau at interval dt use
    ``Psi = exp(-dt / tau)``.

    Parameters
    ----------
    coefficient : float, array_like (c,) or array_like (c, c)
        Psi: one coefficient for all channels, one per channel, or a matrix
        coupling the channels. Its spectral radius must be < 1 (stationary);
        otherwise the process grows without bound and an ArgumentError says so.
    sigma : float or array_like (c,), optional
        Standard deviation of the *innovation* (driving noise) w_k [unit],
        white Gaussian, independent across channels. Not the stationary sd:
        for a scalar Psi the stationary variance is
        ``sigma^2 / (1 - Psi^2)``; for a matrix it is the solution P of the
        discrete Lyapunov equation ``P = Psi P Psi^T + diag(sigma^2)``.
    innovation : NoiseProcess, optional
        A white process (e.g. :class:`Mixture`) to drive the recursion instead
        of the Gaussian one; give either ``sigma`` or ``innovation``. Its
        ``variance`` must be defined (it sets the stationary start).

    Notes
    -----
    Stationary start: x_0 is drawn from ``N(0, P)``, so the series is
    (second-order) stationary from the first epoch. With a non-Gaussian
    innovation the marginal distribution of the first ~1/(1-|Psi|) epochs is
    Gaussian rather than the exact stationary shape; the covariance is right
    throughout. The filtering uses ``mixnav.linalg.ar1_recursion`` per channel
    (after a complex Schur decomposition when Psi is a full matrix).
    """

    coefficient: Any
    sigma: Any = None
    innovation: NoiseProcess | None = None

    def __post_init__(self):
        psi = _real_array(self.coefficient, "coefficient", ndim_max=2)
        if psi.ndim == 2 and psi.shape[0] != psi.shape[1]:
            raise ArgumentError(f"a coefficient matrix must be square (c, c), got shape {psi.shape}",
                              argument="coefficient")
        rho = float(np.max(np.abs(np.linalg.eigvals(psi)))) if psi.ndim == 2 else float(np.max(np.abs(psi)))
        if not rho < 1.0:
            raise ArgumentError(
                f"AR(1) coefficient has spectral radius {rho:.6g} >= 1: the process is not stationary "
                "and grows without bound (coefficients of 1.0-1.5 as printed in some papers diverge); "
                "use a coefficient with |Psi| < 1, e.g. exp(-dt/tau) for correlation time tau",
                argument="coefficient")
        object.__setattr__(self, "coefficient", psi)
        if (self.sigma is None) == (self.innovation is None):
            raise ArgumentError("give exactly one of 'sigma' (Gaussian innovation sd) and 'innovation'",
                              argument="sigma")
        if self.sigma is not None:
            object.__setattr__(self, "sigma", _real_array(self.sigma, "sigma", nonnegative=True))
        else:
            if not _is_white(self.innovation):
                raise ArgumentError("innovation must be a stationary white process (Gaussian, Mixture, "
                                  f"or a Sum of them), got {self.innovation!r}", argument="innovation")
        nc = self._fixed_channels()
        if nc is not None and self.sigma is not None and self.sigma.ndim == 1 and self.sigma.size != nc:
            raise ArgumentError(f"{self.sigma.size} innovation sigmas for a {nc}-channel coefficient",
                              argument="sigma")

    def _fixed_channels(self) -> int | None:
        return None if self.coefficient.ndim == 0 else self.coefficient.shape[0]

    def _innovation_variance(self, c: int) -> np.ndarray:
        v = self.sigma ** 2 if self.sigma is not None else np.asarray(self.innovation.variance, dtype=float)
        return _per_channel(v, c, "innovation variance")

    def _psi_matrix(self, c: int) -> np.ndarray:
        psi = self.coefficient
        if psi.ndim == 2:
            if psi.shape[0] != c:
                raise ValueError(f"the AR(1) coefficient matrix is {psi.shape}, but n_channels={c}")
            return psi
        return np.diag(_per_channel(psi, c, "AR(1) coefficient"))

    def stationary_covariance(self, n_channels: int | None = None) -> np.ndarray:
        """Stationary covariance P (c, c) [unit^2]: ``P = Psi P Psi^T + Q``.

        Parameters
        ----------
        n_channels : int, optional
            Needed when the coefficient and sigma are scalars.
        """
        c = n_channels or self._fixed_channels() or (self.sigma.size if self.sigma is not None
                                                     and self.sigma.ndim == 1 else None)
        if c is None:
            raise ValueError("n_channels is needed for a scalar coefficient and sigma")
        psi = self._psi_matrix(c)
        q = self._innovation_variance(c)
        if self.coefficient.ndim < 2:
            return np.diag(q / (1.0 - np.diag(psi) ** 2))
        p = sla.solve_discrete_lyapunov(psi, np.diag(q))
        return 0.5 * (p + p.T)

    @property
    def variance(self):
        """Stationary variance per channel [unit^2] (float when one value fits all)."""
        if self.coefficient.ndim == 2:
            return np.diag(self.stationary_covariance())
        q = self.sigma ** 2 if self.sigma is not None else np.asarray(self.innovation.variance, dtype=float)
        v = q / (1.0 - self.coefficient ** 2)
        return float(v) if np.ndim(v) == 0 else np.asarray(v)

    def _sample(self, t, c, rng):
        n = t.size
        if self.coefficient.ndim < 2:
            a = _per_channel(self.coefficient, c, "AR(1) coefficient")
            # stationary start x_0 ~ N(0, q / (1 - psi^2)) per channel
            x0 = np.sqrt(self._innovation_variance(c) / (1.0 - a ** 2)) * rng.standard_normal(c)
        else:
            psi = self._psi_matrix(c)
            # stationary start x_0 ~ N(0, P) via a symmetric square root (P may be singular)
            ev, vec = np.linalg.eigh(self.stationary_covariance(c))
            x0 = vec @ (np.sqrt(np.clip(ev, 0.0, None)) * rng.standard_normal(c))
        if self.sigma is not None:
            w = rng.standard_normal((n, c)) * _per_channel(self.sigma, c, "sigma")
        else:
            w = np.asarray(self.innovation.sample(t, c, rng), dtype=float)
        x = np.empty((n, c))
        if n == 0:
            return x
        x[0] = x0
        if n == 1:
            return x
        if self.coefficient.ndim == 0:     # one filter for all channels
            a0 = float(self.coefficient)
            x[1:] = ar1_recursion(np.ascontiguousarray(w[1:]), np.full(c, a0), np.asarray(x0, dtype=float))
            return x
        if self.coefficient.ndim == 1:
            x[1:] = ar1_recursion(np.ascontiguousarray(w[1:]), np.asarray(a, dtype=float), np.asarray(x0, dtype=float))
            return x
        # matrix Psi = Z T Z^H (complex Schur, T upper triangular): z = Z^H x obeys
        # z_k = T z_{k-1} + Z^H w_k; solve from the last mode up, each one a scalar
        # lfilter whose input includes the lagged modes below it.
        from scipy.signal import lfilter   # complex modes: rare, imported when needed
        tt, zz = sla.schur(psi.astype(complex), output="complex")
        u = w[1:] @ zz.conj()            # (n-1, c): rows are (Z^H w_k)^T
        z = np.empty((n, c), dtype=complex)
        z[0] = zz.conj().T @ x0
        for i in range(c - 1, -1, -1):
            drive = u[:, i] + z[:-1, i + 1:] @ tt[i, i + 1:]
            z[1:, i], _ = lfilter([1.0], [1.0, -tt[i, i]], drive, zi=[tt[i, i] * z[0, i]])
        return (z @ zz.T).real

    def describe(self) -> str:
        drive = f"innovation sigma={_fmt(self.sigma)}" if self.sigma is not None \
            else f"innovation: {self.innovation.describe()}"
        return f"AR(1), coefficient={_fmt(self.coefficient)}, {drive}"


# --------------------------------------------------------------------------
# time-dependent processes
# --------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class BiasSegments(NoiseProcess):
    """Constant biases over time windows (e.g. multipath), deterministic.

    Parameters
    ----------
    segments : sequence of (start, end, bias)
        Window ``start <= t < end`` [s] and bias [unit]: a float for all
        channels or a (c,) vector (0 for the channels not affected).
        Overlapping segments add.
    """

    segments: Any = ()

    def __post_init__(self):
        out = []
        for i, seg in enumerate(self.segments):
            key = f"segments[{i}]"
            if not isinstance(seg, (tuple, list)) or len(seg) != 3:
                raise ArgumentError(f"expected (start, end, bias), got {seg!r}", argument=key)
            t0 = float(_real_array(seg[0], key + ".start", ndim_max=0))
            t1 = float(_real_array(seg[1], key + ".end", ndim_max=0))
            if not t1 > t0:
                raise ArgumentError(f"end ({t1:g} s) must be after start ({t0:g} s)", argument=key)
            out.append((t0, t1, _real_array(seg[2], key + ".bias")))
        object.__setattr__(self, "segments", tuple(out))

    def _sample(self, t, c, rng):
        x = np.zeros((t.size, c))
        for t0, t1, b in self.segments:       # loop over segments, not samples
            inside = (t >= t0) & (t < t1)
            x[inside] += _per_channel(b, c, "bias")
        return x

    def sample_detail(self, times, n_channels, rng):
        x, mask = self.sample_with_mask(times, n_channels, rng)
        return x, mask, x.copy()

    def describe(self) -> str:
        return "bias segments " + ", ".join(f"[{a:g}, {b:g}) s: {_fmt(v)}" for a, b, v in self.segments)


@dataclass(frozen=True, eq=False)
class VarianceProfile(NoiseProcess):
    """Another process with its standard deviation scaled over time.

    ``x(t) = scale(t) * base(t)`` with ``scale(t) = step(t) * prod drift_i(t)``:

    - ``step(t)`` is the factor of the latest step with ``t_step <= t``
      (1 before the first); a jump persists until the next step (give a step
      with factor 1 to come back);
    - a drift ``(t0, t1, f)`` rises linearly from 1 at t0 to f at the
      midpoint and returns linearly to 1 at t1 (slow drift up and back).

    Parameters
    ----------
    base : NoiseProcess
        The zero-mean process whose sd is scaled (for a biased base the bias
        is scaled too).
    steps : sequence of (t, factor)
        Times [s] and sd factors (>= 0; 0 silences the process).
    drifts : sequence of (t0, t1, factor)
        Windows [s] and peak sd factors (>= 0).
    """

    base: NoiseProcess
    steps: Any = ()
    drifts: Any = ()

    def __post_init__(self):
        if not isinstance(self.base, NoiseProcess):
            raise ArgumentError(f"base must be a noise process, got {self.base!r}", argument="base")
        st = []
        for i, s in enumerate(self.steps):
            if not isinstance(s, (tuple, list)) or len(s) != 2:
                raise ArgumentError(f"expected (t, factor), got {s!r}", argument=f"steps[{i}]")
            st.append((float(_real_array(s[0], f"steps[{i}].at", ndim_max=0)),
                       float(_real_array(s[1], f"steps[{i}].factor", ndim_max=0, nonnegative=True))))
        st.sort(key=lambda p: p[0])
        dr = []
        for i, d in enumerate(self.drifts):
            if not isinstance(d, (tuple, list)) or len(d) != 3:
                raise ArgumentError(f"expected (start, end, factor), got {d!r}", argument=f"drifts[{i}]")
            t0 = float(_real_array(d[0], f"drifts[{i}].start", ndim_max=0))
            t1 = float(_real_array(d[1], f"drifts[{i}].end", ndim_max=0))
            if not t1 > t0:
                raise ArgumentError(f"end ({t1:g} s) must be after start ({t0:g} s)", argument=f"drifts[{i}]")
            dr.append((t0, t1, float(_real_array(d[2], f"drifts[{i}].factor", ndim_max=0, nonnegative=True))))
        object.__setattr__(self, "steps", tuple(st))
        object.__setattr__(self, "drifts", tuple(dr))

    def scale(self, times) -> np.ndarray:
        """The sd factor at ``times`` (n,) [s], shape (n,)."""
        t = np.asarray(times, dtype=float)
        s = np.ones(t.shape)
        if self.steps:
            at = np.array([p[0] for p in self.steps])
            f = np.concatenate([[1.0], [p[1] for p in self.steps]])
            s = f[np.searchsorted(at, t, side="right")]
        for t0, t1, peak in self.drifts:
            mid, half = 0.5 * (t0 + t1), 0.5 * (t1 - t0)
            tri = np.clip(1.0 - np.abs(t - mid) / half, 0.0, 1.0)   # 0 at the ends, 1 mid-window
            s = s * (1.0 + (peak - 1.0) * tri)
        return s

    def sample_with_mask(self, times, n_channels, rng):
        t = _check_call(times, n_channels, rng)
        x, mask = self.base.sample_with_mask(t, n_channels, rng)
        return x * self.scale(t)[:, None], mask

    def sample_detail(self, times, n_channels, rng):
        t = _check_call(times, n_channels, rng)
        x, mask, b = self.base.sample_detail(t, n_channels, rng)
        s = self.scale(t)[:, None]
        return x * s, mask, b * s

    def sd(self, times, n_channels: int):
        base = self.base.sd(times, n_channels)
        return None if base is None else base * self.scale(times)[:, None]

    def describe(self) -> str:
        parts = [f"sd of ({self.base.describe()}) scaled"]
        parts += [f"x{f:g} from {t:g} s" for t, f in self.steps]
        parts += [f"drift to x{f:g} and back over [{a:g}, {b:g}] s" for a, b, f in self.drifts]
        return ", ".join(parts)


@dataclass(frozen=True, eq=False, init=False)
class Sum(NoiseProcess):
    """The sum of independent processes, sampled in order from the same generator.

    Parameters
    ----------
    *processes : NoiseProcess
    """

    processes: tuple = field(default=())

    def __init__(self, *processes: NoiseProcess):
        if len(processes) == 1 and isinstance(processes[0], (list, tuple)):
            processes = tuple(processes[0])
        for i, p in enumerate(processes):
            if not isinstance(p, NoiseProcess):
                raise ArgumentError(f"not an additive noise process: {p!r}", argument=f"parts[{i}]")
        object.__setattr__(self, "processes", tuple(processes))

    def sample_with_mask(self, times, n_channels, rng):
        t = _check_call(times, n_channels, rng)
        x = np.zeros((t.size, n_channels))
        mask = np.zeros((t.size, n_channels), dtype=bool)
        for p in self.processes:
            xi, mi = p.sample_with_mask(t, n_channels, rng)
            x += xi
            mask |= mi
        return x, mask

    def sample_detail(self, times, n_channels, rng):
        t = _check_call(times, n_channels, rng)
        x = np.zeros((t.size, n_channels))
        mask = np.zeros((t.size, n_channels), dtype=bool)
        b = np.zeros((t.size, n_channels))
        for p in self.processes:
            xi, mi, bi = p.sample_detail(t, n_channels, rng)
            x += xi
            mask |= mi
            b += bi
        return x, mask, b

    @property
    def variance(self):
        vs = [p.variance for p in self.processes]
        if any(v is None for v in vs):
            return None
        total = sum(np.asarray(v, dtype=float) for v in vs) if vs else 0.0
        return float(total) if np.ndim(total) == 0 else total

    def sd(self, times, n_channels: int):
        parts = [p.sd(times, n_channels) for p in self.processes]
        if any(p is None for p in parts):
            return None
        t = np.asarray(times, dtype=float)
        return np.sqrt(sum(p ** 2 for p in parts)) if parts else np.zeros((t.size, n_channels))

    def describe(self) -> str:
        return " + ".join(f"({p.describe()})" for p in self.processes) or "zero"


# --------------------------------------------------------------------------
# outages (availability, not additive)
# --------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Outages:
    """Where an observable is unavailable: windows and/or a random fraction of epochs.

    Parameters
    ----------
    windows : sequence of (start, end)
        Outage windows ``start <= t < end`` [s].
    fraction : float, optional
        In [0, 1]: exactly ``round(fraction * n)`` epochs, chosen at random
        without replacement, are also out.
    channels : sequence of int, optional
        Channels affected (e.g. a subset of satellites); default all.
    """

    windows: Any = ()
    fraction: float | None = None
    channels: Any = None

    def __post_init__(self):
        win = []
        for i, w in enumerate(self.windows):
            if not isinstance(w, (tuple, list)) or len(w) != 2:
                raise ArgumentError(f"expected (start, end), got {w!r}", argument=f"windows[{i}]")
            t0 = float(_real_array(w[0], f"windows[{i}].start", ndim_max=0))
            t1 = float(_real_array(w[1], f"windows[{i}].end", ndim_max=0))
            if not t1 > t0:
                raise ArgumentError(f"end ({t1:g} s) must be after start ({t0:g} s)", argument=f"windows[{i}]")
            win.append((t0, t1))
        object.__setattr__(self, "windows", tuple(win))
        if self.fraction is not None:
            f = float(_real_array(self.fraction, "fraction", ndim_max=0, nonnegative=True))
            if f > 1:
                raise ArgumentError(f"must be in [0, 1], got {f:g}", argument="fraction")
            object.__setattr__(self, "fraction", f)
        if self.channels is not None:
            ch = [_int(v, f"channels[{i}]", minimum=0) for i, v in enumerate(np.atleast_1d(self.channels))]
            object.__setattr__(self, "channels", tuple(ch))

    def available(self, times, n_channels: int, rng: np.random.Generator) -> np.ndarray:
        """Availability mask, shape (n, c): True where the observable exists.

        ``rng`` is used only when ``fraction`` is set.
        """
        t = _check_call(times, n_channels, rng)
        out = np.zeros(t.size, dtype=bool)
        for t0, t1 in self.windows:
            out |= (t >= t0) & (t < t1)
        if self.fraction is not None and t.size:
            k = int(round(self.fraction * t.size))
            out[rng.choice(t.size, size=k, replace=False)] = True
        sel = np.ones(n_channels, dtype=bool)
        if self.channels is not None:
            if max(self.channels) >= n_channels:
                raise ValueError(f"outage channel {max(self.channels)} does not exist (n_channels={n_channels})")
            sel[:] = False
            sel[list(self.channels)] = True
        return ~(out[:, None] & sel[None, :])

    def describe(self) -> str:
        parts = [f"[{a:g}, {b:g}) s" for a, b in self.windows]
        if self.fraction is not None:
            parts.append(f"random {100 * self.fraction:g} % of epochs")
        return "outages: " + (", ".join(parts) or "none")
