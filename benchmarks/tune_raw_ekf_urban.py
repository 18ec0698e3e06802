"""Why the plain EKF among the high-rises (urbannav-tst-static) is no better than the plain SPP,
and whether tuning it by its own innovation likelihood changes that (issue 35: "a tuned urban
filter must never be worse than the plain SPP on the same epochs").

    python benchmarks/tune_raw_ekf_urban.py

1. The EKF's error against the SPP's on the same epochs, their mean error (the bias no
   averaging removes) and sd, for motion noise from a static receiver's to none at all, with
   the inter-system offsets as the pipeline has them (a random walk of 0.01 m/sqrt(s)) and
   free (100 m/sqrt(s): each epoch its own, as the SPP). Diagnosis only: nothing is chosen
   from these errors.
2. ``mixnav tune --method ekf`` on the untuned file (the EKF's own likelihood, no reference),
   then the EKF's pseudorange sigmas scaled by s (``raw_gnss.sigma_a`` and ``sigma_b`` both
   times s: the SPP's positions are unchanged by a common factor on its weights, only its
   covariance, the filter's start, scales) and the floor ``sigma_a`` alone, each scored by the
   same criterion (the EKF's innovation log-likelihood over the tuner's starts); the reference
   only afterwards.

Writes benchmarks/results/tune_raw_ekf_urban.{json,md}.
"""

from __future__ import annotations

import functools
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import tomlkit

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from tune_raw_gnss import DATASETS, untuned_text  # noqa: E402

NAME = "urbannav-tst-static"
STATIC = {"accel_sigma": "0.01 m/s^2/sqrt(Hz)", "vertical_accel_sigma": "0.01 m/s^2/sqrt(Hz)"}
FREE = {"accel_sigma": "30 m/s^2/sqrt(Hz)", "vertical_accel_sigma": "30 m/s^2/sqrt(Hz)", "clock_q_bias": 1e8,
        "clock_q_drift": 1e6}
DEFAULTS = dict.fromkeys(("accel_sigma", "vertical_accel_sigma", "clock_q_bias", "clock_q_drift"))   # keys removed


def plain(text: str, motion: dict | None = None, raw: dict | None = None) -> str:
    """``text`` with the SPP and the EKF only (no smoother), ``motion`` / ``raw`` keys set (None: removed)."""
    doc = tomlkit.parse(text)
    for k, v in (motion or {}).items():
        if v is None:
            doc["motion"].pop(k, None)
        else:
            doc["motion"][k] = v
    for k, v in (raw or {}).items():
        doc["raw_gnss"][k] = v
    methods = tomlkit.aot()
    for m in doc["methods"]:
        if m["name"] in ("spp", "ekf"):
            m.pop("smooth", None)
            methods.append(m)
    doc["methods"] = methods
    return tomlkit.dumps(doc)


def errors(text: str, tmp: Path) -> dict:
    """2-D RMSE, mean error (north, east, its norm) and sd of the SPP and the EKF, same epochs."""
    import mixnav
    p = tmp / "x.toml"
    p.write_text(text)
    sol = mixnav.process_dataset(p).solutions
    ne = {m: (sol[m]["err_n_m"].to_numpy(float), sol[m]["err_e_m"].to_numpy(float)) for m in ("spp", "ekf")}
    ok = np.isfinite(ne["spp"][0]) & np.isfinite(ne["ekf"][0])
    out = {"epochs": int(ok.sum())}
    for m, (n, e) in ne.items():
        n, e = n[ok], e[ok]
        out[m] = {"rmse_m": float(np.sqrt(np.mean(n ** 2 + e ** 2))), "mean_n_m": float(n.mean()),
                  "mean_e_m": float(e.mean()), "mean_norm_m": float(np.hypot(n.mean(), e.mean())),
                  "sd_m": float(np.sqrt(n.var() + e.var()))}
    return out


