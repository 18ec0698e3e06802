"""Monte Carlo runner throughput: local workers 1 vs 2, and the Dask path's overhead per run.

    PYTHONPATH=src python benchmarks/bench_experiment.py [--runs 8] [--repeat 3]

Each timing is a whole ``run_experiment`` call into a fresh folder (pool start,
worker imports and first-run caches included, as a user sees it), median of
``--repeat`` calls. The Dask path runs the same seeds on a LocalCluster
(2 worker processes, 1 thread each, loopback) started before timing; its
first call meets cold workers like the local pool does (that call is the
"cold" figure), later calls reuse the warm worker caches ("warm").
overhead per run = (t_dask - t_local_2_workers) / runs.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
sys.path.insert(0, str(SRC))
os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(SRC), os.environ.get("PYTHONPATH")) if p)

from mixnav.experiment.montecarlo import run_experiment  # noqa: E402

SCENARIO = "loose-demo"


def timed(runs: int, **kw) -> float:
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        run_experiment(SCENARIO, runs, Path(d), progress=False, **kw)
        return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=8)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    runs, rep = a.runs, a.repeat

    timed(1, workers=1)  # warm this process (imports, numba) so workers=1 is not penalised
    t1 = statistics.median(timed(runs, workers=1) for _ in range(rep))
    t2 = statistics.median(timed(runs, workers=2) for _ in range(rep))

    import distributed
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        addr = cluster.scheduler_address
        td_cold = timed(runs, scheduler=addr)
        td_warm = statistics.median(timed(runs, scheduler=addr) for _ in range(rep))

    print(f"machine: {platform.platform()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, dask/distributed {distributed.__version__}")
    print(f"scenario {SCENARIO}, {runs} runs per call, median of {rep} calls")
    print(f"local workers=1: {t1:.2f} s, {runs / t1:.2f} runs/s")
    print(f"local workers=2: {t2:.2f} s, {runs / t2:.2f} runs/s, speed-up x{t1 / t2:.2f}")
    print(f"dask 2 workers cold: {td_cold:.2f} s, {runs / td_cold:.2f} runs/s, overhead per run "
          f"{(td_cold - t2) / runs * 1e3:+.0f} ms vs local 2 workers")
    print(f"dask 2 workers warm: {td_warm:.2f} s, {runs / td_warm:.2f} runs/s, overhead per run "
          f"{(td_warm - t2) / runs * 1e3:+.0f} ms vs local 2 workers")


if __name__ == "__main__":
    main()
