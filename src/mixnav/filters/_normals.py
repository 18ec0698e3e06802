"""Standard normals drawn inside compiled kernels (numba, ``cache=True``).

numpy's ``Generator.standard_normal`` costs about 10 ns per draw on this machine
class (75,000 of them were half of a particle filter's resampling epoch); drawn
inside the kernel that consumes them, from an inlined 64-bit generator, a normal
costs a few ns. The stream of a kernel call starts from seeds the caller draws
from its own ``numpy.random.Generator`` (one per fixed chunk of work), so a run
stays reproducible from its seed and independent of the thread count.

- the uniform source: SplitMix64 (Steele, Lea and Flood 2014, "Fast splittable
  pseudorandom number generators"): a Weyl sequence with the golden-ratio
  increment, each state mixed by two xor-shift-multiply rounds;
- the normal: the ziggurat of Marsaglia and Tsang (2000, "The ziggurat method
  for generating random variables", J. Stat. Softw. 5(8)) with 256 layers of
  equal area, the sign and the layer from the low bits of one 64-bit draw, its
  top 52 bits the abscissa; the wedges by rejection, the tail beyond ``R`` by
  Marsaglia's exponential method. The layer table is built here from ``R``
  (:func:`ziggurat_tables`), not copied.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, uint64

#: right edge of the base layer of the 256-layer ziggurat (Marsaglia and Tsang 2000)
R = 3.6541528853610088
LAYERS = 256
_GOLDEN = uint64(0x9E3779B97F4A7C15)
_MIX1 = uint64(0xBF58476D1CE4E5B9)
_MIX2 = uint64(0x94D049BB133111EB)
_TWO52 = 2.0 ** 52


def ziggurat_tables(r: float = R, layers: int = LAYERS):
    """``(X, F, K, W)``: the layers' right edges ``X`` (layers + 1,: ``X[0] = v / f(r)``,
    the base layer's width as a rectangle of the common area ``v``; ``X[1] = r``; then
    ``X[i + 1] = f^-1(v / X[i] + f(X[i]))``; ``X[layers] = 0``), ``F = f(X)``
    (``f(x) = exp(-x^2 / 2)``), the integer acceptance bounds ``K[i] = floor(2^52 X[i + 1]
    / X[i])`` and the abscissa scales ``W = X / 2^52``."""
    def f(x):
        return math.exp(-0.5 * x * x)
    v = r * f(r) + math.sqrt(0.5 * math.pi) * math.erfc(r / math.sqrt(2.0))    # each layer's area
    X = np.empty(layers + 1)
    X[0], X[1] = v / f(r), r
    for i in range(1, layers - 1):
        X[i + 1] = math.sqrt(-2.0 * math.log(v / X[i] + f(X[i])))
    X[layers] = 0.0
    F = np.exp(-0.5 * X * X)
    K = np.array([int(_TWO52 * X[i + 1] / X[i]) for i in range(layers)], dtype=np.uint64)
    return X, F, K, X / _TWO52


_X, _F, _K, _W = ziggurat_tables()


@njit(cache=True, inline="always")
def _mix(z):
    """SplitMix64's output function of the Weyl state ``z``."""
    z = (z ^ (z >> uint64(30))) * _MIX1
    z = (z ^ (z >> uint64(27))) * _MIX2
    return z ^ (z >> uint64(31))


@njit(cache=True, inline="always")
def next_u64(state):
    """The next SplitMix64 output; ``state`` a (1,) uint64 array, advanced."""
    z = state[0] + _GOLDEN
    state[0] = z
    return _mix(z)


@njit(cache=True, inline="always")
def _uniform_open0(state):
    """A uniform in (0, 1] (53 bits)."""
    return (float(next_u64(state) >> uint64(11)) + 1.0) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def _normal_slow(state, u):
    """The draw ``u`` that fell outside its layer's inner rectangle: the tail (layer 0) or
    the wedge test; on a rejection, new draws until one is accepted."""
    while True:
        i = int(u & uint64(0xFF))
        neg = (u >> uint64(8)) & uint64(1)
        j = u >> uint64(12)
        x = float(j) * _W[i]
        if j < _K[i]:
            return -x if neg else x
        if i == 0:      # the tail beyond R (Marsaglia): x = R + e1 / R with 2 e2 > (e1 / R)^2
            while True:
                xt = -math.log(_uniform_open0(state)) / R
                yt = -math.log(_uniform_open0(state))
                if yt + yt > xt * xt:
                    return -(R + xt) if neg else R + xt
        y = _F[i] + _uniform_open0(state) * (_F[i + 1] - _F[i])
        if y < math.exp(-0.5 * x * x):
            return -x if neg else x
        u = next_u64(state)


@njit(cache=True)
def standard_normals_into(s, out, spill):
    """``out`` (1-D) filled with standard normals from the SplitMix64 stream at the state
    ``s`` (uint64); returns the advanced state. The loop is here, with the state a local
    (a register: twice as fast as a state kept in an array, or a per-draw helper
    returning it, measured); ``spill`` (1,) uint64 carries it through the rare slow
    path."""
    for t in range(out.shape[0]):
        s = s + _GOLDEN
        u = _mix(s)
        i = int(u & uint64(0xFF))
        j = u >> uint64(12)
        if j < _K[i]:       # inside the layer's inner rectangle: ~99 % of the draws
            x = float(j) * _W[i]
            out[t] = -x if (u >> uint64(8)) & uint64(1) else x
        else:
            spill[0] = s
            out[t] = _normal_slow(spill, u)
            s = spill[0]
    return s


@njit(cache=True)
def fill_standard_normal(seed, out):
    """``out`` (any shape, C-contiguous) filled with standard normals from the stream
    started at ``seed`` (uint64), in memory order (tests and benchmarks)."""
    standard_normals_into(uint64(seed), out.reshape(out.size), np.empty(1, dtype=np.uint64))
