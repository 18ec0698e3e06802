"""drive-0708-aided: the along-track drift in the 30 s outage sweep (benchmarks/results/drive0708_drift.md).

    python benchmarks/drive0708_drift.py sweep [--out FILE]    # before/after, all/odd/even
    python benchmarks/drive0708_drift.py suspension            # the squat/dive gain from the data
    python benchmarks/drive0708_drift.py likelihood            # GNSS innovation log-likelihood

``sweep`` runs :func:`mixnav.experiment.sweep.run_outage_sweep` (30 s windows every 10 s,
60-530 s, one withheld at a time, 2 workers) on the shipped drive-0708-aided.toml ("after")
and on the same file without ``[aiding.nhc] pitch_per_accel`` ("before"), and prints per
method the median / p90 / worst of the windows' horizontal maxima and the share of windows
with a mean position NEES above 11.34, over all windows and over the windows starting at odd
(choosing) and even (reporting) multiples of 10 s.

``suspension`` measures the suspension pitch gain from the data alone: the RTK velocity
rotated into the vehicle frame by a run's attitude (the plain EKF's, which has no NHC in it,
and the smoothed aided one, both of the config without the gain), moving faster than 3 m/s, regressed on speed x forward
acceleration (the acceleration from the rotated RTK velocity); on the whole drive, on either
half and outside the config's three withheld windows. No window's error enters it.

``likelihood`` sums the log-likelihood of the aided filter's GNSS position/velocity
innovations (the config's three windows withheld) for the configs with and without the
gain and with the gain's sign flipped.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "src" / "mixnav" / "config" / "datasets" / "drive-0708-aided.toml"
CHI2_99_3 = 11.345


def variant(kind: str) -> str:
    """The shipped config's text as a file of its own: ``after`` (as shipped), ``before``
    (without the suspension gain) or ``flipped`` (the gain's sign flipped)."""
    text = CONFIG.read_text()
    text = text.replace('data_dir = "../shared/data/drive-0708"',
                        f'data_dir = "{(ROOT.parent / "shared" / "data" / "drive-0708").as_posix()}"')
    if kind == "before":
        text = re.sub(r'(?m)^pitch_per_accel = .*\n', "", text)
    elif kind == "flipped":
        text = re.sub(r'(?m)^pitch_per_accel = "', 'pitch_per_accel = "-', text)
    fh = tempfile.NamedTemporaryFile("w", suffix=f"-{kind}.toml", delete=False)
    fh.write(text)
    fh.close()
    return fh.name


def split_summary(rows) -> dict:
    out = {}
    for part, sel in (("all", lambda a: True), ("odd", lambda a: round(a / 10) % 2 == 1),
                      ("even", lambda a: round(a / 10) % 2 == 0)):
        for m, g in rows.groupby("method", sort=False):
            g = g[g.start_s.map(sel)]
            h, ne = g.horizontal_max_m.to_numpy(float), g.nees_pos_mean.to_numpy(float)
            out.setdefault(part, {})[m] = {
                "n": int(len(g)), "median_m": float(np.median(h)), "p90_m": float(np.percentile(h, 90)),
                "worst_m": float(h.max()), "worst_start_s": float(g.start_s.to_numpy()[np.argmax(h)]),
                "nees_over_share": float(np.mean(ne > CHI2_99_3)) if np.isfinite(ne).any() else None}
    return out


def cmd_sweep(a):
    from mixnav.experiment.sweep import run_outage_sweep
    res = {}
    for kind in ("before", "after"):
        r = run_outage_sweep(variant(kind), "30 s", "10 s", ("60 s", "530 s"), workers=2)
        res[kind] = {"summary": split_summary(r.rows),
                     "windows": {m: dict(zip(g.start_s.astype(float), g.horizontal_max_m.astype(float)))
                                 for m, g in r.rows.groupby("method", sort=False)}}
        for part, s in res[kind]["summary"].items():
            for m, v in s.items():
                if m == "ekf":
                    continue
                nees = "" if v["nees_over_share"] is None else f"NEES>bound {100 * v['nees_over_share']:.1f} %"
                print(f"{kind:6s} {part:4s} {m:15s} n={v['n']:2d} median {v['median_m']:5.2f} p90 {v['p90_m']:5.2f} "
                      f"worst {v['worst_m']:5.2f} ({v['worst_start_s']:.0f} s) {nees}")
    print("aided per window (before -> after) [m]:")
    b, f = res["before"]["windows"]["aided"], res["after"]["windows"]["aided"]
    print("  " + "  ".join(f"{s:.0f}: {b[s]:.1f}->{f[s]:.1f}" for s in b))
    if a.out:
        Path(a.out).write_text(json.dumps(res, indent=1))


def cmd_suspension(a):
    from mixnav.experiment.sweep import _load, _run_windowed
    ds, src, p, folder, inputs = _load(variant("before"), None)   # measured without the gain
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        po, _ = _run_windowed(p, ds, src, folder, inputs, [], score=False)
    ref, tabs = po.reference, p.tables(po)
    own = [tuple(w) for w in ds.gnss.withhold]

    def cnb(r, pt, y):
        cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(pt), np.sin(pt), np.cos(y), np.sin(y)
        return np.array([[cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
                         [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy], [-sp, sr * cp, cr * cp]])

    for meth in ("ekf", "aided-smoothed"):
        s = tabs[meth]
        t = s.time_s.to_numpy()
        r, pt, y = (np.radians(s[c].to_numpy()) for c in ("roll_deg", "pitch_deg", "yaw_deg"))
        v_n = np.column_stack([np.interp(t, ref.time, ref.v_n[:, k]) for k in range(3)])
        vb = np.einsum("kji,kj->ki", np.array([cnb(*x) for x in zip(r, pt, y)]), v_n)   # C_bn v_n
        ax = np.gradient(vb[:, 0], t)
        base = (vb[:, 0] > 3) & (t > 50) & np.isfinite(vb[:, 2]) & (abs(ax) < 5)
        inside = np.zeros(len(t), bool)
        for w0, w1 in own:
            inside |= (t > w0) & (t < w1)
        for name, sel in (("whole drive", base), ("t < 300 s", base & (t < 300)), ("t >= 300 s", base & (t >= 300)),
                          ("outside the 3 windows", base & ~inside)):
            X = np.column_stack([np.ones(sel.sum()), vb[sel, 0] * ax[sel]])
            c, *_ = np.linalg.lstsq(X, vb[sel, 2], rcond=None)
            e = vb[sel, 2] - X @ c
            print(f"{meth:15s} {name:22s} n={sel.sum():5d}  k = {np.degrees(c[1]):.3f} deg/(m/s^2)  "
                  f"vertical std {vb[sel, 2].std():.4f} -> {e.std():.4f} m/s")


def gnss_loglik(config_path: str) -> tuple[float, int]:
    """The aided filter's GNSS position/velocity innovation log-likelihood on a config file (its
    own windows withheld) and the GNSS epochs it sums: a criterion that reads no reference."""
    from mixnav.config import load_dataset
    from mixnav.experiment.data_folder import find_data_dir
    from mixnav.experiment.pipelines import pipeline
    from mixnav.filters import ekf as _ekf
    from mixnav.measurements.kinds import KINDS
    log = []
    orig = _ekf.KalmanEstimator.update

    def update(self, epoch):
        rows = epoch.rows()
        if rows is not None:
            log.append((rows.z.copy(), rows.H @ self.P @ rows.H.T + np.diag(rows.R), np.asarray(rows.kinds) % 32))
        return self.update_rows(rows)
    gnss = [KINDS["position"], KINDS["velocity"]]
    _ekf.KalmanEstimator.update = update
    try:
        ds, src, _ = load_dataset(config_path)
        ds = ds.model_copy(update={"methods": [m for m in ds.methods if m.name == "aided"]})
        p = pipeline(ds, src)
        folder = find_data_dir(ds, None, src)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            p.run(ds, src, folder, p.load(ds, src, folder))
    finally:
        _ekf.KalmanEstimator.update = orig
    ll, n = 0.0, 0
    for z, S, k in log:
        sel = np.isin(k, gnss)
        if sel.any():
            zz, SS = z[sel], S[np.ix_(sel, sel)]
            ll -= 0.5 * (zz @ np.linalg.solve(SS, zz) + np.linalg.slogdet(SS)[1] + len(zz) * np.log(2 * np.pi))
            n += 1
    return ll, n


def cmd_nhc_rate(a):
    """The NHC rate by the GNSS innovation log-likelihood (no reference read): the shipped
    config with each rate, the sigmas as shipped and scaled by sqrt(rate / 10 Hz) (the
    violation is correlated over about 2 s, so a row's white-noise equivalent grows with
    the rate: the shipped 0.1 / 0.25 m/s are its 10 Hz values)."""
    for scaled in (False, True):
        for r in (1, 2, 5, 10, 20, 50):
            path = variant("after")
            text = Path(path).read_text()
            text = re.sub(r'(?m)^rate = "10 Hz"$', f'rate = "{r} Hz"', text, count=1)
            if scaled:
                f = (r / 10.0) ** 0.5
                text = text.replace('sigma = ["0.1 m/s", "0.25 m/s"]',
                                    f'sigma = ["{0.1 * f:.4f} m/s", "{0.25 * f:.4f} m/s"]')
            Path(path).write_text(text)
            ll, n = gnss_loglik(path)
            print(f"NHC {r:3d} Hz, sigmas {'scaled' if scaled else 'as shipped'}: GNSS epochs {n}  "
                  f"log-likelihood {ll:.1f}", flush=True)


def cmd_likelihood(a):
    """The GNSS innovation log-likelihood of the configs without the suspension gain, as
    shipped, and with its sign flipped (:func:`gnss_loglik`)."""
    for kind in ("before", "after", "flipped"):
        ll, n = gnss_loglik(variant(kind))
        print(f"{kind:8s} GNSS epochs {n}  log-likelihood {ll:.1f}")

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("sweep", "suspension", "likelihood", "nhc-rate"))
    ap.add_argument("--out", default=None, help="sweep: write the summaries and windows as JSON")
    a = ap.parse_args(argv)
    {"sweep": cmd_sweep, "suspension": cmd_suspension, "likelihood": cmd_likelihood,
     "nhc-rate": cmd_nhc_rate}[a.what](a)


if __name__ == "__main__":
    sys.exit(main())
