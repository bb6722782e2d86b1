"""Shared test fixtures: a random generator whose seed is drawn per run and printed on failure."""
import os

import numpy as np
import pytest


@pytest.fixture
def rng(request):
    """A numpy generator with a fresh key each run (PICO_IMU_TEST_KEY=K replays one)."""
    key = int(os.environ.get("PICO_IMU_TEST_KEY", np.random.SeedSequence().entropy % 2**32))
    request.node.user_properties.append(("key", key))
    print(f"PICO_IMU_TEST_KEY={key}")
    return np.random.default_rng(key)


def noisy_record(rng, n):
    """Rate samples: white noise, a rate random walk and a constant offset, random amounts."""
    white = rng.uniform(0.005, 0.05)
    walk = white * rng.uniform(1e-4, 1e-2)
    return rng.uniform(-2, 2) + rng.normal(0.0, white, n) + walk * np.cumsum(rng.normal(size=n))
