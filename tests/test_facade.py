"""The generic facade: every public filter is a ``Filter`` (a registered name or a factory)."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import numpy as np
import pytest

import mixnav.filters
from mixnav.config.loader import load_scenario
from mixnav.errors import ArgumentError
from mixnav.experiment import methods as registry
from mixnav.filters.colored import ColoredMixtureEkf
from mixnav.filters.ekf import ErrorStateEkf, KalmanEstimator
from mixnav.filters.facade import Filter
from mixnav.filters.gmekf import BankEstimator, BankMixtures, GaussianMixtureEkf
from mixnav.filters.imm import ImmEkf, ImmEstimator
from mixnav.ins.error_model import ClockModel
from mixnav.sim.scenario import simulate


def test_no_filter_class_subclasses_the_plain_ekf_but_the_generic_facade():
    """The twelve per-estimator subclasses are gone: only ``Filter`` extends ``ErrorStateEkf``."""
    found = set()
    for info in pkgutil.iter_modules(mixnav.filters.__path__, "mixnav.filters."):
        module = importlib.import_module(info.name)
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if issubclass(cls, ErrorStateEkf) and cls is not ErrorStateEkf and cls.__module__.startswith("mixnav."):
                found.add(f"{cls.__module__}.{cls.__qualname__}")
    assert found == {"mixnav.filters.facade.Filter"}


def _tight_demo():
    sc, src, _ = load_scenario("tight-demo")
    sim = simulate(sc, 3, src)
    s = sc.gnss.satellites
    clock = ClockModel(q_bias=s.clock_bias_noise ** 2, q_drift=s.clock_drift_noise ** 2)
    ekf, meas = registry.build(sc.methods[0], sim.imu_model, sim.fixes, np.asarray(sc.gnss.lever_arm), src, 0,
                               observations=sim.observations, clock=clock)
    return sim, clock, ekf, meas


def test_a_factory_makes_a_fresh_estimator_per_run_and_reports_its_learning():
    """A factory of the plain Kalman estimator gives the EKF's numbers bitwise; each run gets its
    own estimator; the learning time and unconverged fits reach the result."""
    sim, clock, ekf, meas = _tight_demo()
    made = []

    def factory():
        made.append(KalmanEstimator(ekf.absurd_sigma))
        return made[-1]
    f = Filter(factory, ekf.layout, ekf.imu_model, clock=clock, name="mine", learning_time_s=1.5,
               learner_not_converged=2, attributes={"note": "kept"})
    assert len(made) == 1 and f.estimator is None and f.note == "kept" and f.name == "mine"
    r0 = ekf.run(sim.imu, sim.init, meas)
    r1 = f.run(sim.imu, sim.init, meas)
    assert f.estimator is made[-1] and len(made) == 2
    f.run(sim.imu, sim.init, meas)
    assert len(made) == 3 and made[1] is not made[2]
    np.testing.assert_array_equal(r1.nav, r0.nav)
    assert r1.timing["learning_time_s"] == 1.5 and r1.recoveries["learner_not_converged"] == 2
    assert "learning_time_s" not in r0.timing and f.online_learner is None


def test_a_factory_takes_no_options_and_a_name_no_alias():
    sim, clock, ekf, _ = _tight_demo()
    with pytest.raises(ArgumentError) as e:
        Filter(KalmanEstimator, ekf.layout, ekf.imu_model, {"gate": 3.0})
    assert e.value.argument == "options"
    with pytest.raises(ArgumentError) as e:
        Filter("ekf", ekf.layout, ekf.imu_model, name="other")
    assert e.value.argument == "name"


def test_the_object_built_filters_are_the_generic_facade():
    """The mixture bank, the coloured bank and the IMM: a ``Filter`` with their estimator, their
    smoothing flag and what callers read."""
    sim, clock, ekf, meas = _tight_demo()
    mix = BankMixtures()
    g = GaussianMixtureEkf(ekf.layout, ekf.imu_model, mix, max_components=4, learning_time_s=0.25)
    c = ColoredMixtureEkf(ekf.layout, ekf.imu_model, mix, psi_process=0.5, psi_measurement={"pseudorange": 0.2})
    m = ImmEkf(ekf.layout, ekf.imu_model, [meas, meas], [[0.9, 0.1], [0.1, 0.9]])
    for f, cls, smooth in ((g, BankEstimator, True), (c, BankEstimator, False), (m, ImmEstimator, False)):
        assert type(f) is Filter and isinstance(f.make_estimator(), cls) and f.can_smooth is smooth
    assert g.mixtures is mix and g.max_components == 4 and g.learning_time_s == 0.25
    assert c.augment and c.psi_process.shape == (9,) and c.psi_measurement[0] == 0.2
    assert m.learning_time_s is None and len(m.measurement_sets) == 2
    with pytest.raises(ArgumentError) as e:
        ColoredMixtureEkf(ekf.layout, ekf.imu_model, mix, psi_process=1.0)
    assert e.value.argument == "psi_process"
