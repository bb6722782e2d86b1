"""AllanTools-compatible deviations computed by pico-imu's Allan engine.

A drop-in for the seven statistics of the AllanTools package: change ``import allantools`` to
``from pico_imu import allantools`` and every call below keeps its signature, its defaults and
its result, ``(taus_used, devs, errs, ns)``, equal to AllanTools to rounding:

* ``data``: phase in s (``data_type="phase"``, the default, as in AllanTools) or rate samples
  (``data_type="freq"``: fractional frequency, or any rate such as deg/s; the mean is removed
  and the samples integrated to phase, N samples giving N + 1 phase points).
* ``rate``: the sample rate in Hz.
* ``taus``: ``"octave"`` (default), ``"decade"``, ``"all"``, ``"log10"``, or an array of τ in s,
  each rounded to the nearest whole number of samples m; m outside 1 … N − 1 (N phase points)
  are dropped and duplicates removed.
* Returned: ``taus_used`` (s), ``devs`` (the data's rate unit; TDEV: s for phase data, rate
  unit × s for rate data), ``errs`` = devs/√ns (AllanTools' simple error bar, same unit), and
  ``ns`` (terms in the sum, as floats as in AllanTools). Rows with ns ≤ 1 are dropped.

Differences from AllanTools: the work runs in Rust on all cores with the GIL released; a NaN
or infinite sample raises ``ValueError`` naming its index instead of being trimmed or
propagated; an unknown ``data_type`` or a non-positive ``rate`` raises ``ValueError``. For
confidence intervals from the equivalent degrees of freedom use :func:`pico_imu.deviation`.
"""
from __future__ import annotations

import numpy as np

from . import _native

__all__ = ["adev", "oadev", "mdev", "hdev", "ohdev", "tdev", "totdev", "tau_ms"]


def _as_data(data) -> np.ndarray:
    a = np.ascontiguousarray(np.asarray(data, dtype=np.float64))
    if a.ndim != 1:
        raise ValueError(f"data: expected a 1-D array of samples, got shape {a.shape}")
    return a


def tau_ms(n_phase: int, rate: float, taus="octave") -> np.ndarray:
    """The averaging factors m (whole samples) AllanTools uses for ``taus`` on a record of
    ``n_phase`` phase points sampled at ``rate`` Hz: sorted, unique, 1 ≤ m < n_phase."""
    if isinstance(rate, (str, bytes)) or not np.isscalar(rate) or not np.isreal(rate):
        raise TypeError(f"rate={rate!r}: the sample rate must be a number of Hz")
    if not (rate > 0 and np.isfinite(rate)):
        raise ValueError(f"rate={rate}: the sample rate must be a positive finite number of Hz")
    if taus is None or (isinstance(taus, list) and len(taus) == 0):
        taus = "octave"
    tau0 = 1.0 / rate
    if isinstance(taus, str):
        n = n_phase
        if taus == "all":
            values = np.linspace(1.0, n, n)
        elif taus == "octave":
            k = int(np.floor(np.log2(n)))
            values = np.logspace(0, k, k + 1, base=2.0)
        elif taus == "log10":
            top = np.log10(n)
            values = np.logspace(0, top, int(10 * top), base=10.0)
        elif taus == "decade":
            k = int(np.floor(np.log10(n)))
            values = np.array([c * 10.0**j for j in range(k + 1) for c in (1.0, 2.0, 4.0)])
        else:
            raise ValueError(
                f"taus={taus!r}: expected \"octave\", \"decade\", \"all\", \"log10\" or an array of τ in s"
            )
        taus = tau0 * values
    t = np.asarray(taus, dtype=np.float64).ravel()
    if not np.all(np.isfinite(t)):
        bad = int(np.flatnonzero(~np.isfinite(t))[0])
        raise ValueError(f"taus[{bad}] is not a finite number of s")
    m = np.round(t * rate)
    m = np.unique(m[(m > 0) & (m < n_phase)])
    return m.astype(np.uint64)


def _compat(stat: str, data, rate: float, data_type: str, taus):
    if data_type not in ("phase", "freq"):
        raise ValueError(f"data_type={data_type!r}: expected \"phase\" (s) or \"freq\" (rate samples)")
    x = _as_data(data)
    if len(x) < 3:
        raise ValueError(f"data has {len(x)} samples, at least 3 are needed")
    n_phase = len(x) + 1 if data_type == "freq" else len(x)
    ms = tau_ms(n_phase, rate, taus)
    if len(ms) == 0:
        raise ValueError(f"taus={taus!r}: no τ between 1 and {n_phase - 1} samples at rate={rate} Hz")
    devs, ns = _native.plain_deviations(x, float(rate), stat, data_type, [int(m) for m in ms])
    keep = ns > 1
    ms, devs, ns = ms[keep], devs[keep], ns[keep].astype(np.float64)
    if len(ms) == 0:
        raise ValueError(f"{stat}: no τ has at least 2 terms in a record of {len(x)} samples")
    taus_used = ms.astype(np.float64) / float(rate)
    return taus_used, devs, devs / np.sqrt(ns), ns


def adev(data, rate=1.0, data_type="phase", taus=None):
    """Allan deviation (non-overlapping; NIST SP 1065 eq. 7). Returns (taus_used s, devs, errs,
    ns); devs in the data's rate unit (fractional frequency for phase in s)."""
    return _compat("adev", data, rate, data_type, taus)


def oadev(data, rate=1.0, data_type="phase", taus=None):
    """Overlapping Allan deviation (NIST SP 1065 eq. 11). Returns (taus_used s, devs, errs,
    ns); devs in the data's rate unit."""
    return _compat("oadev", data, rate, data_type, taus)


def mdev(data, rate=1.0, data_type="phase", taus=None):
    """Modified Allan deviation (NIST SP 1065 eq. 14). Returns (taus_used s, devs, errs, ns);
    devs in the data's rate unit."""
    return _compat("mdev", data, rate, data_type, taus)


def hdev(data, rate=1.0, data_type="phase", taus=None):
    """Hadamard deviation (non-overlapping; NIST SP 1065 eq. 17). Returns (taus_used s, devs,
    errs, ns); devs in the data's rate unit."""
    return _compat("hdev", data, rate, data_type, taus)


def ohdev(data, rate=1.0, data_type="phase", taus=None):
    """Overlapping Hadamard deviation (NIST SP 1065 eq. 18). Returns (taus_used s, devs, errs,
    ns); devs in the data's rate unit."""
    return _compat("ohdev", data, rate, data_type, taus)


def tdev(data, rate=1.0, data_type="phase", taus=None):
    """Time deviation τ·MDEV/√3 (NIST SP 1065 eq. 15). Returns (taus_used s, devs, errs, ns);
    devs in s for phase data (rate unit × s for rate data)."""
    return _compat("tdev", data, rate, data_type, taus)


def totdev(data, rate=1.0, data_type="phase", taus=None):
    """Total deviation (NIST SP 1065 eq. 25: the phase reflected at both ends; ns = N − 2 at
    every τ, τ up to N − 1 samples as in AllanTools). Returns (taus_used s, devs, errs, ns);
    devs in the data's rate unit."""
    return _compat("totdev", data, rate, data_type, taus)
