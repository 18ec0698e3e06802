"""drive-0708's IMU time tags: where the first tick belongs, measured from the data alone.

    python benchmarks/drive0708_time_tags.py [--data DIR] [--workers 2] [--out benchmarks/results]

The data README says: spread the IMU ticks linearly between the tag's start and its end. The
tag's first pair says the stream's first bytes came 131 ms after that start, and the ticks'
span (548.59 s) is 141 ms shorter than the tag's: spreading from the start stretches every
IMU time by 257 ppm, a time offset that drifts by 0.13 s over the drive. Two measurements,
neither reads the reference:

1. **The chunks' arrival times.** Each (tick_ms, file_pos) pair says when the stream's first
   ``file_pos`` bytes had come. The stream was logged with CRLF line ends (the CSV has LF: line
   ``i`` starts ``i`` bytes later in the stream; checked by the result, arrival minus tick
   constant to milliseconds, which a wrong byte map would not give). The arrival time of the
   last whole line before each pair, against that line's IMU tick: the lower envelope's slope
   (per 20 s, the earliest arrival: the least queueing) is the IMU clock's rate against the
   logger's, the residual above it the logging jitter.
2. **The GNSS innovation likelihood.** ``drive-0708-aided.toml`` (its withheld windows removed,
   every fix used except the tuner's cross-validation windows) run with IMU time offsets from
   -0.275 to -0.125 s on each quarter of 60-530 s (``mixnav.experiment.tuning.criterion
   .Evaluator``: 30 s windows, 3 folds), under both rules: the offset each quarter prefers.
   One true offset is the same in every quarter.

Writes ``drive0708_time_tags.md`` and ``.json``.
"""

from __future__ import annotations

import argparse
import itertools
import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "drive-0708"
HAND = ROOT / "src" / "mixnav" / "config" / "datasets" / "drive-0708-aided.toml"
QUARTERS = [(60.0, 177.5), (177.5, 295.0), (295.0, 412.5), (412.5, 530.0)]
OFFSETS = [-0.275, -0.25, -0.225, -0.2, -0.175, -0.15, -0.125]
RULES = ("tag", "first-bytes")


