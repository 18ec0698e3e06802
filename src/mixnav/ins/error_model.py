"""Named error-state layouts and the process noise they use.

A layout fixes which error states a filter carries and where; the filters
and measurement models address states by these names, never by bare
numbers. The state order inside each block is N, E, D for navigation errors
and x, y, z (body) for sensor errors; see :mod:`mixnav.ins._error_kernels`
for the dynamics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .imu_model import ImuErrorModel


@dataclass(frozen=True)
class StateBlock:
    """One named block of the error state.

    Attributes
    ----------
    name : str
        ``attitude``, ``velocity``, ``position``, ``gyro_bias``, ``accel_bias``,
        ``gyro_scale``, ``accel_scale``, ``clock`` (the blocks the INS kernels
        know), or any other name for an *auxiliary* block (odometer scale,
        mounting angles, a multipath bias...).
    size : int
    dynamics : str
        ``"ins"`` for the built-in blocks (their rows of F come from the
        error-state kernels, :mod:`mixnav.ins._error_kernels`); ``"random_walk"``
        for an auxiliary block (F rows zero, noise density ``walk ** 2``);
        ``"model"`` for a block of a non-INS motion model's core (dead
        reckoning, constant velocity: its own class gives F and Qd).
    feedback : str
        Where a correction of the block goes: ``"nav"`` (attitude, velocity,
        position of the nominal INS), ``"sensor"``, ``"clock"``, or ``"aux"``
        (the engine keeps an estimate vector per auxiliary block and adds the
        correction to it).
    sigma0 : float
        Initial 1-sigma of an auxiliary block [its unit].
    walk : float
        Random-walk density of an auxiliary block [its unit / sqrt(s)].
    labels : tuple of str
        One short label per state.
    """

    name: str
    size: int
    dynamics: str = "ins"
    feedback: str = "aux"
    sigma0: float = 0.0
    walk: float = 0.0
    labels: tuple = ()


def _ins_block(name, size, feedback, labels):
    return StateBlock(name, size, "ins", feedback, labels=tuple(labels))


#: The blocks the INS kernels know, in the order their offsets are passed to them.
INS_BLOCKS = {
    "attitude": _ins_block("attitude", 3, "nav", ["phi_n", "phi_e", "phi_d"]),
    "velocity": _ins_block("velocity", 3, "nav", ["dv_n", "dv_e", "dv_d"]),
    "position": _ins_block("position", 3, "nav", ["dr_n", "dr_e", "dr_d"]),
    "gyro_bias": _ins_block("gyro_bias", 3, "sensor", ["bg_x", "bg_y", "bg_z"]),
    "accel_bias": _ins_block("accel_bias", 3, "sensor", ["ba_x", "ba_y", "ba_z"]),
    "gyro_scale": _ins_block("gyro_scale", 3, "sensor", ["sg_x", "sg_y", "sg_z"]),
    "accel_scale": _ins_block("accel_scale", 3, "sensor", ["sa_x", "sa_y", "sa_z"]),
    "clock": _ins_block("clock", 2, "clock", ["clock_bias", "clock_drift"]),
}
_CORE = ("attitude", "velocity", "position", "gyro_bias", "accel_bias")


class StateLayout:
    """An error-state layout built from named blocks, compiled to an offset table.

    The first five blocks are always attitude, velocity, position, gyro bias
    and accelerometer bias (the 15-state core, at fixed offsets 0-14, which the
    kernels and measurement models rely on); any further blocks follow in the
    order given. Filters and measurement models address states by block
    (``layout.pos``, ``layout.slice("clock")``), never by bare numbers.

    A motion model other than the strapdown INS (:mod:`mixnav.motion`) gives its
    own ``core`` blocks instead: then ``att``, ``vel``, ``pos``, ``bg``, ``ba`` are
    the slices of the core blocks so named, or None where the core has no such
    block (measurement models address only the blocks that exist), and
    ``sensor_slots`` names what its entries of the engine's 12-element sensor
    vector hold (its recorded estimates).

    Parameters
    ----------
    name : str
    blocks : sequence of StateBlock or str
        The blocks after the core; a string names a built-in block
        (``"gyro_scale"``, ``"accel_scale"``, ``"clock"``).
    core : "ins" or sequence of StateBlock
        The INS core (default) or a motion model's own core blocks
        (``dynamics = "model"``), which must include ``position``.
    sensor_slots : dict, optional
        Non-INS core only: estimate name -> slice of the sensor vector.

    Attributes
    ----------
    n : int
        Number of states.
    sg, sa, clk : int
        First index of the gyro/accelerometer scale-factor blocks and of the
        clock block (bias [m], drift [m/s]); -1 when absent.
    offsets : dict
        Block name -> first index.
    """

    att = slice(0, 3)
    vel = slice(3, 6)
    pos = slice(6, 9)
    bg = slice(9, 12)
    ba = slice(12, 15)

    def __init__(self, name: str, blocks=(), core="ins", sensor_slots=None):
        from ..errors import ArgumentError
        self.is_ins = isinstance(core, str) and core == "ins"
        if self.is_ins:
            full = [INS_BLOCKS[b] for b in _CORE]
        else:
            full = list(core)
            if not all(isinstance(b, StateBlock) and b.dynamics == "model" for b in full):
                raise ArgumentError("a motion model's core blocks must be StateBlocks with dynamics 'model'",
                                    argument="core")
            if "position" not in [b.name for b in full]:
                raise ArgumentError("a motion model's core must have a 'position' block (NED metres)",
                                    argument="core")
        for b in blocks:
            if isinstance(b, str):
                if b not in INS_BLOCKS:
                    raise ArgumentError(f"unknown built-in block '{b}' (known: {', '.join(INS_BLOCKS)}); "
                                        "give a StateBlock for an auxiliary one", argument="blocks")
                b = INS_BLOCKS[b]
            if b.dynamics == "ins" and b.name not in INS_BLOCKS:
                raise ArgumentError(f"block '{b.name}' has INS dynamics but the kernels do not know it",
                                    argument="blocks")
            if b.dynamics == "ins" and not self.is_ins and b.name != "clock":
                raise ArgumentError(f"block '{b.name}' needs the INS core", argument="blocks")
            if b.dynamics not in ("ins", "random_walk") or b.feedback not in ("nav", "sensor", "clock", "aux"):
                raise ArgumentError(f"block '{b.name}': dynamics must be 'ins' or 'random_walk' and "
                                    "feedback one of nav, sensor, clock, aux", argument="blocks")
            if b.dynamics == "random_walk" and b.feedback != "aux":
                raise ArgumentError(f"auxiliary block '{b.name}' must have feedback 'aux'", argument="blocks")
            if int(b.size) < 1:
                raise ArgumentError(f"block '{b.name}' must have at least one state", argument="blocks")
            full.append(b)
        names = [b.name for b in full]
        if len(set(names)) != len(names):
            raise ArgumentError(f"block names must be unique, got {names}", argument="blocks")
        self.name = name
        self.blocks = tuple(full)
        self.offsets = {}
        k = 0
        for b in full:
            self.offsets[b.name] = k
            k += int(b.size)
        self.n = k
        self.sg = self.offsets.get("gyro_scale", -1)
        self.sa = self.offsets.get("accel_scale", -1)
        self.clk = self.offsets.get("clock", -1)
        if (self.sg >= 0) != (self.sa >= 0):
            raise ArgumentError("gyro_scale and accel_scale go together (the kernels carry both)",
                                argument="blocks")
        #: auxiliary blocks: (name, slice) of the states the engine keeps estimates of
        self.aux = tuple((b.name, self.slice(b.name)) for b in full if b.feedback == "aux"
                         and b.dynamics != "model")
        if self.is_ins:
            self._array = np.array([self.n, 9, 12, self.sg, self.sa, self.clk], dtype=np.int64)
            self.sensor_slots = {"gyro_bias": slice(0, 3), "accel_bias": slice(3, 6)}
            if self.sg >= 0:
                self.sensor_slots.update(gyro_scale=slice(6, 9), accel_scale=slice(9, 12))
        else:
            self._array = None
            for attr, block in (("att", "attitude"), ("vel", "velocity"), ("pos", "position"),
                                ("bg", "gyro_bias"), ("ba", "accel_bias")):
                setattr(self, attr, self.slice(block) if block in self.offsets else None)
            self.sensor_slots = dict(sensor_slots or {})

    def sensor_estimates(self, sensor: np.ndarray) -> dict:
        """The named estimates held in the engine's sensor vectors ``sensor`` (K, 12)."""
        return {name: sensor[:, sl] for name, sl in self.sensor_slots.items()}

    def slice(self, block: str) -> slice:
        """The states of a block."""
        o = self.offsets[block]
        return slice(o, o + self.block(block).size)

    def block(self, name: str) -> StateBlock:
        for b in self.blocks:
            if b.name == name:
                return b
        raise KeyError(name)

    def has(self, name: str) -> bool:
        return name in self.offsets

    def as_array(self) -> np.ndarray:
        """``[n, i_bg, i_ba, i_sg, i_sa, i_clk]`` for the compiled INS kernels (a copy)."""
        if self._array is None:
            from ..errors import ArgumentError
            raise ArgumentError(f"layout {self.name!r} is not an INS layout: this needs the strapdown INS "
                                "(its kernels)", argument="layout")
        return self._array.copy()

    def labels(self) -> list[str]:
        """One short label per state, in order (for tables and plots)."""
        lab = []
        for b in self.blocks:
            lab += list(b.labels) if b.labels else [f"{b.name}_{i}" for i in range(b.size)]
        return lab

    def __eq__(self, other):
        return isinstance(other, StateLayout) and self.blocks == other.blocks and self.is_ins == other.is_ins

    def __hash__(self):
        return hash((self.blocks, self.is_ins))

    def __repr__(self):
        return f"StateLayout({self.name!r}, n={self.n}, blocks={[b.name for b in self.blocks]})"


