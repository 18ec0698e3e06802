"""Wall time of ``mixnav tune`` on the three raw-GNSS recordings, one worker, the default
budget: the code on ``PYTHONPATH`` (run it once with the tree before a change, once after).

    PYTHONPATH=SRC python benchmarks/tune_raw_speed.py --label LABEL [--budget N] [--commit C] [--only NAME]

(``--commit``: the commit an exported tree, ``git archive C src``, was taken from; ``--only``:
that recording alone, merged into the label's entry. A label ``before...`` is compared with
``after...`` of the same suffix.)

Each recording's untuned file (``tune_raw_gnss.untuned_text``: the shipped file without its
``[motion]`` noise keys) is tuned into the same folder every time, so the written
``tuned.toml`` of two labels can be compared byte for byte (its SHA-256 and the criterion
values are recorded; each recording is first tuned untimed at budget 2, so numba's
compilation and the files' first read are not timed). Merges its label into benchmarks/results/tune_raw_speed.json and
rewrites benchmarks/results/tune_raw_speed.md.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from tune_raw_gnss import RECORDINGS, untuned_text  # noqa: E402

WORK = Path("/tmp/mixnav-tune-raw-speed")
OUT = HERE / "results" / "tune_raw_speed.json"


def main(argv) -> None:
    import mixnav
    label = argv[argv.index("--label") + 1]
    budget = int(argv[argv.index("--budget") + 1]) if "--budget" in argv else None
    src_dir = Path(mixnav.__file__).resolve().parents[1]
    try:
        commit = subprocess.run(["git", "-C", str(src_dir), "rev-parse", "HEAD"], capture_output=True, text=True,
                                check=True).stdout.strip()
        dirty = bool(subprocess.run(["git", "-C", str(src_dir), "status", "--porcelain", "src"], capture_output=True,
                                    text=True, check=True).stdout.strip())
    except (OSError, subprocess.CalledProcessError):   # an exported tree (git archive): say which
        commit, dirty = argv[argv.index("--commit") + 1] if "--commit" in argv else "unknown", False
    only = argv[argv.index("--only") + 1] if "--only" in argv else None
    names = [only] if only else list(RECORDINGS)
    res = json.loads(OUT.read_text()) if OUT.exists() else {}
    rec = {"src": str(src_dir), "commit": commit, "uncommitted_changes": dirty, "budget": budget or "default",
           "workers": 1, "recordings": res.get(label, {}).get("recordings", {}) if only else {}}
    WORK.mkdir(exist_ok=True)
    for name in names:   # untimed: numba's compilation and the files' first read
        (WORK / f"{name}-untuned.toml").write_text(untuned_text(name))
        mixnav.tune(WORK / f"{name}-untuned.toml", WORK / "warm-up", budget=2, workers=1, overwrite=True)
    for name in names:
        src = WORK / f"{name}-untuned.toml"
        src.write_text(untuned_text(name))
        out = WORK / name
        shutil.rmtree(out, ignore_errors=True)
        kw = {} if budget is None else {"budget": budget}
        load0 = os.getloadavg()
        t0, c0 = time.perf_counter(), time.process_time()
        tr = mixnav.tune(src, out, workers=1, progress=False, **kw)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        text = (out / "tuned.toml").read_bytes()
        rec["recordings"][name] = {"wall_s": wall, "cpu_s": cpu, "filter_runs": tr.runs, "evaluations": len(tr.evaluations),
                                   "criterion_given": tr.given["criterion"], "criterion_tuned": tr.tuned["criterion"],
                                   "tuned_toml_sha256": hashlib.sha256(text).hexdigest(),
                                   "load_before": load0, "load_after": os.getloadavg()}
        print(label, name, f"{wall:.0f} s", tr.runs, "runs", flush=True)
    res = json.loads(OUT.read_text()) if OUT.exists() else {}
    res[label] = rec
    OUT.write_text(json.dumps(res, indent=1) + "\n")
    OUT.with_suffix(".md").write_text(markdown(res))


def markdown(res: dict) -> str:
    lines = ["# mixnav tune on raw-GNSS recordings: wall time, one worker (issue 35)", "",
             "`benchmarks/tune_raw_speed.py`: each recording's untuned file (the shipped file without its "
             "`[motion]` noise keys) tuned with `--workers 1` at the default budget, by the code of each label "
             "(2 cores shared with other sessions: the load averages are beside each row, and the process's CPU "
             "time, which the other sessions move less, beside the wall time; one worker runs in this process).", ""]
    for label, rec in res.items():
        lines.append(f"- `{label}`: {rec['src']} at {rec['commit'][:10]}"
                     f"{' with uncommitted changes' if rec['uncommitted_changes'] else ''}, budget {rec['budget']}")
    lines += ["", "| recording | label | wall [s] | CPU [s] | evaluations | pipeline runs | criterion given -> tuned | "
              "tuned.toml SHA-256 | load before / after |", "|---|---|---:|---:|---:|---:|---|---|---|"]
    for name in RECORDINGS:
        for label, rec in res.items():
            r = rec["recordings"].get(name)
            if r is None:
                continue
            lines.append(f"| {name} | {label} | {r['wall_s']:.0f} | {r['cpu_s']:.0f} | {r['evaluations']} | {r['filter_runs']} | "
                         f"{r['criterion_given']:.6f} -> {r['criterion_tuned']:.6f} | "
                         f"`{r['tuned_toml_sha256'][:16]}` | {r['load_before'][0]:.2f} / {r['load_after'][0]:.2f} |")
    for before in [k for k in res if k.startswith("before")]:
        after = "after" + before.removeprefix("before")
        if after not in res:
            continue
        lines += ["", f"`{before}` against `{after}`:", "",
                  "| recording | speed-up, wall | speed-up, CPU | CPU per pipeline run before / after [s] | "
                  "tuned.toml identical |", "|---|---:|---:|---|---|"]
        for name in RECORDINGS:
            b, a = res[before]["recordings"].get(name), res[after]["recordings"].get(name)
            if a and b:
                lines.append(f"| {name} | {b['wall_s'] / a['wall_s']:.1f} | {b['cpu_s'] / a['cpu_s']:.1f} | "
                             f"{b['cpu_s'] / b['filter_runs']:.2f} / {a['cpu_s'] / a['filter_runs']:.2f} | "
                             f"{'yes' if a['tuned_toml_sha256'] == b['tuned_toml_sha256'] else 'NO'} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main(sys.argv[1:])