def main() -> None:
    import mixnav
    import mixnav.motion.constant_velocity as cvm
    from mixnav.experiment.tuning.criterion import without_reference
    from mixnav.experiment.tuning.raw_gnss import SETTLE, RawEvaluator, starts_for
    shipped = tomlkit.parse((DATASETS / f"{NAME}.toml").read_text())
    shipped["dataset"]["data_dir"] = str((HERE.parent / shipped["dataset"]["data_dir"]).resolve())
    shipped = tomlkit.dumps(shipped)
    res = {"diagnosis": [], "sigma": []}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        layout = cvm.constant_velocity_layout
        for walk in (0.01, 100.0):
            cvm.constant_velocity_layout = functools.partial(layout, offset_walk=walk)
            try:
                for label, motion in (("static (0.01, as shipped)", STATIC), ("schema defaults", DEFAULTS),
                                      ("none (free)", FREE)):
                    res["diagnosis"].append({"offset_walk": walk, "motion": label,
                                             **errors(plain(shipped, motion), tmp)})
                    print(res["diagnosis"][-1], flush=True)
            finally:
                cvm.constant_velocity_layout = layout
        src = tmp / "untuned.toml"
        src.write_text(untuned_text(NAME))
        tr = mixnav.tune(src, tmp / "tune", method="ekf", workers=1)
        tuned = (tmp / "tune" / "tuned.toml").read_text()
        res["ekf_tune"] = {"chosen": {k: c["value"] for k, c in tr.chosen.items()}, "runs": tr.runs,
                           "criterion_given": tr.given["criterion"], "criterion_tuned": tr.tuned["criterion"],
                           "errors_untuned": errors(plain(src.read_text()), tmp),
                           "errors_tuned": errors(plain(tuned), tmp)}
        print(res["ekf_tune"], flush=True)
        doc = tomlkit.parse(tuned)
        a0, b0 = float(doc["raw_gnss"].get("sigma_a", 3.0)), float(doc["raw_gnss"].get("sigma_b", 3.0))
        starts = starts_for(985.0)
        ev = RawEvaluator(without_reference(tuned), str(src), None, "ekf", starts, SETTLE)
        for kind, s in [("scale", s) for s in (0.25, 0.5, 1.0, 2.0, 4.0)] + \
                       [("floor", s) for s in (0.0, 0.5, 2.0, 4.0)]:
            raw = {"sigma_a": a0 * s, "sigma_b": b0 * s} if kind == "scale" else {"sigma_a": a0 * s, "sigma_b": b0}
            text = plain(tuned, raw={k: f"{v:g} m" for k, v in raw.items()})
            sc = ev.evaluate(without_reference(text)).as_dict()
            res["sigma"].append({"kind": kind, "factor": s, **{k: v for k, v in raw.items()},
                                 "criterion": sc["criterion"], **errors(text, tmp)})
            print(res["sigma"][-1], flush=True)
    res["load_average"] = os.getloadavg()
    (HERE / "results" / "tune_raw_ekf_urban.json").write_text(json.dumps(res, indent=1) + "\n")
    (HERE / "results" / "tune_raw_ekf_urban.md").write_text(markdown(res))


def markdown(res: dict) -> str:
    f = lambda e: f"{e['rmse_m']:.2f} / {e['mean_norm_m']:.2f} / {e['sd_m']:.2f}"  # noqa: E731
    lines = ["# The plain EKF among the high-rises (urbannav-tst-static) against the plain SPP (issue 35)", "",
             "`benchmarks/tune_raw_ekf_urban.py`. Cells: 2-D RMSE / norm of the mean error / sd [m] on the same "
             "epochs (the reference used only to score, never to choose).", "",
             "## 1. Motion noise and inter-system offsets (diagnosis)", "",
             "| offset walk [m/sqrt(s)] | motion noise | epochs | EKF | SPP |", "|---:|---|---:|---|---|"]
    for d in res["diagnosis"]:
        lines.append(f"| {d['offset_walk']:g} | {d['motion']} | {d['epochs']} | {f(d['ekf'])} | {f(d['spp'])} |")
    t = res["ekf_tune"]
    lines += ["", "## 2. The EKF tuned by its own likelihood (`mixnav tune --method ekf`)", "",
              f"Criterion {t['criterion_given']:.4f} -> {t['criterion_tuned']:.4f}, {t['runs']} pipeline runs; "
              "chosen: " + "; ".join(f"`{k}` = {v}" for k, v in t["chosen"].items()), "",
              f"- untuned: EKF {f(t['errors_untuned']['ekf'])}, SPP {f(t['errors_untuned']['spp'])}",
              f"- tuned: EKF {f(t['errors_tuned']['ekf'])}, SPP {f(t['errors_tuned']['spp'])}", "",
              "Then the EKF's pseudorange sigmas on the tuned file, by the same criterion (lower is better):", "",
              "| change | sigma_a [m] | sigma_b [m] | criterion | EKF | SPP |", "|---|---:|---:|---:|---|---|"]
    for s in res["sigma"]:
        lines.append(f"| {s['kind']} x{s['factor']:g} | {s['sigma_a']:.2f} | {s.get('sigma_b', float('nan')):.2f} | "
                     f"{s['criterion']:.4f} | {f(s['ekf'])} | {f(s['spp'])} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
