import os
from pathlib import Path

import numpy as np
import pytest

#: Real data lives beside the project, never inside it (../shared/data).
DATA_DIR = Path(os.environ.get("MIXNAV_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


def data_file(*parts) -> Path:
    """Path of a real-data file; skips the test with a message when absent."""
    p = DATA_DIR.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"real data not found at {p} (set MIXNAV_DATA to the shared/data folder)")
    return p


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def reproducible(df):
    """An experiment's results without the wall-clock columns, in a canonical order."""
    from mixnav.experiment.montecarlo import TIMING_METRICS
    df = df.drop(columns=[c for c in TIMING_METRICS if c in df.columns])
    return df.sort_values(["seed", "method"]).reset_index(drop=True)
