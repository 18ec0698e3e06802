"""Online re-learning of the noise mixtures (M4 beyond P1, mixnav.noise.learn.online):
the moment deconvolution against samples of a known convolved mixture, the
gate, the window bookkeeping, the collecting kernel against numpy and against
bank_epoch (bitwise), a stationary and a changing noise on a tight drive
(seeded, paired against the offline-learned mixture), and config errors."""

from __future__ import annotations

import numpy as np
import pytest

from mixnav.config.loader import load_scenario, resolve
from mixnav.errors import ConfigError
from mixnav.experiment import run as runmod
from mixnav.experiment.run import solution_table
from mixnav.experiment import methods as registry
from mixnav.filters._bank_kernels import bank_epoch, bank_epoch_collect, bank_moments
from mixnav.filters.gmekf import BankMixtures, GaussianMixtureEkf, StandardMixture
from mixnav.noise.learn.online import OnlineMixtureLearner, OnlineSettings
from mixnav.ins.error_model import ClockModel
from mixnav.measurements.kinds import KINDS
from mixnav.sim.scenario import simulate

PR = KINDS["pseudorange"]
#: the stationary noise of the drive tests, standardised by the 3 m the filters are told:
#: 0.1 N(0, 6) + 0.9 N(0, 4/9), total variance 1 (so R is the right second moment)
TRUE = StandardMixture((0.1, 0.9), (0.0, 0.0), (6.0, 4.0 / 9.0))


def _parts(mix: StandardMixture, split: float = 1.63):
    """(weight, mean scale) of the narrow (scale < split) and wide parts of a mixture:
    VB may describe one true component by two, so compare parts, not components."""
    w, v = np.asarray(mix.weights), np.asarray(mix.scales)
    out = []
    for sel in (v < split, v >= split):
        W = w[sel].sum()
        out.append((W, (w[sel] @ v[sel]) / W if W > 0 else np.nan))
    return out


def _sample(rng, mix, n):
    k = rng.choice(len(mix.weights), size=n, p=mix.weights)
    return np.asarray(mix.means)[k] + np.sqrt(np.asarray(mix.scales)[k]) * rng.standard_normal(n)


# --- the learner alone -----------------------------------------------------------------
def test_moment_deconvolution_recovers_the_noise_mixture():
    """Innovations = noise + N(0, q_t) with q_t over 0.7-0.9 (the state's share,
    larger than the narrow noise scale 0.44, as for P1's TDCP rows). Over 20
    windows of 3000 rows the deconvolved weights and scales agree with the noise
    mixture within 4 standard errors of their mean (SE from the spread over
    windows; 1e-3 added for VB's own tolerance), and the fit without
    deconvolution is biased by about the mean q (0.8) in the narrow scale: the
    subtraction is needed and right. (With q spread over 0.1-1.5 the narrow scale
    comes out 0.35 instead of 0.44: see the module docstring.)"""
    rng = np.random.default_rng(0)
    lrn = OnlineMixtureLearner(["pseudorange"], {"pseudorange": StandardMixture.gaussian()}, 3000, 1, 10.0, codes=KINDS)
    est, raw = [], []
    m = StandardMixture.gaussian()
    for i in range(25):                  # successive windows, each fit warm-started from the last
        q = rng.uniform(0.7, 0.9, 3000)
        u = _sample(rng, TRUE, 3000) + np.sqrt(q) * rng.standard_normal(3000)
        m = lrn.fit_window(u, q, m)
        if i < 5:                        # the birth moves grow the wide part from the Gaussian start
            continue
        est.append([p for part in _parts(m) for p in part])
        m0 = lrn.fit_window(u, np.zeros_like(q), m)
        raw.append([p for part in _parts(m0) for p in part])
    est, raw = np.array(est), np.array(raw)
    truth = np.array([0.9, 4.0 / 9.0, 0.1, 6.0])
    se = est.std(axis=0, ddof=1) / np.sqrt(len(est))
    assert np.all(np.abs(est.mean(axis=0) - truth) < 4 * se + 1e-3), (est.mean(axis=0), se)
    assert raw[:, 1].mean() - truth[1] > 0.5   # the narrow scale without deconvolution: + mean q


