"""Online re-learning of the measurement-noise mixtures of the Gaussian-mixture EKF
(M4 beyond paper P1: a sliding window of innovations, VB warm starts).

What is collected.  At every measurement epoch the bank kernel
(:func:`mixnav.filters._bank_kernels.bank_epoch_collect`) returns, per row
``k`` of an observable kind being learned, the standardised innovation of the
merged prediction and the state's share of its variance::

    u_k = (z_k - h_k x_m) / sigma_k,      q_k = h_k P_m h_k^T / sigma_k^2

(``sigma_k^2 = r_k`` the model's variance of the row). The last ``window``
rows of each kind are kept. They are not samples of the noise: with the
standardised noise mixture ``sum pi_l N(mu_l, v_l)`` and a consistent state
error ``~ N(0, P_m)``, independent of the noise,

    u_k ~ sum_l pi_l N(mu_l, v_l + q_k),

the noise mixture convolved with the prediction's own uncertainty.

How noise mixtures are obtained from them (moment deconvolution per component).
Every ``every`` measurement epochs, once a kind's window is full:

1. Gate: rows farther than ``gate`` standard deviations
   (``|u - mu_l| > gate sqrt(v_l + q)``) from every component of the current
   mixture are left out of the fit. A single absurd row would otherwise be
   absorbed by the widest component (a component of one row is pruned) and
   inflate its variance by ``u^2 / n_l``.
2. Warm start: the responsibilities of the kept rows under the current mixture
   in innovation space (``N(u; mu_l, v_l + q)``, per row) start the VB
   iteration (P1 eqs. 19-28, the offline learner's prior: alpha0 = beta0 =
   nu0 = 1, W0 = 2, ``prune``; no merge moves). This is one E-step away from
   ``warm_start_from`` and works alike when the current mixture was given,
   learned offline or re-learned. When the current mixture has fewer than
   ``n_components`` components and at least ``max(prune * n, 2)`` rows are
   more than 3 standard deviations from all of them, those rows start one
   extra component (a birth move; VB prunes it again if the data do not
   support it) -- without it a mixture that lost a component, or a Gaussian
   start, could never grow one.
3. The VB fit gives the innovation-space mixture ``(pi_l, mu_l, s_l)``. Its
   responsibilities ``g_tl`` for the window's rows give each component's mean
   prediction share ``qbar_l = sum_t g_tl q_t / sum_t g_tl``, and the noise
   component is ``v_l = s_l - qbar_l``: within component ``l`` the rows'
   second moment about ``mu_l`` is ``v_l + E[q | l]``, which is what VB fits as
   ``s_l`` (method of moments; a single mean of ``q`` over the window would be
   wrong when ``q`` correlates with the component, e.g. rows right after an
   outage). It is exact when ``q`` is the same for the window's rows (a
   Gaussian component convolved with one Gaussian stays Gaussian). When ``q``
   spreads, a component becomes a scale mixture in innovation space, VB's
   Gaussian fit gives its tails to wider components and the narrow scale comes
   out low: measured with ``q`` uniform on 0.1-1.5 and 0.1 N(0, 6) + 0.9
   N(0, 0.44) noise, 0.35 instead of 0.44 and weight 0.86 instead of 0.9;
   with ``q`` on 0.7-0.9 no bias beyond the sampling error (tested). In the
   shipped scenarios ``q`` varies by a few per cent within a window (P1-sim1:
   pseudorange 1.54-1.64, TDCP 0.75; tight drive with 3 m sigma: 0.05-0.07),
   except right after an outage. The overall mean of the mixture is held at
   that of the starting mixture: the window mean of the innovations is the
   slowly varying state error as much as the noise, and a common bias is the
   states' to carry (clock). ``v_l`` is floored at one standard error of
   ``s_l``, ``s_l sqrt(2 / n_eff)`` (``n_eff = n_l E / n``: ``n_l = sum_t
   g_tl`` rows from ``E`` epochs, the rows of one epoch sharing its state
   error): below that the window cannot tell the noise variance from zero, and
   a smaller scale would make the filter overconfident. Floored components are
   counted.
4. The kind's mixture in the bank's tables is replaced; the filter uses it
   from the next epoch.

Why this and not the alternatives: post-update residuals ``z - h x^+`` depend
on the mixture being learned (the update weights each row by it), so fitting
them is circular and biased low. A per-row deconvolution (the "extreme
deconvolution" EM of Bovy, Hogg & Roweis 2011, every row with its own
``v_l + q_t``) removes the bias under a spread ``q`` in the limit, but its EM
converges slowly; tried after the moment step (compiled, 30 iterations), with
``q`` on 0.1-1.5 it moved the narrow scale from 0.31 to 0.40 (truth 0.44) at
9 ms a fit for 3000 rows, and at 600 rows to 0.36 +- 0.03 for 2.6 ms: not
worth four times the refit where ``q`` hardly spreads, so not kept. The
moment deconvolution reuses the P1 VB learner as is and costs one E-step
over the window after the fit.

The feedback is stabilising: if ``v`` is too small the filter trusts the rows
too much, its ``P`` (hence ``q``) is too small, and ``s - q`` comes out larger;
if ``v`` is too large, smaller (tested: a stationary mixture is recovered and
NEES/NIS stay in their bands).

Where it does not help. The window's estimates are only as good as the
innovations are informative about the noise: when the state's share
dominates (P1-sim1: ``q`` about 1.6 for pseudoranges against a noise
variance of 0.4, TDCP 0.75 against 0.4, rows of one epoch sharing the
clock's error) the re-learned scales scatter by tens of per cent from window
to window. And it cannot rescue a filter that has diverged: its innovations
then carry a state error that ``P`` does not describe, and learning from them
widens the mixture the filter uses to explain them away. Measured on P1-sim1
(10 seeds, gross errors from epoch 10, scored after 100 s): horizontal RMS
0.09-0.28 m offline and 0.11-0.33 m online in nine seeds; in the tenth the
offline VB-GMEKF already diverges (5.3 m) and online learning makes it
23.9 m. On a drive where the noise, not the state, dominates the innovations
(tests/test_online.py: pseudorange sigma 3 m, ``q`` about 0.06) the mixture
is recovered and tracked.

Rows of rejected epochs (absurd innovation, innovation covariance not PD,
non-finite) are not collected: the filter did not use them and an absurd
epoch is what the gate of step 1 guards against. The process-noise mixture
is not re-learned (its samples are not observed).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...errors import ArgumentError
from ..mixture import StandardMixture

_LOG2PI = math.log(2.0 * math.pi)
#: Rows this many standard deviations from every current component start a birth.
BIRTH_SIGMA = 3.0


@dataclass(frozen=True)
class OnlineSettings:
    """What to re-learn online and how (``mixture.learn.online`` of a scenario;
    see :class:`OnlineMixtureLearner` for the meaning of each field)."""

    kinds: tuple
    window: int = 600
    every: int = 20
    gate: float = 10.0
    n_components: int = 4
    prune: float = 0.01

    def __post_init__(self):
        if int(self.window) < 10 * int(self.n_components):
            raise ArgumentError(f"needs at least 10 rows per component ({10 * int(self.n_components)}), "
                              f"got {self.window}", argument="window")
        if int(self.every) < 1:
            raise ArgumentError(f"must be at least 1, got {self.every}", argument="every")
        if not float(self.gate) >= 3.0:
            raise ArgumentError(f"must be at least 3 (standard deviations), got {self.gate}",
                                argument="gate")

    def learner(self, mixtures, codes: dict) -> "OnlineMixtureLearner":
        """A fresh learner starting from the measurement mixtures of ``mixtures``
        (:class:`mixnav.noise.mixture.BankMixtures`; a kind it lacks starts Gaussian);
        ``codes`` maps each kind name to the code the filter's rows carry."""
        start = {k: mixtures.measurement.get(k, StandardMixture.gaussian()) for k in self.kinds}
        return OnlineMixtureLearner(self.kinds, start, self.window, self.every, self.gate, self.n_components,
                                    self.prune, codes=codes)


