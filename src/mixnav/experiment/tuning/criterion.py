"""The reference-free criteria a candidate setting is judged by.

Both come from the recording's own GNSS; neither reads ``[reference]`` (the section is
taken out of the file before anything is loaded, :func:`without_reference`).

* **Cross-validation on withheld GNSS** (the criterion the search minimises): the span is
  cut into windows of ``window`` seconds, dealt round-robin to ``folds`` runs; each run
  withholds its windows (and the dataset's own ``withhold`` windows, never scored: they are
  the user's evaluation) and the withheld fixes are the truth. Per withheld fix, the
  negative log predictive density of the fix under the filter's position (its covariance
  plus the fix's own sigmas): ``0.5 (e^T S^-1 e + log det S + 3 log 2 pi)``, averaged. This
  is what an outage needs: the position and how far to trust it after seconds without
  GNSS. For RTK-grade fixes it predicts the outage error directly; a filter that is
  confident and wrong pays quadratically, one that is vague pays log det S.
* **The GNSS innovation log-likelihood** of the same runs (the fixes not withheld): each
  update's ``-(nis + log det S + m log 2 pi) / 2``, from the engine's record
  (:func:`mixnav.filters.ekf.innovation_likelihood`). It scores 0.25-1 s predictions and
  sees the white noise and the GNSS sigmas well but the bias walks and the constraints'
  sigmas hardly: those show after tens of seconds without GNSS. The tool reports it beside
  the cross-validation and trusts the cross-validation where they disagree (the report
  lists where the two optima differ).
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass

import numpy as np
import tomlkit

#: sections a tuning run never reads
REFERENCE_SECTIONS = ("reference", "reference_point")
_LOG2PI = math.log(2.0 * math.pi)


def without_reference(text: str) -> str:
    """The dataset file's text with ``[reference]`` and ``[reference_point]`` removed."""
    doc = tomlkit.parse(text)
    for k in REFERENCE_SECTIONS:
        if k in doc:
            del doc[k]
    return tomlkit.dumps(doc)


def cv_windows(first: float, last: float, window: float, folds: int, avoid=(), step: float | None = None
               ) -> list[list[tuple]]:
    """Windows of ``window`` s from ``first`` to ``last`` [s], one starting every ``step`` s
    (default: back to back), dealt round-robin to ``folds`` lists; a window overlapping one of
    ``avoid`` (the dataset's own windows, widened by ``window`` after their end: the filter is
    reconverging there) is left out. Windows of one fold start ``folds x step`` apart."""
    step = window if step is None else step
    out: list[list[tuple]] = [[] for _ in range(folds)]
    k, a = 0, first
    while a + window <= last + 1e-9:
        b = a + window
        if not any(a < e + window and b > s for s, e in avoid):
            out[k % folds].append((a, b))
            k += 1
        a += step
    return out


@dataclass
class Score:
    """One candidate's criteria (``nlpd`` is minimised)."""

    nlpd: float                 # mean negative log predictive density of the withheld fixes
    innovation_ll: float        # GNSS innovation log-likelihood per update (mean over updates)
    window_hmax: list           # horizontal maximum error [m] per withheld window, against the withheld fixes
    window_nees: list           # mean 3-D position NEES per window (filter covariance only)
    n_fixes: int
    n_updates: int
    error: str | None = None
    window_nlpd: list = None    # per window: the sum of its withheld fixes' NLPD
    window_fixes: list = None   # per window: how many withheld fixes it scored
    n_distinct_updates: int = 0  # the updates of all folds' runs, each time counted once

    def as_dict(self) -> dict:
        h = np.asarray(self.window_hmax, float)
        return {"criterion": self.nlpd, "nlpd": self.nlpd, "innovation_ll_per_update": self.innovation_ll,
                "n_withheld_fixes": self.n_fixes,
                "n_updates": self.n_updates, "n_distinct_updates": self.n_distinct_updates,
                "cv_median_hmax_m": float(np.median(h)) if len(h) else None,
                "cv_p90_hmax_m": float(np.percentile(h, 90)) if len(h) else None,
                "cv_worst_hmax_m": float(h.max()) if len(h) else None,
                "cv_window_hmax_m": [float(x) for x in h], "cv_window_nees": [float(x) for x in self.window_nees],
                "cv_window_nlpd_sum": [float(x) for x in (self.window_nlpd or [])],
                "cv_window_fixes": [int(x) for x in (self.window_fixes or [])],
                "criterion_se": criterion_se(self.window_nlpd or [], self.window_fixes or []),
                "error": self.error}