def test_compiled_steps_equal_their_numpy_formulas():
    """Gate, start responsibilities (with the birth column) and the per-component
    prediction shares against the formulas of the module docstring in numpy."""
    from scipy.stats import norm
    from mixnav.noise.learn.online import BIRTH_SIGMA, component_shares, start_responsibilities
    rng = np.random.default_rng(5)
    u = np.concatenate([rng.standard_normal(300), [40.0, -60.0], rng.normal(0, 5, 20)])
    q = rng.uniform(0.05, 0.5, len(u))
    w, mu, v = np.array([0.3, 0.7]), np.array([0.2, -0.1]), np.array([2.0, 0.5])
    keep, resp = start_responsibilities(u, q, w, mu, v, 10.0, True, 0.01)
    S = v + q[:, None]
    d = np.abs(u[:, None] - mu) / np.sqrt(S)
    np.testing.assert_array_equal(keep, d.min(axis=1) <= 10.0)
    far = d[keep].min(axis=1) > BIRTH_SIGMA
    assert far.sum() >= 2 and resp.shape == (keep.sum(), 3)
    dens = w * norm.pdf(u[keep][:, None], mu, np.sqrt(S[keep]))
    np.testing.assert_allclose(resp[~far, :2], (dens / dens.sum(axis=1, keepdims=True))[~far], rtol=1e-12)
    np.testing.assert_array_equal(resp[far], np.tile([0.0, 0.0, 1.0], (far.sum(), 1)))
    _, r2 = start_responsibilities(u, q, w, mu, v, 10.0, False, 0.01)
    assert r2.shape == (keep.sum(), 2)
    x = u[keep]
    nl, qbar = component_shares(x, q[keep], w, mu, v)
    g = w * norm.pdf(x[:, None], mu, np.sqrt(v))
    g /= g.sum(axis=1, keepdims=True)
    np.testing.assert_allclose(nl, g.sum(axis=0), rtol=1e-12)
    np.testing.assert_allclose(qbar, (g * q[keep][:, None]).sum(axis=0) / g.sum(axis=0), rtol=1e-12)


def test_gate_keeps_an_absurd_row_out_of_the_fit():
    rng = np.random.default_rng(1)
    u = _sample(rng, TRUE, 600)
    q = np.full(600, 0.05)
    a = OnlineMixtureLearner(["pseudorange"], {"pseudorange": TRUE}, 600, 1, 10.0, codes=KINDS)
    clean = a.fit_window(u[1:], q[1:], TRUE)
    u[0] = 1e4                           # a gross error: 1e4 sigma
    gated = a.fit_window(u, q, TRUE)
    assert a.rows_gated == 1
    np.testing.assert_allclose(gated.scales, clean.scales, rtol=1e-9)
    b = OnlineMixtureLearner(["pseudorange"], {"pseudorange": TRUE}, 600, 1, 1e9, codes=KINDS)   # no gate
    poisoned = b.fit_window(u, q, TRUE)
    assert max(poisoned.scales) > 1e3 * max(clean.scales)


def test_window_bookkeeping_and_refit_schedule():
    """Refits only every `every` epochs once the window is full and has new rows;
    rows of rejected epochs and of other kinds are not collected; the ring
    buffer holds the last `window` rows."""
    lrn = OnlineMixtureLearner(["pseudorange"], {"pseudorange": StandardMixture.gaussian()}, 100, 5, 10.0, codes=KINDS)
    rng = np.random.default_rng(2)
    kinds = np.array([PR] * 8 + [KINDS["range_rate"]] * 8)
    for e in range(1, 31):
        u = rng.standard_normal(16)
        u[8:] = 1e6                       # range-rate rows: never in the pseudorange window
        lrn.observe(e != 7, kinds, u, np.zeros(16))
        full = min(8 * (e - (e >= 7)), 100)
        assert lrn.filled("pseudorange") == full
        # first full at epoch 14 (13 accepted epochs x 8 rows >= 100): refits at 15, 20, 25, 30
        assert lrn.refits == sum(1 for k in (15, 20, 25, 30) if k <= e)
    u_win, _ = lrn.window_rows("pseudorange")
    assert len(u_win) == 100 and np.all(np.abs(u_win) < 10)
    assert len(lrn.history) == 4 and all(k == "pseudorange" for _, k, _ in lrn.history)