_WARM = []


def warm_online() -> None:  # the module-level name of OnlineMixtureLearner.warm_up
    """Compile (or load from the numba cache) the VB kernel once per process,
    outside the timed loop."""
    if _WARM:
        return
    z = np.zeros(3)
    zi = np.zeros(1, dtype=np.int64)
    push_rows(zi, z, z, zi, np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2), dtype=np.int64), zi.copy(),
              zi.copy(), zi.copy(), 1)
    component_shares(z, z, np.ones(1), np.zeros(1), np.ones(1))
    start_responsibilities(z, z, np.ones(1), np.zeros(1), np.ones(1), 10.0, True, 0.01)
    from . import VariationalGaussianMixture
    x = np.random.default_rng(0).standard_normal((40, 1))
    resp = np.zeros((40, 2))
    resp[:20, 0] = resp[20:, 1] = 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        VariationalGaussianMixture(2, nu0=1.0, W0=np.array([[2.0]]), merge=False, init_resp=resp).fit(x)
    _WARM.append(True)


@njit(cache=True)
def start_responsibilities(u, q, w, mu, v, gate, allow_birth, prune):
    """Steps 1-2 of the module docstring in one pass over the window.

    Parameters
    ----------
    u, q : ndarray (n,)
        Standardised innovations and prediction shares [-].
    w, mu, v : ndarray (L,)
        The mixture in use (weights > 0, means, scales).
    gate : float
        Rows with ``|u - mu_l| > gate sqrt(v_l + q)`` for every ``l`` are left out.
    allow_birth : bool
        Add a birth column when at least ``max(prune n, 2)`` kept rows are more
        than :data:`BIRTH_SIGMA` standard deviations from every component.

    Returns
    -------
    keep : ndarray of bool (n,)
    resp : ndarray (n_kept, L) or (n_kept, L + 1)
        Responsibilities ``∝ w_l N(u; mu_l, v_l + q)`` (the birth column: 1 for
        the far rows, whose other columns are 0).
    """
    n = u.shape[0]
    L = w.shape[0]
    lr = np.empty((n, L))
    keep = np.zeros(n, dtype=np.bool_)
    far = np.zeros(n, dtype=np.bool_)
    g2, b2 = gate * gate, BIRTH_SIGMA * BIRTH_SIGMA
    n_keep = 0
    n_far = 0
    for t in range(n):
        dmin = np.inf
        for l in range(L):
            s = v[l] + q[t]
            e = u[t] - mu[l]
            d2 = e * e / s
            if d2 < dmin:
                dmin = d2
            lr[t, l] = math.log(w[l]) - 0.5 * (_LOG2PI + math.log(s) + d2)
        if dmin <= g2:
            keep[t] = True
            n_keep += 1
            if dmin > b2:
                far[t] = True
                n_far += 1
    birth = allow_birth and n_far >= max(prune * n_keep, 2.0)
    resp = np.zeros((n_keep, L + 1 if birth else L))
    o = 0
    for t in range(n):
        if not keep[t]:
            continue
        if birth and far[t]:
            resp[o, L] = 1.0
        else:
            m = -np.inf
            for l in range(L):
                if lr[t, l] > m:
                    m = lr[t, l]
            tot = 0.0
            for l in range(L):
                r = math.exp(lr[t, l] - m)
                resp[o, l] = r
                tot += r
            for l in range(L):
                resp[o, l] /= tot
        o += 1
    return keep, resp


