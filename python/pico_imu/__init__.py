"""pico-imu on numpy arrays.

* :mod:`pico_imu.allantools` — the seven AllanTools statistics with AllanTools' signatures and
  results, computed by pico-imu's Allan engine.
* :func:`deviation` — a deviation table with each row's noise exponent, equivalent degrees of
  freedom and 68.3 % confidence bounds, as ``imu-lab adev`` prints it.
* :class:`Stream` — the device's bounded streaming engine fed chunk by chunk: a day at 1 kHz in
  a few KiB.
* :func:`read_csv` — a recording that follows the CSV contract (time from ``t``, gaps, units);
  :func:`read_csv_chunks` the same in chunks of rows, and :func:`stream_csv` a column of any
  length through the streaming engine in bounded memory.
* :func:`fit` — the noise lab (``imu-lab fit``): the model of Jaime et al. and the effects the
  diagnosis names, each estimate with its uncertainty, the verdict, the walk; a :class:`Fit`.
* :func:`calibrate` — the calibration lab (``imu-lab calibrate``): a :class:`Calibration` whose
  ``save`` writes the TOML file the CLI and the device read.
* :class:`Device` — the device (a Pico on its USB port, or the emulated one on ``tcp:HOST:PORT``)
  through ``imu-lab``'s link: status, recordings into arrays, its Allan tables, calibration
  upload with the CLI's checks.

Every function releases the GIL while it computes (and :class:`Device` while it waits). Bad
arguments raise ``ValueError`` naming the argument (and the index of a bad sample); a file that
cannot be opened, or a device that fails, raises ``OSError`` (``TimeoutError`` when it does not
answer).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

import numpy as np

from . import _native
from . import allantools

__all__ = ["allantools", "deviation", "Table", "Stream", "read_csv", "Recording", "read_csv_chunks",
           "stream_csv", "STATS", "fit", "Fit", "Term", "Step", "calibrate", "Calibration", "Device",
           "DeviceTable"]

#: The statistics :func:`deviation` computes.
STATS = ("adev", "oadev", "mdev", "hdev", "ohdev", "tdev", "totdev")


def _as_samples(data, name: str = "data") -> np.ndarray:
    a = np.ascontiguousarray(np.asarray(data, dtype=np.float64))
    if a.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D array of samples, got shape {a.shape}")
    return a


@dataclass
class Table:
    """A deviation table. Arrays, one entry a row: ``tau`` (s), ``m`` (samples), ``dev`` and
    the 68.3 % bounds ``lo``, ``hi`` (in ``unit``; TDEV: ``unit``·s), ``n`` (terms in the sum),
    ``alpha`` (noise exponent used for the EDF, S_y ∝ f^alpha), ``edf`` (equivalent degrees of
    freedom), and, for the streaming engine, ``stride`` (samples between differences)."""

    stat: str
    unit: str
    tau: np.ndarray
    m: np.ndarray
    dev: np.ndarray
    n: np.ndarray
    alpha: np.ndarray
    edf: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    stride: Optional[np.ndarray] = None

    @classmethod
    def _of(cls, stat: str, unit: str, d: dict) -> "Table":
        return cls(stat=stat, unit=unit, **d)

    def dev_unit(self) -> str:
        """The unit of ``dev``, ``lo`` and ``hi``."""
        return f"{self.unit}·s" if self.stat == "tdev" else self.unit

    def to_dict(self) -> Dict[str, list]:
        """The table as plain lists (JSON-ready), keys as the attributes."""
        out = {"stat": self.stat, "unit": self.dev_unit()}
        for k in ("tau", "m", "dev", "n", "alpha", "edf", "lo", "hi", "stride"):
            v = getattr(self, k)
            if v is not None:
                out[k] = [None if isinstance(x, float) and not np.isfinite(x) else x for x in v.tolist()]
        return out

    def __len__(self) -> int:
        return len(self.tau)

    def __str__(self) -> str:
        u = self.dev_unit()
        head = (f"{'tau [s]':>12} {'m':>10} {self.stat + ' [' + u + ']':>22} {'lo [' + u + ']':>16} "
                f"{'hi [' + u + ']':>16} {'n':>10} {'alpha':>5} {'edf':>10}")
        lines = [f"{self.stat.upper()}; bounds are 68.3 % (Greenhall EDF, χ²)", head]
        for i in range(len(self)):
            lines.append(
                f"{self.tau[i]:>12.6g} {int(self.m[i]):>10d} {self.dev[i]:>22.6g} "
                f"{self.lo[i]:>16.6g} {self.hi[i]:>16.6g} {int(self.n[i]):>10d} "
                f"{int(self.alpha[i]):>5d} {self.edf[i]:>10.4g}"
            )
        return "\n".join(lines)

    def plot(self, ax=None, label: Optional[str] = None):
        """Draws the deviation against τ on log-log axes with its 68.3 % bounds as error bars
        (matplotlib, the ``plot`` extra: ``pip install './python[plot]'``). Returns the axes."""
        try:
            import matplotlib.pyplot as plt
        except ImportError:
            raise ImportError("Table.plot needs matplotlib: pip install './python[plot]'") from None
        if ax is None:
            _, ax = plt.subplots()
        ok = np.isfinite(self.lo) & np.isfinite(self.hi)
        ax.errorbar(self.tau[ok], self.dev[ok], yerr=[self.dev[ok] - self.lo[ok], self.hi[ok] - self.dev[ok]],
                    fmt="o-", ms=3, capsize=2, label=label or self.stat.upper())
        if not ok.all():
            ax.plot(self.tau[~ok], self.dev[~ok], "o", ms=3, mfc="none", color=ax.lines[-1].get_color())
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("τ [s]")
        ax.set_ylabel(f"{self.stat.upper()} [{self.dev_unit()}]" if self.unit else self.stat.upper())
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        return ax

    def _repr_html_(self) -> str:
        u = self.dev_unit()
        rows = "".join(
            f"<tr><td>{self.tau[i]:.6g}</td><td>{int(self.m[i])}</td><td>{self.dev[i]:.6g}</td>"
            f"<td>{self.lo[i]:.6g}</td><td>{self.hi[i]:.6g}</td><td>{int(self.n[i])}</td>"
            f"<td>{int(self.alpha[i])}</td><td>{self.edf[i]:.4g}</td></tr>"
            for i in range(len(self))
        )
        return (
            f"<table><tr><th>τ [s]</th><th>m</th><th>{self.stat} [{u}]</th><th>lo (68.3 %) [{u}]</th>"
            f"<th>hi (68.3 %) [{u}]</th><th>n</th><th>α</th><th>EDF</th></tr>{rows}</table>"
        )


def deviation(data, rate: float, stat: str = "oadev", taus="octave", data_type: str = "freq",
              unit: str = "") -> Table:
    """The deviation ``stat`` (one of :data:`STATS`) of ``data`` sampled at ``rate`` Hz, with
    the noise exponent, EDF (Greenhall's algorithm) and 68.3 % bounds of every row.

    ``data``: rate samples (``data_type="freq"``, default; e.g. deg/s) or phase in s
    (``"phase"``). ``taus``: ``"octave"``, ``"decade"``, ``"all"``, ``"N/octave"``, or a
    sequence of whole averaging factors m (samples). ``unit`` labels the table. Rows with
    fewer than 2 terms are dropped."""
    x = _as_samples(data)
    if isinstance(taus, str):
        d = _native.deviation(x, float(rate), stat, data_type, taus=taus)
    else:
        ms = np.asarray(taus, dtype=float)
        if (ms.ndim != 1 or ms.size == 0 or not np.all(np.isfinite(ms)) or not np.all(ms == np.round(ms))
                or np.any(ms < 1) or np.any(ms > 2.0**62)):
            raise ValueError("taus: give a name or a non-empty sequence of whole m ≥ 1 (samples)")
        d = _native.deviation(x, float(rate), stat, data_type, ms=[int(v) for v in ms])
    return Table._of(stat, unit, d)


class Stream:
    """The bounded streaming engine of the device (overlapping Allan and Hadamard deviations at
    octave τ, integer-exact, a few KiB whatever the length), fed chunk by chunk.

    Samples are whole counts (raw LSB); ``scale`` is the value of one count in ``unit``.
    At m ≤ 8 its rows equal the batch OADEV/OHDEV; longer τ use differences every m/8 samples
    (``stride``), with the EDF of that estimator."""

    def __init__(self, rate: float, scale: float = 1.0, unit: str = ""):
        self._engine = _native.Stream(float(rate), float(scale))
        self.rate = float(rate)
        self.unit = unit

    def push(self, chunk) -> None:
        """Feeds whole counts (a 1-D array). A chunk with a non-integer, NaN or out-of-range
        value is refused whole (``ValueError`` naming its index)."""
        self._engine.push(_as_samples(chunk, "chunk"))

    def gap(self) -> None:
        """Marks lost samples before the next chunk: no difference spans a gap."""
        self._engine.gap()

    @property
    def samples(self) -> int:
        """Samples pushed so far."""
        return self._engine.samples

    @property
    def gaps(self) -> int:
        """Gaps marked so far."""
        return self._engine.gaps

    def table(self, stat: str = "oadev") -> Table:
        """The table so far: ``"oadev"`` or ``"ohdev"``, in ``unit``."""
        return Table._of(stat, self.unit, self._engine.table(stat))


@dataclass
class Recording:
    """A recording read by :func:`read_csv` or made by :meth:`Device.record`. ``columns``:
    name → array in the contract's unit (``units``: ax ay az m/s², gx gy gz deg/s, mx my mz µT,
    temp °C, gap_before samples; a device recording's attitude q0…q3 (1), roll pitch heading
    deg, ahrs state; NaN where empty); ``t`` (s) or None; ``rate_hz`` (Hz, from the median
    spacing of ``t``) or None; ``segments``: (start, stop) row ranges between gaps; ``timing``:
    median_dt_s (s), gaps, missing_samples, irregular, summary (or None without ``t``).

    A device recording also has ``losses`` (per sensor: samples ``received``, ``lost``, the
    device's ``causes`` and those lost on the ``link``), ``summary``, ``events``,
    ``device_status`` and ``raw`` (see :meth:`Device.record`); None for a file."""

    path: str
    columns: Dict[str, np.ndarray]
    units: Dict[str, str]
    t: Optional[np.ndarray]
    rate_hz: Optional[float]
    segments: List[Tuple[int, int]] = field(default_factory=list)
    timing: Optional[dict] = None
    losses: Optional[dict] = None
    summary: Optional[str] = None
    events: Optional[List[str]] = None
    device_status: Optional[dict] = None
    raw: Optional[bool] = None

    def to_csv(self, path) -> None:
        """Writes the recording as ``imu-lab record`` writes its CSV (header ``t,ax,ay,az,gx,
        gy,gz,mx,my,mz,temp,gap_before,q0,q1,q2,q3,roll,pitch,heading,ahrs``; t with µs
        resolution, values at f32 precision, NaN as an empty field), which :func:`read_csv`
        reads back. Needs ``t``, ``gap_before`` and the nine sensor columns; ``temp`` and the
        attitude columns may be missing (empty fields). ``OSError`` if it cannot be written."""
        _native.write_record_csv(os.fspath(path), {k: np.ascontiguousarray(v, dtype=np.float64)
                                                   for k, v in self.columns.items()})

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.columns[name]
        except KeyError:
            raise KeyError(f"{self.path}: no column {name!r} (columns: {', '.join(self.columns)})") from None


def read_csv(path, skip_lines: int = 0) -> Recording:
    """Reads a recording that follows pico-imu's CSV contract into numpy arrays (see
    :class:`Recording`). A malformed file raises ``ValueError`` naming the line and field; a
    missing file ``OSError``."""
    d = _native.read_csv(str(path), int(skip_lines))
    return Recording(path=str(path), **d)


def read_csv_chunks(path, columns: Optional[List[str]] = None, rows: int = 65536, skip_lines: int = 0):
    """A recording read ``rows`` rows at a time, in bounded memory: an iterator of dicts with
    ``start`` (index of the chunk's first row), ``columns`` (name → array, contract units) and
    ``gaps`` (offsets in the chunk of the rows a gap precedes; each starts a new segment). Its
    ``rate_hz`` (Hz, from the median spacing of the first 65 536 stamps; None without ``t``) is
    known before the first chunk. Errors as :func:`read_csv`."""
    return _native.CsvChunks(str(path), columns, int(rows), int(skip_lines))


def stream_csv(path, column: str, scale: float = 1.0, unit: Optional[str] = None, rows: int = 65536,
               rate: Optional[float] = None) -> Stream:
    """A column of whole counts fed from the file through the streaming engine chunk by chunk,
    a gap in ``t`` (or ``gap_before``) closing the engine's segment as on the device: a day at
    1 kHz in constant memory. ``scale`` is one count in ``unit`` (default: the contract's unit
    of the column); ``rate`` (Hz) defaults to the file's. Returns the fed :class:`Stream`."""
    chunks = read_csv_chunks(path, [column], rows)
    rate = rate if rate is not None else chunks.rate_hz
    if rate is None:
        raise ValueError(f"{path}: no t column to read the rate from; give rate= (Hz)")
    if unit is None:
        unit = chunks.units.get(column, "")
    s = Stream(rate, scale, unit)
    for chunk in chunks:
        y = chunk["columns"][column]
        cuts = [0] + [int(g) for g in chunk["gaps"]] + [len(y)]
        for k in range(len(cuts) - 1):
            if k > 0:
                s.gap()
            try:
                s.push(y[cuts[k]:cuts[k + 1]])
            except ValueError as e:
                raise ValueError(f"{path}: rows from {chunk['start'] + cuts[k]}: {e}") from None
    return s


from .lab import Calibration, Fit, Step, Term, calibrate, fit  # noqa: E402  (lab imports Recording from here)
from .device import Device, DeviceTable  # noqa: E402  (device imports Recording and Table from here)
