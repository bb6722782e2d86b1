"""pico_imu.allantools against AllanTools itself on generated data: the seven statistics, every
`taus` form, both data types; taus, devs, errs and ns equal to 1e-9 relative."""
import allantools as reference
import numpy as np
import pytest

from pico_imu import allantools as ours

from conftest import noisy_record

STATS = ["adev", "oadev", "mdev", "hdev", "ohdev", "tdev", "totdev"]


def same(a, b, what):
    names = ("taus", "devs", "errs", "ns")
    for k in range(4):
        assert len(a[k]) == len(b[k]), f"{what}: {names[k]} lengths {len(a[k])} vs {len(b[k])}"
        np.testing.assert_allclose(b[k], a[k], rtol=1e-9, atol=0, err_msg=f"{what}: {names[k]}")


@pytest.mark.parametrize("stat", STATS)
@pytest.mark.parametrize("data_type", ["freq", "phase"])
@pytest.mark.parametrize("taus", ["octave", "decade", "log10", None, "array"])
def test_equal_to_allantools(rng, stat, data_type, taus):
    n = int(rng.integers(2_000, 30_000))
    rate = float(rng.choice([1.0, 100.0, 1000.0, rng.uniform(10, 500)]))
    y = noisy_record(rng, n)
    data = y if data_type == "freq" else np.cumsum(y) / rate  # phase in s
    if taus == "array":
        # τ in s, unsorted, with duplicates after rounding and values out of range both ends
        taus = np.concatenate([rng.uniform(0.0, 2 * n / rate, 12), [0.2 / rate, 1 / rate, 1 / rate, 10 * n / rate]])
    a = getattr(reference, stat)(data, rate=rate, data_type=data_type, taus=taus)
    b = getattr(ours, stat)(data, rate=rate, data_type=data_type, taus=taus)
    same(a, b, f"{stat} {data_type} taus={taus if isinstance(taus, str) else 'array'} n={n} rate={rate}")


@pytest.mark.parametrize("stat", STATS)
def test_equal_to_allantools_all_taus(rng, stat):
    n = int(rng.integers(300, 1_500))
    y = noisy_record(rng, n)
    a = getattr(reference, stat)(y, rate=10.0, data_type="freq", taus="all")
    b = getattr(ours, stat)(y, rate=10.0, data_type="freq", taus="all")
    same(a, b, f"{stat} all n={n}")


def test_defaults_are_allantools_defaults(rng):
    x = np.cumsum(noisy_record(rng, 5_000))
    same(reference.oadev(x), ours.oadev(x), "oadev(x)")
    same(reference.totdev(list(x[:600])), ours.totdev(list(x[:600])), "totdev(list)")
