"""pico-imu on numpy arrays: AllanTools-compatible deviations, tables with confidence intervals,
the bounded streaming engine and the CSV recording contract."""
from dataclasses import dataclass
from os import PathLike
from typing import Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

from . import allantools as allantools

STATS: Tuple[str, ...]

@dataclass
class Table:
    """A deviation table: ``tau`` (s), ``m`` (samples), ``dev``/``lo``/``hi`` (68.3 % bounds,
    in :meth:`dev_unit`), ``n`` (terms), ``alpha`` (noise exponent), ``edf``; ``stride``
    (samples) for the streaming engine."""

    stat: str
    unit: str
    tau: npt.NDArray[np.float64]
    m: npt.NDArray[np.uint64]
    dev: npt.NDArray[np.float64]
    n: npt.NDArray[np.uint64]
    alpha: npt.NDArray[np.int32]
    edf: npt.NDArray[np.float64]
    lo: npt.NDArray[np.float64]
    hi: npt.NDArray[np.float64]
    stride: Optional[npt.NDArray[np.uint64]] = None
    def dev_unit(self) -> str:
        """The unit of ``dev``, ``lo`` and ``hi`` (``unit``; TDEV ``unit``·s)."""
    def to_dict(self) -> Dict[str, object]:
        """Plain lists, JSON-ready."""
    def __len__(self) -> int: ...
    def plot(self, ax: object = None, label: Optional[str] = None) -> object:
        """Deviation against τ (s), log-log, 68.3 % bounds as error bars (matplotlib)."""
    def _repr_html_(self) -> str: ...

def deviation(
    data: npt.ArrayLike,
    rate: float,
    stat: str = "oadev",
    taus: Union[str, Sequence[int]] = "octave",
    data_type: str = "freq",
    unit: str = "",
) -> Table:
    """The table of ``stat`` over ``data`` (rate samples in ``unit``, or phase in s) sampled at
    ``rate`` Hz, with noise exponent, EDF and 68.3 % bounds per row."""

class Stream:
    """The device's bounded streaming engine (OADEV/OHDEV at octave τ, a few KiB of state)
    fed whole counts chunk by chunk; ``scale`` is one count in ``unit``; ``rate`` in Hz."""

    rate: float
    unit: str
    def __init__(self, rate: float, scale: float = 1.0, unit: str = "") -> None: ...
    def push(self, chunk: npt.ArrayLike) -> None:
        """Feeds whole counts; a chunk with a bad value is refused whole (ValueError, index)."""
    def gap(self) -> None:
        """Marks lost samples before the next chunk."""
    @property
    def samples(self) -> int: ...
    @property
    def gaps(self) -> int: ...
    def table(self, stat: str = "oadev") -> Table:
        """``"oadev"`` or ``"ohdev"`` so far, in ``unit``."""

@dataclass
class Recording:
    """``columns`` (contract units: m/s², deg/s, µT, °C; a device recording's attitude too),
    ``units``, ``t`` (s), ``rate_hz`` (Hz), ``segments`` (row ranges between gaps), ``timing``;
    a device recording's ``losses``, ``summary``, ``events``, ``device_status``, ``raw``."""

    path: str
    columns: Dict[str, npt.NDArray[np.float64]]
    units: Dict[str, str]
    t: Optional[npt.NDArray[np.float64]]
    rate_hz: Optional[float]
    segments: List[Tuple[int, int]] = ...
    timing: Optional[dict] = ...
    losses: Optional[dict] = ...
    summary: Optional[str] = ...
    events: Optional[List[str]] = ...
    device_status: Optional[dict] = ...
    raw: Optional[bool] = ...
    def __getitem__(self, name: str) -> npt.NDArray[np.float64]: ...
    def to_csv(self, path: Union[str, PathLike]) -> None:
        """Writes the CSV ``imu-lab record`` writes (t in s with µs resolution, values at f32
        precision, NaN as an empty field); ``read_csv`` reads it back."""

def read_csv(path: Union[str, PathLike], skip_lines: int = 0) -> Recording:
    """Reads a contract recording; ValueError names a malformed line and field, OSError a file
    that cannot be opened."""

class CsvChunks:
    """Iterator of chunk dicts: ``start`` (row index), ``columns`` (name → array), ``gaps``
    (offsets of rows a gap precedes)."""

    @property
    def names(self) -> List[str]: ...
    @property
    def units(self) -> Dict[str, str]:
        """The contract unit of each chosen column."""
    @property
    def rate_hz(self) -> Optional[float]:
        """Hz, from the median spacing of the first 65 536 stamps; None without ``t``."""
    def __iter__(self) -> "CsvChunks": ...
    def __next__(self) -> Dict[str, object]: ...

