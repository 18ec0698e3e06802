"""One kernel body, two compiled entry points: :func:`serial_and_parallel`.

A kernel that loops over particles (or samples) with ``numba.prange`` is written
once; numba compiles it twice: without ``parallel`` (``prange`` is then ``range``:
the serial twin) and with ``parallel=True`` (the loop on numba's threads). Each
twin is compiled from its own copy of the Python function, under its own
``__qualname__`` (``name_serial`` and ``name``), because numba's disk cache
(``cache=True``) names its files by module, qualname and line and keys the
entries inside a file by signature and bytecode only, not by the ``parallel``
flag: one function compiled twice under one name would let the serial twin load
the parallel machine code from the cache, or the other way round
(tests/test_jit.py checks the cache files of both in fresh processes).
"""

from __future__ import annotations

import types
from collections.abc import Callable
from typing import NamedTuple

from numba import njit

__all__ = ["KernelPair", "serial_and_parallel"]


class KernelPair(NamedTuple):
    """The two compiled entry points of one kernel body."""

    serial: Callable
    parallel: Callable


def _renamed(py_func, name: str, global_names: dict | None):
    """A copy of ``py_func`` called ``name`` (its ``__name__`` and ``__qualname__``: the
    cache's file name); with ``global_names``, its globals are the module's at this
    moment with those names rebound (a twin calling the matching twin of a callee)."""
    glb = py_func.__globals__
    if global_names:
        glb = dict(glb)
        glb.update(global_names)
    fn = types.FunctionType(py_func.__code__, glb, name, py_func.__defaults__, py_func.__closure__)
    fn.__qualname__ = name
    fn.__doc__ = py_func.__doc__
    fn.__module__ = py_func.__module__
    fn.__kwdefaults__ = py_func.__kwdefaults__
    return fn


def serial_and_parallel(py_func, name: str | None = None, *, serial_name: str | None = None,
                        calls: dict | None = None, parallel: bool = True, **options) -> KernelPair:
    """Compile the body ``py_func`` (with ``cache=True`` and ``options``) into a serial
    twin named ``<name>_serial`` and a parallel twin named ``<name>`` (default: the
    body's own name).

    Parameters
    ----------
    py_func : function
        The kernel body; its per-item loop is a ``numba.prange``.
    name : str, optional
        The parallel twin's name.
    serial_name : str, optional
        The serial twin's name (default ``<name>_serial``).
    calls : dict, optional
        ``{global name: KernelPair}``: callees whose serial twin the serial twin
        calls and whose parallel twin the parallel twin calls (the body refers to
        the global name). The globals are then taken as they are at this call: the
        callees the body uses must be defined above it.
    parallel : bool
        Compile the parallel twin with ``parallel=True`` (default); False when the
        body has no ``prange`` of its own and only its ``calls`` differ.

    Notes
    -----
    A ``prange`` index is ``uint64`` in the parallel twin and ``int64`` in the serial one,
    so a kernel the body calls with it would compile once per type (measured: 0.5-2.8 s
    each on a cold cache); the bodies pass ``np.int64(index)``, one compile for both.
    """
    base = name or py_func.__name__
    ser = {k: v.serial for k, v in (calls or {}).items()}
    par = {k: v.parallel for k, v in (calls or {}).items()}
    options = {"cache": True, **options}
    serial = njit(**options)(_renamed(py_func, serial_name or base + "_serial", ser))
    par_options = dict(options, parallel=True) if parallel else options
    return KernelPair(serial, njit(**par_options)(_renamed(py_func, base, par)))