def test_collecting_kernel_is_bank_epoch_plus_the_innovations():
    """bank_epoch_collect returns bank_epoch's values bitwise, and u, q equal the
    standardised innovations of the merged prediction computed in numpy."""
    rng = np.random.default_rng(3)
    N, na, n, m = 4, 9, 7, 6
    A = rng.standard_normal((N, na, na))
    P = A @ np.swapaxes(A, 1, 2) / na + np.eye(na)
    X = rng.standard_normal((N, na)) * 0.3
    lw = np.log(np.full(N, 1.0 / N))
    H = rng.standard_normal((m, na)) * (rng.random((m, na)) < 0.6)
    z, r = rng.standard_normal(m), rng.random(m) + 0.2
    kinds = np.zeros(m, dtype=np.int64)
    tb = BankMixtures({"pseudorange": TRUE}).tables(KINDS)
    a = bank_epoch(lw, X, P, z, H, r, kinds, *tb, 1e4, 2, n)
    u, q = np.empty(m + 3), np.empty(m + 3)
    b = bank_epoch_collect(lw, X, P, z, H, r, kinds, *tb, 1e4, 2, n, u, q)
    assert a[0] == b[0] == 0 and a[1] == b[1]
    for x, y in zip(a[2:], b[2:]):
        assert np.array_equal(x, y)
    _, xm, Pm = bank_moments(lw, X, P)
    np.testing.assert_allclose(u[:m], (z - H @ xm) / np.sqrt(r), rtol=1e-12)
    np.testing.assert_allclose(q[:m], np.einsum("ij,jk,ik->i", H, Pm, H) / r, rtol=1e-12)


# --- on a tight drive ------------------------------------------------------------------
def _drive(change=None, eps=(0.1, 0.4), online="{ window = 600, every = 10 }", methods=("vb", "vb-online")):
    """tight-demo (pseudorange + Doppler, sigma told 3 m) without its satellite outage;
    pseudorange noise TRUE, or with ``change`` [s] its contamination jumps from
    eps[0] to eps[1] (wide part N(0, 6) in both)."""
    text, _ = resolve("tight-demo")
    text = text.replace('outages = [{ window = ["300 s", "360 s"], keep = 3 }]', '')
    if change is None:
        noise = ('pseudorange_noise = { type = "mixture", weights = [0.1, 0.9], '
                 'sigmas = ["7.3484692 m", "2 m"] }')
    else:  # narrow N(0, 2^2) always, plus N(0, 50) with probability eps (6 x 9 = 4 + 50)
        part = ('{{ type = "profile", base = {{ type = "mixture", weights = [{e}, {f}], sigmas = '
                '["7.0710678 m", "1 mm"] }}, steps = {s} }}')
        noise = ('pseudorange_noise = { type = "sum", parts = [ { type = "gaussian", sigma = "2 m" }, '
                 + part.format(e=eps[0], f=1 - eps[0], s=f'[["{change} s", 0]]') + ", "
                 + part.format(e=eps[1], f=1 - eps[1], s=f'[["0 s", 0], ["{change} s", 1]]') + " ] }")
    text = text.replace('range_rate_sigma = "0.1 m/s"', 'range_rate_sigma = "0.1 m/s"\n' + noise)
    common = 'type = "tight-ekf"\nstates = 17\nestimator = "gaussian-mixture"\n'
    body = {
        "vb": 'mixture = { learn = { method = "vb", observables = ["pseudorange"], process = false } }',
        "vb-online": ('mixture = { learn = { method = "vb", observables = ["pseudorange"], process = false, '
                      f'online = {online} }} }}'),
        "online": ('mixture = { learn = { method = "vb", offline = false, observables = ["pseudorange"], '
                   f'online = {online} }} }}'),
    }
    head = text.split("[[methods]]", 1)[0]
    return head + "".join(f'\n[[methods]]\nname = "{k}"\n{common}{body[k]}\n' for k in methods)