FAILED = Score(math.inf, -math.inf, [], [], 0, 0)


def criterion_se(window_sums, window_counts) -> float | None:
    """The standard error of the mean NLPD per withheld fix with the windows as the independent
    units (the fixes inside a window are strongly correlated): the cluster-robust (sandwich)
    standard error of a ratio of sums, ``sqrt(m / (m - 1) * sum_w (S_w - c n_w)^2) / N`` with
    ``S_w`` and ``n_w`` window w's NLPD sum and fix count, ``N = sum n_w``, ``c`` the mean and
    ``m`` the number of windows. Unlike ``2 / m`` (a likelihood-ratio interval, which holds
    when the filter's model is the data's) it is measured from the windows' own spread, so it
    stays honest when the model is wrong. None with fewer than two windows."""
    s, n = np.asarray(window_sums, float), np.asarray(window_counts, float)
    m = len(s)
    if m < 2 or len(n) != m or n.sum() <= 0 or not np.isfinite(s).all():
        return None
    c = s.sum() / n.sum()
    return float(math.sqrt(m / (m - 1) * np.sum((s - c * n) ** 2)) / n.sum())


class Evaluator:
    """Runs candidate settings of one dataset file and scores them (:class:`Score`).

    Parameters
    ----------
    text : str
        The dataset file's text, reference sections already removed.
    source : str
        The file it stands for (relative paths resolve from it; errors name it).
    data : str or None
        Another copy of the data folder (``--data``).
    method : str
        The ``[[methods]]`` entry tuned (run without smoothing).
    windows : list of list of (start, end)
        The folds' withheld windows [s] (:func:`cv_windows`).
    span : (float, float)
        Innovation log-likelihood counted inside it only [s].
    """

    def __init__(self, text: str, source: str, data: str | None, method: str, windows, span):
        from ...config.loader import load_dataset_text
        from ..data_folder import find_data_dir
        from ..pipelines import pipeline
        self.text, self.source, self.method, self.windows, self.span = text, source, method, windows, span
        ds, _, _ = load_dataset_text(text, source)
        self.pipeline = pipeline(ds, source)
        self.folder = find_data_dir(ds, data, source)
        self._inputs_key, self._inputs = None, None

    def dataset(self, doc_text: str, smooth: bool = False):
        """The candidate's dataset: only the tuned method, smoothed only when asked."""
        from ...config.loader import load_dataset_text
        ds, _, _ = load_dataset_text(doc_text, self.source)
        methods = [m.model_copy(update={"smooth": smooth}) if hasattr(m, "smooth") else m
                   for m in ds.methods if m.name == self.method]
        return ds.model_copy(update={"methods": methods})

    def _load(self, ds):
        # the read depends on the IMU, installation and GNSS sections only (time offset, sigma floor)
        key = json.dumps([ds.imu.model_dump(mode="json"), ds.installation.model_dump(mode="json"),
                          ds.gnss.model_copy(update={"withhold": []}).model_dump(mode="json")], sort_keys=True)
        if key != self._inputs_key:
            self._inputs_key, self._inputs = key, None
            self._inputs = _cropped(self.pipeline.load(ds, self.source, self.folder), self.span[1] + 1.0)
        return self._inputs

    def run(self, ds, windows):
        """The pipeline's run with ``windows`` and the dataset's own windows withheld."""
        from ...filters.ekf import innovation_likelihood
        from ...io.imu_checks import DataWarning
        from ..ins_common import with_withheld
        # the file's own windows after the runs' end (the span's, :func:`_cropped`) withhold nothing there
        own = [tuple(w) for w in ds.gnss.withhold if w[0] < self.span[1]]
        with innovation_likelihood(), warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            warnings.simplefilter("ignore", RuntimeWarning)
            return self.pipeline.run(with_withheld(ds, own + list(windows)), self.source, self.folder,
                                     self._load(ds))

    def evaluate(self, doc_text: str) -> Score:
        """Every fold's run of the candidate file ``doc_text``, scored."""
        return self.evaluate_per_fold([doc_text] * len(self.windows))

    def evaluate_per_fold(self, doc_texts: list) -> Score:
        """Fold k run with the candidate file ``doc_texts[k]`` (one per fold; a quantity fitted
        without fold k's fixes is scored on them: :func:`.installation.cross_fitted_score`)."""
        if len(doc_texts) != len(self.windows):
            raise ValueError(f"{len(doc_texts)} files for {len(self.windows)} folds")
        return combined([self.fold_part(t, k) for k, t in enumerate(doc_texts)])

    def fold_part(self, doc_text: str, k: int):
        """Fold ``k``'s run of the candidate file ``doc_text``, scored: a :class:`FoldPart`, or
        the error's text when the file cannot run (:func:`combined` makes the Score)."""
        from ...errors import MixnavError
        fold = self.windows[k]
        try:
            ds = self.dataset(doc_text)
            po = self.run(ds, fold)
            res = po.results[self.method]
            ws, wn, h, ne = _withheld_scores(po, res, fold)
            held = [tuple(w) for w in ds.gnss.withhold] + list(fold)
            ll, m, t_upd = _innovation_ll(res, self.span, held)
        except (MixnavError, np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
            return f"{type(exc).__name__}: {exc}"
        return FoldPart(ws, wn, h, ne, ll, m, t_upd)


@dataclass
class FoldPart:
    """One fold's run, scored (:meth:`Evaluator.fold_part`): per withheld window its NLPD sum,
    fix count, horizontal maximum and mean NEES; the innovation log-likelihood sum, the number
    of updates and their times."""

    window_nlpd: list
    window_fixes: list
    window_hmax: list
    window_nees: list
    ll: float
    n_updates: int
    update_times: np.ndarray


def combined(parts: list) -> Score:
    """The candidate's :class:`Score` from its folds' parts (an error text: a failed Score)."""
    for p in parts:
        if isinstance(p, str):
            return Score(math.inf, -math.inf, [], [], 0, 0, error=p)
    w_sum = [x for p in parts for x in p.window_nlpd]
    w_n = [x for p in parts for x in p.window_fixes]
    n_fix = sum(w_n)
    if n_fix == 0:
        return Score(math.inf, -math.inf, [], [], 0, 0, error="no withheld fix was scored")
    n_upd = sum(p.n_updates for p in parts)
    # an update outside a fold's windows is in most folds' runs: how many distinct ones the
    # likelihood sum stands for (search.gain_needed's likelihood-ratio bound counts these)
    times = [p.update_times for p in parts]
    distinct = len(np.unique(np.round(np.concatenate(times), 6))) if times else 0
    nlpd_sum = sum(sum(p.window_nlpd) for p in parts)   # fold by fold: the same rounding as the journal's
    return Score(nlpd_sum / n_fix, sum(p.ll for p in parts) / max(n_upd, 1),
                 [x for p in parts for x in p.window_hmax], [x for p in parts for x in p.window_nees], n_fix, n_upd,
                 window_nlpd=w_sum, window_fixes=w_n, n_distinct_updates=distinct)


def nearest(times: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Index into the increasing, non-empty ``times`` of the one nearest each of ``t``."""
    if len(times) == 1:
        return np.zeros(len(t), int)
    j = np.clip(np.searchsorted(times, t), 1, len(times) - 1)
    return j - ((t - times[j - 1]) < (times[j] - t))


def _cropped(inputs, end: float):
    """The read IMU and fixes up to ``end`` [s since the first IMU sample]: a causal filter's
    criterion inside the span does not depend on what comes after it, so the runs stop
    there (a tuning on the first half of a drive costs half)."""
    from dataclasses import fields, is_dataclass, replace
    if not math.isfinite(end) or not is_dataclass(inputs) or not {"imu", "fixes"} <= {f.name for f in fields(inputs)}:
        return inputs
    imu, fx = inputs.imu, inputs.fixes
    t_end = imu.start_time + end
    k = imu.time <= t_end
    j = fx.time <= t_end
    cut = lambda a, m: None if a is None else a[m]   # noqa: E731
    return replace(inputs, imu=replace(imu, time=imu.time[k], dt=imu.dt[k], dtheta=imu.dtheta[k], dvel=imu.dvel[k]),
                   fixes=replace(fx, time=fx.time[j], lla=fx.lla[j], pos_sigma=fx.pos_sigma[j],
                                 vel_n=cut(fx.vel_n, j), vel_sigma=cut(fx.vel_sigma, j)))


def _withheld_scores(po, res, windows) -> tuple[list, list, list, list]:
    """Per window: the sum of its withheld fixes' negative log predictive densities, their
    number, the horizontal maximum error and the mean position NEES (against the fixes)."""
    from ...data import Trajectory
    from ..outputs import solution_table
    fx = po.all_fixes
    truth = Trajectory(time=fx.time, lla=fx.lla, v_n=None, q_nb=None)
    inside = np.zeros(len(res.time), bool)
    for a, b in windows:
        inside |= (res.time > a) & (res.time <= b)
    if not inside.any():
        return [], [], [], []
    tab = solution_table(res, truth, (), lever=po.lever)
    e = tab[["err_n_m", "err_e_m", "err_d_m"]].to_numpy()
    # the fix sigma nearest each record (the fixes are the truth, with their own noise)
    j = nearest(fx.time, res.time)
    sig = np.broadcast_to(np.asarray(fx.pos_sigma, float).reshape(len(fx.time), -1), (len(fx.time), 3))[j]
    w_sum, w_n, hmax, nees = [], [], [], []
    for a, b in windows:
        sel = np.flatnonzero((res.time > a) & (res.time <= b))
        if len(sel) == 0:
            continue
        S = res.pv_cov[sel, 3:, 3:] + np.einsum("ki,ij->kij", sig[sel] ** 2, np.eye(3))
        L = np.linalg.cholesky(S)
        w = np.linalg.solve(L, e[sel][..., None])[..., 0]
        logdet = 2.0 * np.log(np.diagonal(L, axis1=1, axis2=2)).sum(axis=1)
        w_sum.append(float(np.sum(0.5 * (np.sum(w * w, axis=1) + logdet + 3 * _LOG2PI))))
        w_n.append(len(sel))
        hmax.append(float(np.max(np.hypot(e[sel, 0], e[sel, 1]))))
        nees.append(float(np.nanmean(tab["nees_pos"].to_numpy()[sel])))
    return w_sum, w_n, hmax, nees


def _innovation_ll(res, span, withheld) -> tuple[float, int, np.ndarray]:
    """Sum of the GNSS position updates' innovation log-likelihoods inside ``span`` and outside
    the ``withheld`` windows (the first fix after a window included), their number and times."""
    if res.nis_time is None or res.nis_kind is None:
        return 0.0, 0, np.zeros(0)
    t = res.nis_time
    sel = np.array(["position" in k for k in res.nis_kind], bool) & (t >= span[0]) & (t <= span[1])
    for a, b in withheld:
        sel &= ~((t > a) & (t <= b))
    sel &= np.isfinite(res.nis_logdet)
    ll = -0.5 * (res.nis[sel] + res.nis_logdet[sel] + res.nis_dim[sel] * _LOG2PI)
    return float(ll.sum()), int(sel.sum()), np.asarray(t[sel], float)
