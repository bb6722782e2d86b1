"""The bounded streaming engine fed chunk by chunk, against the batch engine."""
import numpy as np
import pytest

import pico_imu


def counts(rng, n):
    white = rng.uniform(20, 400)
    walk = white * rng.uniform(1e-3, 2e-2)
    y = rng.integers(-3000, 3000) + rng.normal(0, white, n) + walk * np.cumsum(rng.normal(size=n))
    return np.round(y)


def feed(y, rng, scale=1.0):
    s = pico_imu.Stream(rate=1000.0, scale=scale, unit="deg/s")
    i = 0
    while i < len(y):
        k = int(rng.integers(1, 5_000))
        s.push(y[i:i + k])
        i += k
    return s


@pytest.mark.parametrize("stat", ["oadev", "ohdev"])
def test_stream_equals_batch_where_both_are_exact_and_agrees_beyond(rng, stat):
    n = int(rng.integers(50_000, 200_000))
    y = counts(rng, n)
    scale = 1 / 131.0
    table = feed(y, rng, scale).table(stat)
    batch = pico_imu.deviation(y * scale, rate=1000.0, stat=stat, unit="deg/s")
    by_m = {int(m): k for k, m in enumerate(batch.m)}
    exact = table.stride == 1
    assert exact.sum() >= 4, table.m
    for k in range(len(table)):
        b = by_m.get(int(table.m[k]))
        if b is None:
            continue
        assert table.tau[k] == pytest.approx(batch.tau[b], rel=1e-12)
        if exact[k]:
            # the same estimator: equal to rounding (the engine's sums are integer-exact)
            assert table.dev[k] == pytest.approx(batch.dev[b], rel=1e-9), (stat, int(table.m[k]))
            assert table.n[k] == batch.n[b]
        else:
            # fewer differences (every stride samples): the same quantity within the
            # stride estimator's own 68.3 % bounds widened threefold
            width = max(table.hi[k] - table.dev[k], table.dev[k] - table.lo[k])
            assert abs(table.dev[k] - batch.dev[b]) < 3 * width + 3 * (batch.hi[b] - batch.lo[b]), (
                stat, int(table.m[k]), table.dev[k], batch.dev[b])


def test_chunking_changes_nothing(rng):
    y = counts(rng, 30_000)
    a = feed(y, rng).table("oadev")
    b = feed(y, rng).table("oadev")
    whole = pico_imu.Stream(rate=1000.0)
    whole.push(y)
    c = whole.table("oadev")
    np.testing.assert_array_equal(a.dev, b.dev)
    np.testing.assert_array_equal(a.dev, c.dev)
    np.testing.assert_array_equal(a.n, c.n)
    assert whole.samples == len(y)


def test_a_gap_keeps_differences_apart(rng):
    y = counts(rng, 20_000)
    s = pico_imu.Stream(rate=1000.0)
    s.push(y[:10_000])
    s.gap()
    s.push(y[10_000:] + 5_000)  # a bias jump at the gap, which no difference may see
    g = s.table("oadev")
    one = pico_imu.Stream(rate=1000.0)
    one.push(y[:10_000])
    two = pico_imu.Stream(rate=1000.0)
    two.push(y[10_000:])
    a, b = one.table("oadev"), two.table("oadev")
    assert s.gaps == 1 and s.samples == 20_000
    # at m = 1 the pooled variance is the term-weighted mean of the two segments'
    pooled = np.sqrt((a.dev[0] ** 2 * a.n[0] + b.dev[0] ** 2 * b.n[0]) / (a.n[0] + b.n[0]))
    assert g.dev[0] == pytest.approx(pooled, rel=1e-9)
    assert g.n[0] == a.n[0] + b.n[0]
