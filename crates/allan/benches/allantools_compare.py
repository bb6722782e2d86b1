"""Time AllanTools' oadev on the same file as examples/oadev_file.rs (docs/benchmarks.md).

Run in a throwaway venv with `pip install allantools==2024.06`; the project's tests never need it.
usage: python allantools_compare.py FILE RATE_HZ
"""
import sys, time
import numpy as np
import allantools

y = np.fromfile(sys.argv[1], dtype='<f8')
rate = float(sys.argv[2])
t = time.perf_counter()
taus, devs, errs, ns = allantools.oadev(y, rate=rate, data_type='freq', taus='octave')
print(f"{len(y)} samples, {len(taus)} rows in {time.perf_counter() - t:.3f} s", file=sys.stderr)
for a, d, n in zip(taus, devs, ns):
    print(f"{a:.6e} {d:.10e} {n}")