def read_csv_chunks(
    path: Union[str, PathLike], columns: Optional[List[str]] = None, rows: int = 65536, skip_lines: int = 0
) -> CsvChunks:
    """A recording ``rows`` rows at a time, in bounded memory, with the gaps found on the way."""

def stream_csv(
    path: Union[str, PathLike],
    column: str,
    scale: float = 1.0,
    unit: Optional[str] = None,
    rows: int = 65536,
    rate: Optional[float] = None,
) -> Stream:
    """A column of whole counts through the streaming engine chunk by chunk (gaps close the
    engine's segment); ``scale``: one count in ``unit``; ``rate``: Hz (default: the file's)."""

@dataclass
class Term:
    """One fitted term. ``params``/``sigma``/``interval`` (68.3 %)/``upper_bound`` (95 %, when
    not detected) by parameter name, in the parameter's unit (amplitudes in the column's unit ×
    s^k, e.g. N in deg/s·√s; corner frequencies in Hz; time constants in s); ``tau_range_s``
    where it dominates (s)."""

    effect: str
    params: Dict[str, Optional[float]]
    sigma: Dict[str, Optional[float]]
    interval: Dict[str, List[Optional[float]]]
    detected: bool
    upper_bound: Dict[str, Optional[float]]
    known: bool
    tau_range_s: Optional[List[float]]
    reading: str
    units: Dict[str, str]
    """Parameter name → unit."""

@dataclass
class Step:
    """One step of the walk: effects added/removed, χ²/dof and RMS log-residual before → after,
    adequacy before → after, the step's p-value (None for a step asked by hand), the reading."""

    added: List[str]
    removed: List[str]
    reading: str
    p_value: Optional[float]
    chi2_dof_before: float
    chi2_dof_after: float
    rms_log_residual_before: float
    rms_log_residual_after: float
    adequate_before: bool
    adequate_after: bool

class Fit:
    """The last model of a noise-lab session (``imu-lab fit``)."""

    column: str
    unit: str
    rate_hz: float
    """Hz."""
    samples: int
    terms: List[Term]
    chi2_dof: float
    """χ² per degree of freedom of the fit on the Allan variance (≈ 1 when adequate)."""
    dof: float
    p_value: Optional[float]
    rms_log_residual: float
    adequate: bool
    verdict: str
    missing: Optional[str]
    """The effect the diagnosis names, or None."""
    explanation: str
    evidence: List[str]
    physics: Dict[str, str]
    """Effect name → its physical mechanism (the model's effects and the missing one)."""
    table: Dict[str, npt.NDArray[np.float64]]
    """Per τ: ``tau_s`` (s), ``dev``/``lo``/``hi``/``model``/``model_sigma`` (unit; the last the
    model's 1σ from its parameters), ``residual`` (CI half-widths), ``z``, ``edf``,
    ``edf_model``."""
    steps: List[Step]
    stop: Optional[str]
    def term(self, effect: str) -> Term: ...
    def to_dict(self) -> Dict[str, object]:
        """The object ``imu-lab fit --json`` prints."""
    def stages(self) -> List[Dict[str, object]]:
        """Every model of the session: ``effects``, ``tau`` (s), ``dev``/``lo``/``hi``/``model``
        and ``terms`` (name → deviation) in ``unit``, ``residual``, ``adequate``."""
    def plot(self, fig: object = None, stage: int = -1) -> object:
        """Allan deviation (unit) against τ (s) with bounds, model and terms; residual panel."""
    def steps_text(self) -> str: ...
    def terms_text(self) -> str: ...
    def _repr_html_(self) -> str: ...

def fit(
    y: Union[npt.ArrayLike, Recording],
    rate: Optional[float] = None,
    unit: Optional[str] = None,
    terms: Sequence[str] = (),
    add: Sequence[str] = (),
    effects: Sequence[Union[str, PathLike]] = (),
    auto: bool = False,
    max_steps: int = 6,
    tolerance: Optional[float] = None,
    column: Optional[str] = None,
    t: Optional[npt.ArrayLike] = None,
    temp: Optional[npt.ArrayLike] = None,
) -> Fit:
    """The noise lab on rate samples (``rate`` Hz; ``t`` s, ``temp`` °C; ``tolerance`` in
    ``unit``) or on a recording's ``column``: ``imu-lab fit``'s session."""

class Calibration:
    """The last model of a calibration session (``imu-lab calibrate``)."""

    sensor: str
    unit: str
    """Unit of the columns, of offsets and biases, of ``residual_rms`` and ``noise_floor``."""
    model: List[str]
    params: Dict[str, object]
    """By parameter: offsets in ``unit``; scale factors, misalignments, soft iron dimensionless."""
    sigma: Dict[str, object]
    """1σ of ``params``, same layout."""
    residual_rms: float
    noise_floor: float
    adequate: bool
    verdict: str
    missing: Optional[str]
    explanation: str
    steps: List[Dict[str, object]]
    stop: Optional[str]
    def to_dict(self) -> Dict[str, object]:
        """The object ``imu-lab calibrate --json`` prints."""
    def save(self, path: Union[str, PathLike]) -> None:
        """Writes (or updates this sensor's section of) the TOML calibration file; ValueError
        naming key, axis, value and bound when the device could not hold it."""
    def _repr_html_(self) -> str: ...