LAYOUTS: dict[int, StateLayout] = {
    15: StateLayout("ins15"),
    17: StateLayout("ins15+clock", ["clock"]),
    21: StateLayout("ins15+scale", ["gyro_scale", "accel_scale"]),
    23: StateLayout("ins15+scale+clock", ["gyro_scale", "accel_scale", "clock"]),
}


def get_layout(n_states: int) -> StateLayout:
    """The layout with ``n_states`` states (15, 17, 21 or 23)."""
    from ..errors import ArgumentError
    try:
        return LAYOUTS[int(n_states)]
    except (KeyError, ValueError, TypeError):
        raise ArgumentError(f"no error-state layout with {n_states!r} states; choose one of "
                            f"{sorted(LAYOUTS)}", argument="states") from None


@dataclass(frozen=True)
class ClockModel:
    """Two-state receiver clock: white frequency and random-walk frequency noise.

    ``q_bias`` [m^2/s] drives the bias, ``q_drift`` [m^2/s^3] the drift.
    """

    q_bias: float = 0.1
    q_drift: float = 0.01


def body_noise(imu: ImuErrorModel) -> np.ndarray:
    """Per-body-axis white-noise densities ``[arw_x^2, arw_y^2, arw_z^2, vrw_x^2, vrw_y^2, vrw_z^2]``.

    Non-zero only when ARW or VRW differ between the axes. The navigation-frame
    density is then ``Qc_att = C_nb diag(arw_b^2) C_bn`` (``Qc_vel`` alike with
    VRW), which is not diagonal; the compiled propagation adds it
    (:func:`mixnav.ins._error_kernels.propagate_block`). When ARW and VRW
    are the same on every axis ``C diag(q) C^T = q I`` and the diagonal
    ``qc`` of :func:`process_noise` carries them, bit for bit as before.

    Returns
    -------
    ndarray (6,)
        [rad^2/s] x 3, [m^2/s^3] x 3; all zero for isotropic white noise.
    """
    if not (imu.is_per_axis("arw") or imu.is_per_axis("vrw")):
        return np.zeros(6)
    return np.concatenate([imu.axes("arw") ** 2, imu.axes("vrw") ** 2])


