"""The demo's walk from Python: the noise lab's session on a recording's gyro column — the
five-term model of Jaime et al. fitted, diagnosed, the named effect added and refitted until the
model is adequate — the same Rust function `imu-lab fit --auto` runs, so the step table and
`Fit.to_dict()` are the CLI's.

    pip install './python[plot]'
    cargo xtask demo                                     # writes out/demo/recording.csv
    python docs/examples/fit_from_python.py out/demo/recording.csv gx [walk.png]

Without a file it makes a minute at 1 kHz of white noise seen through a one-pole low-pass filter
at 188 Hz (the emulated MPU-6050's), plus a rate random walk: the walk names the filter.
"""
import sys
import time

import numpy as np

import pico_imu


def main() -> None:
    if len(sys.argv) > 1:
        column = sys.argv[2] if len(sys.argv) > 2 else "gx"
        data = pico_imu.read_csv(sys.argv[1])
        kw = dict(column=column)
        print(f"{sys.argv[1]}: column {column}")
    else:
        rate, n = 1000.0, 60_000
        g = np.random.default_rng()
        a = np.exp(-2 * np.pi * 188.0 / rate)
        w = 0.02 * g.normal(size=n)
        y = np.empty(n)
        acc = 0.0
        for i in range(n):  # the one-pole filter y[i] = a·y[i−1] + (1 − a)·w[i]
            acc = a * acc + (1 - a) * w[i]
            y[i] = acc
        data = y + 2e-5 * np.cumsum(g.normal(size=n))
        kw = dict(rate=rate, unit="deg/s", column="gx")
        print(f"synthetic: {n} samples at {rate} Hz, white noise through a one-pole filter at 188 Hz")

    t = time.perf_counter()
    f = pico_imu.fit(data, auto=True, **kw)
    print(f"\n== Automatic walk (computed in {time.perf_counter() - t:.1f} s): diagnose → add the named effect → refit")
    print(f.steps_text())
    print(f"\n== Final model of {f.column} [{f.unit}], {f.samples} samples at {f.rate_hz:.6g} Hz")
    print(f.terms_text())
    print(f"Verdict: {f.verdict}")
    print(f"Diagnosis: {f.explanation}")
    if len(sys.argv) > 3:
        import matplotlib
        matplotlib.use("Agg")
        f.plot().savefig(sys.argv[3], dpi=120)
        print(f"wrote {sys.argv[3]}")


if __name__ == "__main__":
    main()
