"""One kernel body, two entry points (mixnav._jit.serial_and_parallel): numba's disk
cache must keep the serial and the parallel twin apart. Checked in fresh processes: the
first compiles and saves both, the second loads both from the cache and runs them; the
parallel twin must still spread its loop over two threads, the serial one must not."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import mixnav

SRC = str(Path(mixnav.__file__).resolve().parents[1])

KERNELS = textwrap.dedent('''
    import numba
    from numba import njit, prange

    from mixnav._jit import serial_and_parallel


    def _owner(out):
        for i in prange(out.shape[0]):
            out[i] = numba.get_thread_id()


    owners = serial_and_parallel(_owner, "owner")
    owner_serial, owner = owners


    def _outer(out):
        _inner(out)


    # the outer body is not parallel itself; each twin calls the matching inner twin
    outer_serial, outer = serial_and_parallel(_outer, "outer", calls={"_inner": owners},
                                              parallel=False)

    # what the factory avoids: one Python function compiled twice under one name
    naive_serial = njit(cache=True)(_owner)
    naive_parallel = njit(cache=True, parallel=True)(_owner)
''')

# numba.get_thread_id in serial machine code loaded from the cache needs the threading
# layer's symbols, which only a parallel call would load otherwise: load them first
PRELUDE = '''
from numba.np.ufunc.parallel import _launch_threads
_launch_threads()
'''

RUN = PRELUDE + textwrap.dedent('''
    import json
    import numpy as np
    import kernels_under_test as k

    out = {}
    for name in ("owner_serial", "owner", "outer_serial", "outer"):
        a = np.full(64, -1, dtype=np.int64)
        getattr(k, name)(a)
        out[name] = {"threads": sorted(set(a.tolist())), "hits": sum(getattr(k, name).stats.cache_hits.values())}
    print(json.dumps(out))
''')


def _run(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), NUMBA_NUM_THREADS="2",
               PYTHONPATH=os.pathsep.join([str(tmp_path), SRC]))
    res = subprocess.run([sys.executable, "-c", RUN], env=env, capture_output=True, text=True, timeout=600, check=False)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_twins_cached_apart_and_reloaded(tmp_path):
    (tmp_path / "kernels_under_test.py").write_text(KERNELS)
    first = _run(tmp_path)          # compiles and saves
    second = _run(tmp_path)         # a fresh process: loads both from the cache
    for run in (first, second):
        assert run["owner_serial"]["threads"] == [0]
        assert run["owner"]["threads"] == [0, 1]         # a static schedule: half the loop on thread 1
        assert run["outer_serial"]["threads"] == [0]     # calls the serial inner twin
        assert run["outer"]["threads"] == [0, 1]         # calls the parallel inner twin
    assert all(v["hits"] == 0 for v in first.values())
    assert all(v["hits"] == 1 for v in second.values())
    index = sorted(p.name.split("-")[0] for p in (tmp_path / "cache").rglob("*.nbi"))
    # one index file per twin, named by the twin (module.qualname-line...)
    assert index == ["kernels_under_test.outer", "kernels_under_test.outer_serial",
                     "kernels_under_test.owner", "kernels_under_test.owner_serial"]


def test_one_function_compiled_twice_shares_one_cache_entry(tmp_path):
    """Why the factory renames: numba keys a cache entry by signature and bytecode, not by
    ``parallel``, so the naive pair's parallel function loads the serial one's machine code
    from the cache the serial one has just written (and runs on one thread)."""
    (tmp_path / "kernels_under_test.py").write_text(KERNELS)
    script = PRELUDE + textwrap.dedent('''
        import json
        import numpy as np
        import kernels_under_test as k
        out = {}
        for name in ("naive_serial", "naive_parallel"):
            a = np.full(64, -1, dtype=np.int64)
            getattr(k, name)(a)
            out[name] = {"threads": sorted(set(a.tolist())), "hits": sum(getattr(k, name).stats.cache_hits.values())}
        print(json.dumps(out))
    ''')
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), NUMBA_NUM_THREADS="2",
               PYTHONPATH=os.pathsep.join([str(tmp_path), SRC]))
    res = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=600, check=False)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["naive_parallel"] == {"threads": [0], "hits": 1}
    assert len(list((tmp_path / "cache").rglob("*.nbi"))) == 1
