"""The Allan part of the demo's walk, from Python: a recording's gyro column read through the
CSV contract, its overlapping Allan deviation with 68.3 % confidence bounds, the same through
the device's bounded streaming engine chunk by chunk, and the AllanTools-compatible call.

    pip install ./python
    cargo xtask demo                                     # writes out/demo/recording.csv
    python docs/examples/allan_from_python.py out/demo/recording.csv gx

Without a file it makes a minute of white noise plus a rate random walk at 1 kHz.
"""
import sys
import time

import numpy as np

import pico_imu
from pico_imu import allantools


def main() -> None:
    if len(sys.argv) > 1:
        column = sys.argv[2] if len(sys.argv) > 2 else "gx"
        rec = pico_imu.read_csv(sys.argv[1])
        y, rate, unit = rec[column], rec.rate_hz, rec.units.get(column, "")
        print(f"{sys.argv[1]}: {len(y)} samples of {column} [{unit}] at {rate:.3f} Hz, "
              f"{len(rec.segments)} segment(s); {rec.timing['summary'] if rec.timing else 'no t column'}")
    else:
        column, rate, unit = "gx", 1000.0, "deg/s"
        g = np.random.default_rng()
        y = 0.02 * g.normal(size=60_000) + 2e-5 * np.cumsum(g.normal(size=60_000))
        print(f"synthetic: {len(y)} samples of {column} [{unit}] at {rate} Hz")

    t = time.perf_counter()
    table = pico_imu.deviation(y, rate=rate, stat="oadev", unit=unit)
    print(f"\nOADEV with EDF and 68.3 % bounds ({time.perf_counter() - t:.3f} s):\n{table}")

    # The device's engine: whole counts (here the MPU-6050's 1/131 deg/s LSB), fed in chunks.
    lsb = 1 / 131.0
    stream = pico_imu.Stream(rate=rate, scale=lsb, unit=unit)
    counts = np.round(y / lsb)
    for start in range(0, len(counts), 4096):
        stream.push(counts[start:start + 4096])
    s = stream.table("oadev")
    print(f"\nStreaming engine, {stream.samples} samples in constant memory (stride = samples between differences):")
    for k in range(len(s)):
        print(f"  τ = {s.tau[k]:>10.4g} s  oadev = {s.dev[k]:.4g} {unit}  [{s.lo[k]:.4g}, {s.hi[k]:.4g}]  stride {int(s.stride[k])}")

    taus, devs, errs, ns = allantools.oadev(y, rate=rate, data_type="freq", taus="octave")
    print(f"\nAllanTools-compatible oadev: {len(taus)} rows; at τ = {taus[0]:g} s: "
          f"{devs[0]:.6g} ± {errs[0]:.2g} {unit} (n = {int(ns[0])})")


if __name__ == "__main__":
    main()
