"""Where ``mixnav tune``'s candidate files are scored: the evaluators on worker processes (or a
Dask cluster), each built once per process and keeping the data it read, and the driver's
:class:`Scorer` (the journal, the budget, one progress bar, one pool).

A *setup* names the evaluator class and its arguments: ``("module:Class", text, source, data,
method, ...)``: :class:`.criterion.Evaluator` (IMU + fixes: the folds' windows, the span) or
:class:`.vehicle.VehicleEvaluator` (odometry + pseudoranges: the starts, how long after each
start the rows are scored, the criterion). The class is imported by name in the worker, so
this module depends on neither.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import os
from pathlib import Path


_EVALUATORS: dict = {}


def _evaluator(setup: tuple):
    key = hashlib.sha256(json.dumps(setup, default=str).encode()).hexdigest()
    if key not in _EVALUATORS:
        _EVALUATORS.clear()
        module, name = setup[0].split(":")
        _EVALUATORS[key] = getattr(importlib.import_module(module), name)(*setup[1:])
    return _EVALUATORS[key]


def _evaluate_task(setup: tuple, text: str) -> tuple[str, dict]:
    """A candidate file's score, anywhere (the evaluator is built once per process)."""
    return text, _evaluator(setup).evaluate(text).as_dict()


def _worker_init(setup: tuple) -> None:
    from ..parallel import die_with_parent
    die_with_parent()
    _evaluator(setup)


# ---------------------------------------------------------------- driver side

class Scorer:
    """Scores candidate files: from the journal, else on the executor; appends to the journal.
    One progress bar over the budget, and one process pool (or Dask client) for the whole
    tuning: the workers keep the data they read (:meth:`close` ends them)."""

    def __init__(self, setup, journal: Path, workers, scheduler, progress, budget: int, runs_per_candidate: int):
        from ..parallel import Progress
        self.setup, self.journal, self.workers, self.scheduler = setup, journal, workers, scheduler
        self.budget, self.runs, self.runs_per_candidate = budget, 0, runs_per_candidate
        self.bar = Progress(budget, progress, label="tune")
        self._pool, self._client = None, None
        self.cache: dict[str, dict] = {}
        self.seen: set[str] = set()
        # the journal's key: everything but the file's text (each candidate is keyed by its own text)
        self.setup_key = hashlib.sha256(json.dumps([setup[0], *setup[2:]], default=str).encode()).hexdigest()[:16]
        if journal.exists():
            for line in journal.read_text().splitlines():
                try:
                    rec = json.loads(line)
                except json.JSONDecodeError:
                    continue   # a line cut by an interruption: that candidate runs again
                if rec.get("setup") == self.setup_key:
                    self.cache[rec["key"]] = rec["score"]

    @staticmethod
    def key(text: str) -> str:
        return hashlib.sha256(text.encode()).hexdigest()

    def left(self) -> int:
        return self.budget - len(self.seen)

    def score(self, texts: list[str]) -> list[dict]:
        """Scores of ``texts`` in order. Each distinct candidate counts once against the budget,
        whether it is run or found in the journal (a resumed search takes the same path and
        stops at the same place); those beyond the budget get None."""
        todo = []
        for t in texts:
            k = self.key(t)
            if k not in self.seen:
                if self.left() <= 0:
                    continue
                self.seen.add(k)
                if k in self.cache:
                    self.bar.advance()
            if k not in self.cache and t not in todo:
                todo.append(t)
        if todo:
            results = self._map(todo)
            with open(self.journal, "a") as fh:
                for text, sc in results:
                    self.cache[self.key(text)] = sc
                    fh.write(json.dumps({"setup": self.setup_key, "key": self.key(text), "score": sc}) + "\n")
            self.runs += len(todo) * self.runs_per_candidate
        return [self.cache.get(k) if k in self.seen else None for k in map(self.key, texts)]

    def map(self, fn, args: list) -> list:
        """``fn(setup, *a)`` for each ``a`` of ``args`` on the same workers (or Dask cluster) as
        the candidates, the results in completion order (``fn`` returns what orders them); not
        journaled, not counted against the budget (a step such as
        :func:`.installation.cross_fitted_score` that is deterministic and cheap to redo)."""
        from ..parallel import Progress
        return self._run(fn, [(self.setup, *a) for a in args], Progress(len(args), False, label="tune"))

    def _map(self, texts):
        return self._run(_evaluate_task, [(self.setup, t) for t in texts], self.bar)

    def _run(self, fn, tasks, bar):
        from concurrent.futures import ProcessPoolExecutor
        from ..parallel import dask_client, dask_map, pool_map
        if self.scheduler:
            if self._client is None:
                self._client = dask_client(self.scheduler.strip())
            return dask_map(self._client, fn, tasks, bar)
        n = self.workers or os.cpu_count() or 1
        if n <= 1 or len(tasks) == 1 and self._pool is None:
            out = []
            for t in tasks:
                out.append(fn(*t))
                bar.advance()
            return out
        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=n, initializer=_worker_init, initargs=(self.setup,))
        try:
            return pool_map(fn, tasks, n, bar, pool=self._pool)
        except BaseException:
            self._pool = None     # pool_map ended its workers
            raise

    def close(self) -> None:
        """End the workers (or the Dask connection) and the progress bar."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        if self._client is not None:
            self._client.close()
            self._client = None
        self.bar.close()
