"""pico_imu.allantools.oadev against allantools.oadev on the same data, one run.

Each library runs in a fresh process: it generates the same record (seeded; white noise plus a
rate random walk, rate samples), then times one oadev call at octave τ and reports the wall time
and the peak resident memory the call added above the process with the record in it (Linux
ru_maxrss, so it includes every temporary array or buffer, Rust's too). The two tables are
compared to 1e-9 relative.

    python python/bench/oadev.py [--samples 5000000] [--repeat 3]
"""
import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np


def record(n: int) -> np.ndarray:
    """Filled in chunks, so the process's peak before the call is the record itself."""
    rng = np.random.default_rng(20261127)
    y = np.empty(n)
    walk = 0.0
    for i in range(0, n, 1 << 16):
        k = min(1 << 16, n - i)
        w = walk + 1e-5 * np.cumsum(rng.normal(size=k))
        walk = w[-1]
        y[i:i + k] = rng.normal(0.0, 0.01, k) + w
    return y


def child(lib: str, n: int, repeat: int) -> None:
    y = record(n)
    if lib == "allantools":
        import allantools as m
    else:
        from pico_imu import allantools as m
    m.oadev(y[:1000], rate=1000.0, data_type="freq", taus="octave")  # import and warm-up
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = m.oadev(y, rate=1000.0, data_type="freq", taus="octave")
        times.append(time.perf_counter() - t)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(json.dumps({
        "lib": lib, "times_s": times, "added_peak_MiB": (peak - before) / 1024.0,
        "peak_MiB": peak / 1024.0, "record_MiB": y.nbytes / 2**20,
        "taus": out[0].tolist(), "devs": out[1].tolist(), "ns": out[3].tolist(),
    }))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", type=int, default=5_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--child")
    a = ap.parse_args()
    if a.child:
        child(a.child, a.samples, a.repeat)
        return
    res = {}
    for lib in ("allantools", "pico_imu"):
        out = subprocess.run([sys.executable, __file__, "--child", lib, "--samples", str(a.samples),
                              "--repeat", str(a.repeat)], check=True, capture_output=True, text=True)
        res[lib] = json.loads(out.stdout)
    at, pi = res["allantools"], res["pico_imu"]
    same = np.allclose(at["devs"], pi["devs"], rtol=1e-9, atol=0) and at["ns"] == pi["ns"]
    print(f"oadev, {a.samples} rate samples at 1 kHz, octave τ ({len(pi['taus'])} rows), "
          f"tables equal to 1e-9: {same}")
    for r in (at, pi):
        ts = sorted(r["times_s"])
        print(f"  {r['lib']:>10}: median {ts[len(ts) // 2]:.3f} s (min {ts[0]:.3f} s, max {ts[-1]:.3f} s"
              f" over {len(ts)}), peak memory added {r['added_peak_MiB']:.0f} MiB"
              f" (process peak {r['peak_MiB']:.0f} MiB with the {r['record_MiB']:.0f} MiB record)")
    ta = sorted(at["times_s"])[len(at["times_s"]) // 2]
    tp = sorted(pi["times_s"])[len(pi["times_s"]) // 2]
    print(f"  speed-up {ta / tp:.1f}×")


if __name__ == "__main__":
    main()
