"""Named random streams: reproducible, independent of each other and of order."""

import numpy as np
import pytest

from mixnav.sim.rng import Streams


def test_same_seed_and_name_same_numbers_whatever_the_order():
    a = Streams(5)
    x1 = a.get("imu").standard_normal(5)
    a.get("gnss").standard_normal(100)
    x2 = Streams(5).get("imu").standard_normal(5)
    np.testing.assert_array_equal(x1, x2)
    np.testing.assert_array_equal(x1, a.get("imu").standard_normal(5))


def test_streams_differ_and_are_uncorrelated():
    s = Streams(0)
    x = s.get("imu").standard_normal(20000)
    y = s.get("gnss").standard_normal(20000)
    z = Streams(1).get("imu").standard_normal(20000)
    # |corr| of independent normal samples: sd 1/sqrt(20000) = 0.007; 5 sd
    assert abs(np.corrcoef(x, y)[0, 1]) < 0.035
    assert abs(np.corrcoef(x, z)[0, 1]) < 0.035


@pytest.mark.parametrize("bad", [-1, 1.5, "3"])
def test_bad_seed(bad):
    with pytest.raises(ValueError, match="seed"):
        Streams(bad)