def _run_drive(tmp_path, text, seed, after=0.0):
    """Per method: (horizontal RMS, vertical RMS, NEES_pos / 3 after ``after`` [s],
    NIS per dof, the filter)."""
    p = tmp_path / "drive.toml"
    p.write_text(text)
    sc, src, _ = load_scenario(str(p))
    sim = simulate(sc, seed, src)
    s = sc.gnss.satellites
    clock = ClockModel(q_bias=s.clock_bias_noise ** 2, q_drift=s.clock_drift_noise ** 2)
    training = runmod._training(sc, seed, src)
    out = {}
    for i, m in enumerate(sc.methods):
        f, meas = registry.build(m, sim.imu_model, sim.fixes, np.asarray(sc.gnss.lever_arm), src, i,
                                 observations=sim.observations, clock=clock, training=training, seed=seed)
        res = f.run(sim.imu, sim.init, meas)
        t = solution_table(res, sim.truth, sim.outages)
        sel = (t.time_s > after).to_numpy()
        out[m.name] = (np.sqrt(np.mean((t.err_n_m ** 2 + t.err_e_m ** 2)[sel])),
                       np.sqrt(np.mean(t.err_d_m[sel] ** 2)), t.nees_pos[sel].mean() / 3,
                       float(np.mean(res.nis / res.nis_dim)), f, res)
    return out


def _stationary(tmp_path, seeds):
    parts, cons = [], []
    for seed in seeds:
        r = _run_drive(tmp_path, _drive(methods=("online",)), seed, after=100.0)
        h, v, nees, nis, f, res = r["online"]
        lrn = f.online_learner
        # every refit after the first window fill (the first ~65 s), from a Gaussian start
        parts += [[p for part in _parts(mm) for p in part] for e, _, mm in lrn.history if e > 150]
        cons.append((nees, nis))
        assert res.timing["online_refits"] == lrn.refits > 40 and res.timing["online_failed"] == 0
    return np.array(parts), np.array(cons)


def _check_stationary(parts, cons, n_seeds):
    """The window holds 600 rows of ~9 satellites, ~65 epochs. Per window the standard
    errors are: narrow weight sqrt(0.09 / 600) = 0.012, but the rows of one epoch
    share the clock's prediction error, so with the ~65 epochs as the independent
    count 0.037; narrow scale 0.444 sqrt(2 / 540) = 0.027 if the rows' components
    were known, doubled because they are not (the components overlap: rows between
    1 and 2.5 sd are ambiguous), 0.054; wide scale 6 sqrt(2 / 60) = 1.1, and 1.5
    with the overlap. (Measured over 900 refits of 20 runs: SD 0.026, 0.042, 1.43.)
    Each refit must be within 4 of those, and the mean over the refits
    (450 s / 65 s ~ 7 independent windows per run) within 4 of those divided by
    sqrt(7 n_seeds). The wide scale per refit, from ~60 rows, only within
    6 +- 4 x 1.5."""
    truth = np.array([0.9, 4.0 / 9.0, 0.1, 6.0])
    se = np.array([0.037, 0.054, 0.037, 1.5])
    assert np.all(np.abs(parts - truth) < 4 * se), parts[np.any(np.abs(parts - truth) >= 4 * se, axis=1)]
    assert np.all(np.abs(parts.mean(axis=0) - truth) < 4 * se / np.sqrt(7 * n_seeds)), parts.mean(axis=0)
    # Consistency: the noise's variance is the R the filter is told, so the merged
    # prediction's NIS per dof has mean 1: over ~9 rows x 600 epochs a run's mean is
    # within +-0.1 (the rows of one epoch are correlated through the state). The
    # position NEES / 3 of one run averages ~10-20 independent error realisations
    # (errors correlated over 30-60 s): the band [0.4, 1.8] per run is +-3 SD of a
    # chi2(3 x 15) / 45 mean, widened for the EKF's own linearisation; the mean over
    # runs within [0.6, 1.4].
    nees, nis = cons[:, 0], cons[:, 1]
    assert np.all(np.abs(nis - 1.0) < 0.1), nis
    assert np.all((nees > 0.4) & (nees < 1.8)), nees
    assert 0.6 < nees.mean() < 1.4, nees