def process_noise(layout: StateLayout, imu: ImuErrorModel, clock: ClockModel | None = None):
    """Continuous noise density ``qc`` (diagonal), correlation times, and P0 of sensor states.

    Returns
    -------
    qc : ndarray (n,)
        Spectral densities: ARW^2 and VRW^2 on the attitude and velocity
        errors (zero there when the white noise is per body axis: then
        :func:`body_noise` carries it); ``2 sigma^2 / tau + walk^2`` on the biases (Gauss-Markov
        plus random walk); zero on the scale factors (constants); the clock
        densities.
    tau : ndarray (4,)
        Correlation times of bg, ba, sg, sa [s].
    sensor_sigma0 : ndarray (n,)
        Initial 1-sigma of the sensor-error states (zero elsewhere): turn-on
        bias and in-run instability combined; scale-factor sigma.
    """
    n = layout.n
    qc = np.zeros(n)
    s0 = np.zeros(n)
    # white noise given per body axis lives in body_noise (rotated into the n-frame by the kernel)
    qb = body_noise(imu)
    if not qb.any():
        qc[layout.att] = np.asarray(imu.arw) ** 2
        qc[layout.vel] = np.asarray(imu.vrw) ** 2
    gm = lambda s, t: 2.0 * s * s / t if np.isfinite(t) else 0.0  # noqa: E731
    # the biases are body-frame states: a per-axis walk is simply per state
    qc[layout.bg] = gm(imu.gyro_bias_instability, imu.gyro_bias_tau) + np.asarray(imu.gyro_bias_walk) ** 2
    qc[layout.ba] = gm(imu.accel_bias_instability, imu.accel_bias_tau) + np.asarray(imu.accel_bias_walk) ** 2
    s0[layout.bg] = np.hypot(imu.gyro_bias, imu.gyro_bias_instability)
    s0[layout.ba] = np.hypot(imu.accel_bias, imu.accel_bias_instability)
    tau = np.array([imu.gyro_bias_tau if imu.gyro_bias_instability > 0 else np.inf,
                    imu.accel_bias_tau if imu.accel_bias_instability > 0 else np.inf,
                    np.inf, np.inf])
    if layout.sg >= 0:
        s0[layout.sg:layout.sg + 3] = imu.gyro_scale
        s0[layout.sa:layout.sa + 3] = imu.accel_scale
    for name, sl in layout.aux:  # auxiliary blocks: random walks
        b = layout.block(name)
        qc[sl] = b.walk ** 2
        s0[sl] = b.sigma0
    if layout.clk >= 0:
        clock = clock or ClockModel()
        qc[layout.clk] = clock.q_bias
        qc[layout.clk + 1] = clock.q_drift
    return qc, tau, s0