@njit(cache=True)
def component_shares(x, q, w, mu, s):
    """Step 3: per component of the fitted innovation-space mixture ``(w, mu, s)``
    (K,), the responsibility mass ``n_l = sum_t g_tl`` and the mean prediction
    share ``qbar_l = sum_t g_tl q_t / n_l`` of the rows ``x``, ``q`` (n,)."""
    n = x.shape[0]
    K = w.shape[0]
    c = np.empty(K)
    for l in range(K):
        c[l] = math.log(w[l]) - 0.5 * (_LOG2PI + math.log(s[l]))
    nl = np.zeros(K)
    qs = np.zeros(K)
    lg = np.empty(K)
    for t in range(n):
        m = -np.inf
        for l in range(K):
            e = x[t] - mu[l]
            lg[l] = c[l] - 0.5 * e * e / s[l]
            if lg[l] > m:
                m = lg[l]
        tot = 0.0
        for l in range(K):
            lg[l] = math.exp(lg[l] - m)
            tot += lg[l]
        for l in range(K):
            g = lg[l] / tot
            nl[l] += g
            qs[l] += g * q[t]
    qbar = np.empty(K)
    for l in range(K):
        qbar[l] = qs[l] / max(nl[l], 1e-300)
    return nl, qbar


@njit(cache=True)
def push_rows(kinds, u, q, codes, U, Q, EP, pos, filled, new, epoch):
    """Append the rows of the learned kinds (``codes``) to their ring buffers
    ``U``, ``Q``, ``EP`` (n_learned, window), in place; one pass, no allocation."""
    W = U.shape[1]
    for t in range(kinds.shape[0]):
        for j in range(codes.shape[0]):
            if kinds[t] == codes[j]:
                p = pos[j]
                U[j, p] = u[t]
                Q[j, p] = q[t]
                EP[j, p] = epoch
                pos[j] = (p + 1) % W
                if filled[j] < W:
                    filled[j] += 1
                new[j] += 1
                break