def arrival_against_ticks(folder: Path) -> dict:
    """Part 1: the IMU clock's rate against the logger's from the tag's pairs (module docstring)."""
    from mixnav.io.drive0708 import _FIXED, _HEADER, read_time_tag
    tag = read_time_tag(folder / "imu_1934.csv.tag")      # validated: start, end, the first pair's lead
    # the reader keeps no pairs: read them past its header and fixed part
    b = (folder / "imu_1934.csv.tag").read_bytes()
    pairs = np.frombuffer(b, dtype="<u4", offset=_HEADER + _FIXED).reshape(-1, 2).astype(np.int64)
    data = (folder / "imu_1934.csv").read_bytes()
    starts = np.concatenate([[0], np.flatnonzero(np.frombuffer(data, dtype=np.uint8) == 10) + 1])
    stream_starts = starts + np.arange(len(starts))          # CRLF in the stream: one byte more a line
    ticks = np.full(len(starts), np.nan)
    for i, line in enumerate(data.split(b"\n")[:len(starts)]):
        f = line.split(b",")
        if len(f) == 7:
            try:
                ticks[i] = float(f[6]) / 1000.0
            except ValueError:
                pass
    k = np.searchsorted(stream_starts, pairs[:, 1], side="right") - 2     # the last whole line before
    ok = (k >= 0) & (k < len(ticks))
    tick, arrival = ticks[k[ok]], pairs[ok, 0] / 1000.0
    g = np.isfinite(tick)
    tick, arrival = tick[g], arrival[g]
    d = arrival - tick
    bins = ((tick - tick[0]) // 20.0).astype(int)
    env = np.array([(tick[bins == i][np.argmin(d[bins == i])], arrival[bins == i][np.argmin(d[bins == i])])
                    for i in np.unique(bins)])
    slope, icpt = np.polyfit(env[:, 0], env[:, 1], 1)
    resid = arrival - (slope * tick + icpt)
    tick_span = (np.nanmax(ticks) - np.nanmin(ticks))
    # the span from the last pair's tick (end - start would lose 0.05 us to the epoch's size)
    tag_span, lead = pairs[-1, 0] / 1000.0, tag.first
    return {"pairs": int(len(tick)), "envelope_rate_ppm": float((slope - 1) * 1e6),
            "jitter_median_s": float(np.median(resid)), "jitter_p90_s": float(np.percentile(resid, 90)),
            "jitter_min_s": float(resid.min()), "tick_span_s": float(tick_span), "tag_span_s": tag_span,
            "lead_s": lead, "tag_rule_ppm": float((tag_span / tick_span - 1) * 1e6),
            "first_bytes_rule_ppm": float(((tag_span - lead) / tick_span - 1) * 1e6)}


def _job(args):
    rule, span, offset, data = args
    import tomlkit
    from mixnav.experiment.tuning.criterion import Evaluator, cv_windows, without_reference
    doc = tomlkit.parse(without_reference(HAND.read_text()))
    del doc["gnss"]["withhold"]
    doc["imu"]["tag_start"] = rule
    doc["installation"]["imu_time_offset"] = f"{offset} s"
    text = tomlkit.dumps(doc)
    windows = [f for f in cv_windows(span[0], span[1], 30.0, 3, step=15.0) if f]
    sc = Evaluator(text, str(HAND), data, "aided", windows, span).evaluate(text)
    return rule, span, offset, sc.innovation_ll, sc.nlpd


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(DATA))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    a = ap.parse_args(argv)
    part1 = arrival_against_ticks(Path(a.data))
    jobs = [(r, q, o, a.data) for r, q, o in itertools.product(RULES, QUARTERS, OFFSETS)]
    with ProcessPoolExecutor(a.workers) as ex:
        rows = list(ex.map(_job, jobs))
    best = {r: [max((x for x in rows if x[0] == r and x[1] == q), key=lambda x: x[3])[2] for q in QUARTERS]
            for r in RULES}
    res = {"arrival": part1, "offsets_s": OFFSETS, "quarters_s": QUARTERS, "best_offset_s": best,
           "innovation_ll": {r: {f"{q[0]:g}-{q[1]:g}": [x[3] for x in rows if x[0] == r and x[1] == q]
                                 for q in QUARTERS} for r in RULES}}
    out = Path(a.out)
    (out / "drive0708_time_tags.json").write_text(json.dumps(res, indent=1) + "\n")
    p = part1
    lines = ["# drive-0708: where the IMU's first tick belongs (the time tag)", "",
             "`python benchmarks/drive0708_time_tags.py` (module docstring). No reference read.", "",
             "## 1. The chunks' arrival times against the IMU ticks", "",
             f"{p['pairs']} tag pairs. The IMU ticks span {p['tick_span_s']:.3f} s, the tag {p['tag_span_s']:.3f} s; "
             f"its first pair comes {1000 * p['lead_s']:.0f} ms after its start.", "",
             "| | IMU clock against the logger's [ppm] |", "|---|---|",
             f"| the chunks' arrival (lower envelope, per 20 s) | {p['envelope_rate_ppm']:.1f} |",
             f"| the data README's rule (first tick at the tag's start) | {p['tag_rule_ppm']:.1f} |",
             f"| `tag_start = \"first-bytes\"` (first tick at the first pair) | {p['first_bytes_rule_ppm']:.1f} |", "",
             f"Arrival above the envelope: median {1000 * p['jitter_median_s']:.1f} ms, p90 "
             f"{1000 * p['jitter_p90_s']:.1f} ms, lowest {1000 * p['jitter_min_s']:.1f} ms.", "",
             "## 2. The IMU time offset each quarter's GNSS innovation likelihood prefers", "",
             "`drive-0708-aided.toml` with every fix but the cross-validation windows; per update, higher is "
             "better; offsets " + ", ".join(f"{o:g}" for o in OFFSETS) + " s.", "",
             "| rule | " + " | ".join(f"{q[0]:g}-{q[1]:g} s" for q in QUARTERS) + " |",
             "|---|" + "---|" * len(QUARTERS)]
    for r in RULES:
        lines.append(f"| {r} | " + " | ".join(f"{b:+.3f} s" for b in best[r]) + " |")
    lines += ["", "Innovation log-likelihood per update (rows: offsets as above):", ""]
    for r in RULES:
        lines += [f"- {r}: " + "; ".join(f"{k}: " + " ".join(f"{v:.3f}" for v in vals)
                                         for k, vals in res["innovation_ll"][r].items())]
    (out / "drive0708_time_tags.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