def calibrate(
    sensor: str,
    samples: Union[Recording, Dict[str, npt.ArrayLike]],
    model: Sequence[str] = (),
    auto: bool = False,
    rate: Optional[float] = None,
    units: Optional[Dict[str, str]] = None,
    g: Optional[float] = None,
    field: Optional[float] = None,
    window: float = 1.0,
    threshold_k: float = 6.0,
    min_static: float = 1.5,
    saturation: Optional[float] = None,
    blocks: int = 50,
    max_steps: int = 4,
    part: Optional[str] = None,
) -> Calibration:
    """The calibration lab on ``accel``/``gyro``/``mag`` columns (m/s², deg/s, µT unless
    ``units`` says otherwise; ``rate`` Hz; ``g``, ``field`` in the columns' unit; ``window``,
    ``min_static`` s; ``saturation`` deg/s; ``part`` the recording's part, e.g. ``"HMC5883L"``):
    ``imu-lab calibrate``'s session."""

@dataclass
class DeviceTable(Table):
    """One channel's Allan table from the device (OADEV at octave τ, EDF, 68.3 % bounds):
    ``channel``, ``snapshot``, ``t_s`` (device time of the snapshot, s), ``tau0_s`` (measured
    sample period, s), ``scale`` (``unit`` per count), ``pushed`` (samples since the Allan
    reset), ``gaps``."""

    channel: str = ...
    snapshot: int = ...
    t_s: float = ...
    tau0_s: float = ...
    scale: float = ...
    pushed: int = ...
    gaps: int = ...

class Device:
    """A device running pico-imu's firmware: a serial port or ``tcp:HOST:PORT`` (the
    emulator). ``timeout`` in s. ValueError for bad arguments and refused calibrations
    (nothing sent), TimeoutError when the device does not answer, OSError for the port."""

    def __init__(self, port: str, timeout: float = 3.0) -> None: ...
    def __enter__(self) -> "Device": ...
    def __exit__(self, *exc: object) -> None: ...
    @property
    def port(self) -> str: ...
    @property
    def closed(self) -> bool: ...
    def close(self) -> None: ...
    @property
    def identity(self) -> dict:
        """``protocol``, ``firmware``, ``board``, ``imu_rate_hz``/``mag_rate_hz`` (Hz),
        ``allan_overlap``, ``allan_levels``, ``allan_levels_mag``."""
    @property
    def requests_sent(self) -> int: ...
    def status(self) -> dict:
        """Counters and health: ``uptime_s`` (s), per sensor ``samples_taken``, ``samples_lost``,
        ``period_s`` (s); ``cpu_load_percent`` (%), ``temperature_c`` (°C), ``calibration``,
        ``mode``."""
    def info(self) -> dict:
        """``port``, ``identity``, ``status``, ``calibration`` (with the parts it was fitted
        for) and ``link`` (``requests_sent``, ``frames_rejected``)."""
    def record(self, seconds: float, raw: bool = False) -> Recording:
        """``seconds`` (s) of device time as ``imu-lab record`` records it; Ctrl-C raises
        KeyboardInterrupt within 0.1 s (the stream switched off)."""
    def tables(self, channels: Optional[Sequence[str]] = None, timeout: float = 30.0) -> Dict[str, DeviceTable]:
        """The device's Allan tables of one snapshot (``timeout`` in s)."""
    def reset_allan(self) -> None: ...
    def calibration(self) -> dict:
        """``blob`` (bytes), ``source``, ``status``, ``fitted_for``, ``accel``/``gyro``/``mag``
        (``matrix``, ``offset_lsb`` in nominal LSB; the gyro's ``kappa``, ``t_ref_lsb``)."""
    def upload(self, calibration: Union[Calibration, str, PathLike, bytes, bytearray], persist: bool = True) -> dict:
        """Checked as ``imu-lab device calibrate --upload`` checks (ValueError naming key, axis,
        value, bound; nothing sent), uploaded, read back (:meth:`calibration`)."""
    def orientation(self) -> dict:
        """``declination_deg`` (deg), ``field_ut`` (µT), ``dip_deg`` (deg), ``learnt``."""
    def set_orientation(self, declination_deg: Optional[float] = None, field_ut: Optional[float] = None,
                        dip_deg: Optional[float] = None, learn: bool = False) -> dict: ...
    @property
    def declination(self) -> float:
        """Degrees, east positive."""
    @declination.setter
    def declination(self, deg: float) -> None: ...