class OnlineMixtureLearner:
    """Sliding windows of standardised innovations and the VB refits (module docstring).

    Parameters
    ----------
    kinds : sequence of str
        Observable kinds re-learned (keys of :data:`mixnav.measurements.kinds.KINDS`).
    start : dict
        kind -> :class:`mixnav.filters.gmekf.StandardMixture`, the mixtures the
        filter starts with (given, learned offline, or Gaussian).
    window : int
        Rows per kind in the window.
    every : int
        Measurement epochs between refits.
    gate : float
        Rows farther than ``gate`` standard deviations from every component are
        not fitted [-].
    n_components, prune : int, float
        VB's largest number of components and pruning threshold (as offline).
    max_iter : int
        VB iterations per refit at most.

    Attributes
    ----------
    current : dict
        kind -> the mixture in use.
    refits, refit_time_s, floored, failed, rows_gated : counters
    history : list of (int, str, StandardMixture)
        Measurement-epoch index (1-based), kind and mixture of every refit.
    """

    def __init__(self, kinds, start: dict, window: int, every: int, gate: float, n_components: int = 4,
                 prune: float = 0.01, max_iter: int = 200, codes: dict | None = None):
        self.kinds = list(kinds)
        if codes is None or any(k not in codes for k in self.kinds):
            raise ArgumentError(f"a kind code is needed for each of {self.kinds}", argument="codes")
        self.codes = np.array([codes[k] for k in self.kinds], dtype=np.int64)
        self.current = {k: start[k] for k in self.kinds}
        self._mean0 = {k: float(np.dot(start[k].weights, start[k].means)) for k in self.kinds}
        self.window, self.every, self.gate = int(window), int(every), float(gate)
        self.n_components, self.prune, self.max_iter = int(n_components), float(prune), int(max_iter)
        W, nk = self.window, len(self.kinds)
        self._U = np.zeros((nk, W))                       # ring buffers, one row per kind
        self._Q = np.zeros((nk, W))
        self._EP = np.zeros((nk, W), dtype=np.int64)      # measurement epoch of each row
        self._pos = np.zeros(nk, dtype=np.int64)
        self._filled = np.zeros(nk, dtype=np.int64)
        self._new = np.zeros(nk, dtype=np.int64)
        self.epochs = 0
        self.refits = 0
        self.refit_time_s = 0.0
        self.floored = 0
        self.failed = 0
        self.rows_gated = 0
        self.history: list = []

    # --- per epoch ---------------------------------------------------------------------
    def observe(self, accepted: bool, kinds: np.ndarray, u: np.ndarray, q: np.ndarray) -> bool:
        """Take one measurement epoch's rows; refit when due.

        Parameters
        ----------
        accepted : bool
            False for a rejected epoch: its rows are not collected.
        kinds : ndarray of int (m,)
            Kind code of each row.
        u, q : ndarray (m,)
            Standardised innovations and prediction shares of the rows [-].

        Returns
        -------
        changed : bool
            True when a mixture was replaced (the caller rebuilds its tables).
        """
        self.epochs += 1
        if accepted:
            push_rows(kinds, u, q, self.codes, self._U, self._Q, self._EP, self._pos, self._filled, self._new,
                      self.epochs)
        if self.epochs % self.every:
            return False
        changed = False
        for j, k in enumerate(self.kinds):
            if self._filled[j] == self.window and self._new[j] > 0:
                changed |= self._refit(j, k)
        return changed

    def filled(self, kind: str) -> int:
        """Rows of ``kind`` in its window."""
        return int(self._filled[self.kinds.index(kind)])

    def window_rows(self, kind: str):
        """``(u, q)`` of the rows of ``kind`` in its window (ring order), each (filled,)."""
        j = self.kinds.index(kind)
        f = self._filled[j]
        return self._U[j, :f].copy(), self._Q[j, :f].copy()

    # --- refit -------------------------------------------------------------------------
    def _refit(self, j, k) -> bool:
        t0 = time.perf_counter()
        try:
            n_epochs = len(np.unique(self._EP[j]))
            new = self.fit_window(self._U[j], self._Q[j], self.current[k], n_epochs, self._mean0[k])
        finally:
            self.refit_time_s += time.perf_counter() - t0
        self._new[j] = 0
        self.refits += 1
        if new is None:
            self.failed += 1
            return False
        self.current[k] = new
        self.history.append((self.epochs, k, new))
        return True

    def fit_window(self, u: np.ndarray, q: np.ndarray, cur, n_epochs: int | None = None, mean: float = 0.0):
        """The noise mixture from a window's innovations ``u`` and shares ``q``
        (n,), starting from the mixture ``cur`` (steps 1-3 of the module
        docstring), its overall mean held at ``mean``; ``n_epochs``: how many
        epochs the rows come from (default: one per row), for the floor. None
        when the fit fails (the caller keeps ``cur``)."""
        from . import VariationalGaussianMixture
        w, mu, v = (np.asarray(a, dtype=float) for a in (cur.weights, cur.means, cur.scales))
        live = w > 0
        w, mu, v = w[live], mu[live], v[live]
        allow_birth = len(w) < self.n_components
        keep, resp = start_responsibilities(u, q, w, mu, v, self.gate, allow_birth, self.prune)   # steps 1-2
        x, qk = u[keep], q[keep]
        n = len(x)
        self.rows_gated += len(u) - n
        if n < 10 * max(len(w), 1):
            return None
        est = VariationalGaussianMixture(n_components=resp.shape[1], alpha0=1.0, beta0=1.0, nu0=1.0,
                                         W0=np.array([[2.0]]), tol=1e-6, max_iter=self.max_iter,
                                         prune_threshold=self.prune, merge=False, init_resp=resp)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")           # an unconverged warm fit is still usable
                est.fit(x[:, None])
        except (np.linalg.LinAlgError, ValueError):
            return None
        pw, pm, ps = est.weights_, est.means_[:, 0], est.covariances_[:, 0, 0]
        if not (np.all(np.isfinite(pw)) and np.all(np.isfinite(pm)) and np.all(ps > 0)):
            return None
        nl, qbar = component_shares(x, qk, pw, pm, ps)     # step 3
        n_eff = nl * (min(n_epochs, n) / n if n_epochs else 1.0)   # rows of one epoch share its state error
        floor = ps * np.sqrt(2.0 / np.maximum(n_eff, 1.0))
        vs = ps - qbar
        low = vs < floor
        self.floored += int(low.sum())
        vs = np.where(low, floor, vs)
        pw = pw / pw.sum()
        pm = pm + (mean - pw @ pm)                        # the overall mean is the states' business
        return StandardMixture(tuple(pw), tuple(pm), tuple(vs))

    def timing(self) -> dict:
        """The counters reported in the run's timing / metrics."""
        return {"online_refits": float(self.refits), "online_refit_time_s": self.refit_time_s,
                "online_floored": float(self.floored), "online_failed": float(self.failed),
                "online_rows_gated": float(self.rows_gated)}


OnlineMixtureLearner.warm_up = staticmethod(warm_online)
