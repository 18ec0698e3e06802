"""Running tasks on local worker processes or a Dask cluster: what the Monte Carlo runner
(:mod:`mixnav.experiment.montecarlo`) and the sweeps (:mod:`mixnav.experiment.sweep`) share.

- :func:`die_with_parent`: a pool worker's initializer ends it with its parent (also ``kill -9``);
- :class:`Progress`: a rich progress bar on a terminal, else a plain line every few tasks;
- :func:`terminate_pool`: end a process pool's workers now (an interrupted command leaves none);
- :func:`dask_client`: a connected ``distributed.Client`` or a ConfigError saying why not;
- :func:`pool_map`, :func:`dask_map`: ``fn(*task)`` for every task on a process pool or a Dask
  cluster, the results in completion order, the progress bar advanced per task.
"""

from __future__ import annotations

import os
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

from ..errors import ConfigError


def die_with_parent() -> None:
    """End this worker when its parent ends, however it ends (also ``kill -9``).

    Linux: ``PR_SET_PDEATHSIG`` sends SIGKILL at the parent's death; elsewhere
    (and as a second line) a daemon thread checks the parent every second.
    Ctrl-C goes to the whole process group: the worker ignores it and leaves
    the clean-up to the parent, which terminates its workers. SIGTERM (the
    parent's ``terminate``) ends the worker at once: a forked worker would
    otherwise inherit the command's handler, turn it into an exception of its
    task and go on to the next one until killed.
    """
    import signal
    import threading
    parent = os.getppid()
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    except ValueError:  # not the main thread
        pass
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:  # the parent died before the signal was armed
        os._exit(1)

    def watch():
        while True:
            time.sleep(1.0)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="mixnav-parent-watch", daemon=True).start()



class Progress:
    """rich progress bar on a terminal, else a plain line every few runs (stderr)."""

    def __init__(self, total: int, enabled: bool, label: str = "runs"):
        self.total, self.done, self.t0, self.label = total, 0, time.perf_counter(), label
        self.enabled = enabled and total > 0
        self.step = max(1, min(10, total // 20))
        self.bar = None
        if self.enabled and sys.stderr.isatty():
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                       TimeElapsedColumn, TimeRemainingColumn)
            from rich.console import Console
            self.bar = Progress(TextColumn(label), BarColumn(), MofNCompleteColumn(),
                                TextColumn("{task.fields[rate]}"),
                                TimeElapsedColumn(), TimeRemainingColumn(),
                                console=Console(stderr=True))
            self.bar.start()
            self.task = self.bar.add_task(label, total=total, rate="")

    def advance(self) -> None:
        self.done += 1
        if not self.enabled:
            return
        if self.bar is not None:
            dt = time.perf_counter() - self.t0
            self.bar.update(self.task, advance=1,
                            rate=f"{self.done / dt:.2f} {self.label}/s" if dt > 0 else "")
        elif self.done % self.step == 0 or self.done == self.total:
            dt = time.perf_counter() - self.t0
            rate = self.done / dt if dt > 0 else float("inf")
            eta = (self.total - self.done) / rate if rate > 0 else float("nan")
            print(f"{self.label} done {self.done}/{self.total}, {rate:.1f} {self.label}/s, eta {eta:.0f} s",
                  file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()



def terminate_pool(pool: ProcessPoolExecutor, timeout: float = 5.0) -> list[int]:
    """End the pool's workers now (SIGTERM, then SIGKILL after ``timeout`` s in all); the
    pids of those that have ended."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.terminate()
    deadline = time.monotonic() + timeout
    for p in procs:
        p.join(timeout=max(deadline - time.monotonic(), 0.0))
    for p in procs:
        if p.is_alive():
            p.kill()
            p.join(timeout=timeout)
    return [p.pid for p in procs if not p.is_alive()]


#: Seconds to wait for a Dask scheduler to answer.
DASK_CONNECT_TIMEOUT_S = 5.0
#: Seconds to wait for a reachable scheduler to have at least one worker.
DASK_WORKER_WAIT_S = 60.0


def dask_client(address: str):
    """A ``distributed.Client`` connected to ``address``, or a ConfigError."""
    try:
        import distributed
    except ImportError:
        raise ConfigError("running on a Dask scheduler needs the 'distributed' package: "
                          'pip install "mixnav[dask]"') from None
    try:
        client = distributed.Client(address, timeout=DASK_CONNECT_TIMEOUT_S,
                                    set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:  # refused, timed out, bad address
        raise ConfigError(f"cannot connect to the Dask scheduler at {address} within "
                          f"{DASK_CONNECT_TIMEOUT_S:g} s ({type(exc).__name__}: {exc}); is it "
                          "running and is the address right?") from None
    try:
        client.wait_for_workers(1, timeout=DASK_WORKER_WAIT_S)
    except (OSError, TimeoutError) as exc:
        client.close()
        raise ConfigError(f"the Dask scheduler at {address} has no worker after "
                          f"{DASK_WORKER_WAIT_S:g} s ({exc})") from None
    except BaseException:
        client.close()
        raise
    return client


def pool_map(fn, tasks, workers: int, bar: Progress, initializer=None, initargs=(), terminate=terminate_pool,
             on_abort=None, pool: ProcessPoolExecutor | None = None) -> list:
    """``fn(*task)`` for every task on a pool of ``workers`` processes (each started by
    ``initializer(*initargs)``): the results in completion order. A task's error or an
    interruption ends the running workers now (``terminate(pool)``, which returns the pids
    that ended; a task can take minutes and no worker outlives the command), then
    ``on_abort(pids)`` cleans up after them, and the error is raised. ``pool``: a pool the
    caller keeps across calls (its workers keep what they loaded; the caller shuts it down),
    instead of one made and shut down here."""
    own = pool is None
    if own:
        pool = ProcessPoolExecutor(max_workers=workers, initializer=initializer, initargs=initargs)
    out: list = []
    try:
        pending = {pool.submit(fn, *task) for task in tasks}
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in done:
                out.append(f.result())  # re-raises a worker's error
                bar.advance()
    except BaseException:
        ended = terminate(pool)
        if on_abort is not None:
            on_abort(ended)
        raise
    if own:
        pool.shutdown(wait=True)
    return out


def dask_map(client, fn, tasks, bar: Progress, keys=None) -> list:
    """``fn(*task)`` for every task on a Dask cluster (``keys``: the tasks' keys, else Dask's):
    the results in completion order; an error or interruption cancels the rest."""
    from distributed import as_completed
    futures = [client.submit(fn, *task, pure=False, **({} if keys is None else {"key": keys[i]}))
               for i, task in enumerate(tasks)]
    out: list = []
    try:
        for f in as_completed(futures, loop=client.loop):
            out.append(f.result())  # re-raises a worker's error
            bar.advance()
    except BaseException:
        client.cancel(futures)
        raise
    finally:
        for f in futures:
            f.release()
    return out