def test_stationary_mixture_is_relearned_from_a_gaussian_start_and_the_filter_stays_consistent(tmp_path):
    seeds = range(3)
    parts, cons = _stationary(tmp_path, seeds)
    _check_stationary(parts, cons, len(seeds))


@pytest.mark.slow
def test_stationary_mixture_relearned_20_runs(tmp_path):
    seeds = range(20)
    parts, cons = _stationary(tmp_path, seeds)
    _check_stationary(parts, cons, len(seeds))


def _changing(tmp_path, seeds, change=300.0):
    rows, wide = [], []
    for seed in seeds:
        r = _run_drive(tmp_path, _drive(change=change), seed, after=change + 70.0)
        rows.append([r["vb"][:3], r["vb-online"][:3]])
        lrn = r["vb-online"][4].online_learner
        wide += [_parts(mm)[1][0] for e, _, mm in lrn.history if e > change + 70]
    return np.array(rows), np.array(wide)


def _check_changing(rows, wide):
    """After the jump (contamination 0.1 -> 0.4 at 300 s; scored from 370 s, once
    the 600-row window holds only new rows) the online learner's wide weight
    tracks 0.4 (per refit within 4 x 0.06, the weight's SE over ~65 epochs), and
    the filter is at least as accurate as with the offline mixture learned
    before the jump (paired one-sided 95 % t bound of the mean difference <= 0,
    horizontal and vertical), and less overconfident: the offline filter, told
    10 % contamination, has the larger NEES (paired, one-sided 95 %)."""
    from scipy.stats import t as student
    assert np.all(np.abs(wide - 0.4) < 4 * 0.06), wide
    off, on = rows[:, 0, :], rows[:, 1, :]
    n = len(rows)
    for j in (0, 1):
        d = on[:, j] - off[:, j]
        half = student.ppf(0.95, n - 1) * d.std(ddof=1) / np.sqrt(n)
        assert d.mean() - half <= 0.0, (j, d.mean(), half)
    d = on[:, 2] - off[:, 2]
    assert d.mean() + student.ppf(0.95, n - 1) * d.std(ddof=1) / np.sqrt(n) < 0.0, (on[:, 2], off[:, 2])


def test_online_tracks_a_contamination_jump_and_is_not_worse_than_offline(tmp_path):
    rows, wide = _changing(tmp_path, range(6))
    _check_changing(rows, wide)


@pytest.mark.slow
def test_online_tracks_a_contamination_jump_30_runs(tmp_path):
    rows, wide = _changing(tmp_path, range(30))
    _check_changing(rows, wide)


