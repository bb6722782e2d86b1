"""The GIL is released while the engine computes: another Python thread keeps running."""
import threading
import time

import numpy as np

import pico_imu
from pico_imu import allantools


def steps_per_second():
    """How fast the main thread's loop step runs alone."""
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < 0.1:
        n += 1
    return n / (time.perf_counter() - t0)


def python_share_during(call):
    """The share of `call`'s duration (run in a worker, 20 ms cut from either end) in which the
    main thread ran Python, in units of its solo loop rate; a held GIL allows about none (only
    the switch interval's 5 ms hand-offs at the ends). Also returns the call's duration."""
    rate = steps_per_second()
    started, done = threading.Event(), threading.Event()
    span = {}

    def worker():
        started.set()
        t0 = time.perf_counter()
        call()
        span["t"] = (t0, time.perf_counter())
        done.set()

    th = threading.Thread(target=worker)
    th.start()
    started.wait()
    n_loop, stamps = 0, []
    while not done.is_set():
        n_loop += 1
        stamps.append(time.perf_counter())
    th.join()
    t0, t1 = span["t"]
    window = (t1 - 0.02) - (t0 + 0.02)
    inside = sum(1 for s in stamps if t0 + 0.02 < s < t1 - 0.02)
    return inside / rate / window, t1 - t0


def test_python_runs_while_the_engine_computes(rng):
    y = rng.normal(size=8_000_000)
    counts = np.round(y * 100)
    stream = pico_imu.Stream(rate=1000.0)
    held, _ = python_share_during(lambda: sum(range(20_000_000)))  # a C loop that keeps the GIL
    for name, call in (
        ("allantools.mdev", lambda: allantools.mdev(y, rate=1000.0, data_type="freq", taus="decade")),
        ("deviation hdev", lambda: [pico_imu.deviation(y, rate=1000.0, stat="hdev") for _ in range(4)]),
        ("Stream.push", lambda: [stream.push(counts) for _ in range(2)]),
    ):
        share, took = python_share_during(call)
        assert took > 0.1, f"{name}: call too short to tell ({took:.3f} s)"
        assert share > max(0.15, 3 * held), (
            f"{name}: Python ran {share:.1%} of a {took:.3f} s call (GIL-holding C loop: {held:.1%})")