def test_online_disabled_or_never_refitting_is_bitwise_the_offline_filter(tmp_path):
    """Without an online table the filter is the one it was (no collecting kernel);
    with one whose window never fills, the collecting kernel runs every epoch and
    the solution is bitwise the same."""
    p = tmp_path / "d.toml"
    p.write_text(_drive(methods=("vb",)))
    sc, src, _ = load_scenario(str(p))
    sim = simulate(sc, 4, src)
    s = sc.gnss.satellites
    clock = ClockModel(q_bias=s.clock_bias_noise ** 2, q_drift=s.clock_drift_noise ** 2)
    training = runmod._training(sc, 4, src)
    f, meas = registry.build(sc.methods[0], sim.imu_model, sim.fixes, np.asarray(sc.gnss.lever_arm), src, 0,
                             observations=sim.observations, clock=clock, training=training, seed=4)
    assert f.online is None
    r0 = f.run(sim.imu, sim.init, meas)
    g = GaussianMixtureEkf(f.layout, f.imu_model, f.mixtures, clock=clock,
                           online=OnlineSettings(("pseudorange",), window=10 ** 6))
    r1 = g.run(sim.imu, sim.init, meas)
    assert r1.timing["online_refits"] == 0 and g.online_learner.filled("pseudorange") > 4000
    assert np.array_equal(r0.nav, r1.nav) and np.array_equal(r0.sigma, r1.sigma)
    assert np.array_equal(r0.nis, r1.nis)


# --- configuration ---------------------------------------------------------------------
@pytest.mark.parametrize("online,extra,key", [
    ("{ window = 10 }", "", "learn.online.window"),
    ("{ every = 0 }", "", "learn.online.every"),
    ("{ gate = 2 }", "", "learn.online.gate"),
    ("{ windw = 600 }", "", "learn.online.windw"),
    ("{ window = 30 }", "", "mixture.learn"),                       # < 10 rows x 4 components
    ("{ window = 600 }", ', method = "gibbs"', "mixture.learn"),    # online needs VB
    (None, ", offline = false", "mixture.learn"),                   # nothing to learn
    ("{ window = 600 }", ", offline = false, process = true", "mixture.learn"),
])
def test_bad_online_tables_name_their_key(tmp_path, online, extra, key):
    learn = 'method = "vb", observables = ["pseudorange"]' if "method" not in extra else 'observables = ["pseudorange"]'
    learn += extra + (f", online = {online}" if online else "")
    text = _drive(methods=("vb",)).replace(
        'mixture = { learn = { method = "vb", observables = ["pseudorange"], process = false } }',
        f"mixture = {{ learn = {{ {learn} }} }}")
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_scenario(str(p))
    assert key in str(e.value) and "methods[0]" in str(e.value)


def test_online_from_given_mixtures_needs_no_training_and_starts_from_them(tmp_path):
    text = _drive(methods=("online",)).replace(
        'mixture = { learn = { method = "vb", offline = false',
        'mixture = { measurement.pseudorange = { weights = [0.5, 0.5], scales = [0.5, 3.0] }, '
        'learn = { method = "vb", offline = false')
    p = tmp_path / "g.toml"
    p.write_text(text)
    sc, src, _ = load_scenario(str(p))
    assert runmod._training(sc, 0, src) is None
    sim = simulate(sc, 0, src)
    f, _ = registry.build(sc.methods[0], sim.imu_model, sim.fixes, np.zeros(3), src, 0,
                          observations=sim.observations, clock=ClockModel())
    assert f.mixtures.measurement["pseudorange"].scales == (0.5, 3.0)
    lrn = f.online.learner(f.mixtures, KINDS)
    assert lrn.current["pseudorange"].weights == (0.5, 0.5)


def test_online_with_the_coloured_noise_filter_is_a_config_error(tmp_path):
    """M6 (ColoredBankBelief) has its own update and does not collect innovations."""
    text = _drive(methods=("vb-online",)).replace(
        "mixture = { learn = {", "mixture = { colored = { measurement = { pseudorange = 0.5 } }, learn = {")
    p = tmp_path / "c.toml"
    p.write_text(text)
    sc, src, _ = load_scenario(str(p))
    sim = simulate(sc, 0, src)
    with pytest.raises(ConfigError) as e:
        registry.build(sc.methods[0], sim.imu_model, sim.fixes, np.zeros(3), src, 0,
                       observations=sim.observations, clock=ClockModel(),
                       training=runmod._training(sc, 0, src))
    assert "methods[0].mixture.learn.online" in str(e.value)
