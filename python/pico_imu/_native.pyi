"""Type stubs of the Rust extension module (python/src/). Use the package's public API
(:mod:`pico_imu`, :mod:`pico_imu.allantools`); these are its building blocks."""
from typing import Dict, List, Optional, Tuple

import numpy as np
import numpy.typing as npt

def deviation(
    data: npt.NDArray[np.float64],
    rate: float,
    stat: str,
    data_type: str = "freq",
    taus: str = "octave",
    ms: Optional[List[int]] = None,
) -> Dict[str, np.ndarray]:
    """Table of ``stat`` over ``data`` (rate samples, or phase in s) sampled at ``rate`` Hz:
    arrays ``tau`` (s), ``m``, ``dev``, ``n``, ``alpha``, ``edf``, ``lo``, ``hi`` (68.3 %)."""

def plain_deviations(
    data: npt.NDArray[np.float64], rate: float, stat: str, data_type: str, ms: List[int]
) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.uint64]]:
    """(deviations, term counts) at each m; NaN and 0 where an m has no term."""

def read_csv(path: str, skip_lines: int = 0) -> dict:
    """A contract recording: columns, units, t (s), rate_hz (Hz), segments, timing."""

def panic_for_test() -> None:
    """Raises RuntimeError from a deliberate Rust panic (for the tests)."""

class Stream:
    """The device's streaming engine (overlap 8, 32 octave levels) on whole counts."""

    def __init__(self, rate: float, scale: float = 1.0) -> None: ...
    def push(self, chunk: npt.NDArray[np.float64]) -> None:
        """Feeds whole counts; the GIL is released while they are summed."""
    def gap(self) -> None:
        """Marks lost samples: no difference spans the gap."""
    @property
    def samples(self) -> int: ...
    @property
    def gaps(self) -> int: ...
    def table(self, stat: str = "oadev") -> Dict[str, np.ndarray]:
        """``tau`` (s), ``m``, ``dev`` (count × scale), ``n``, ``alpha``, ``edf``, ``lo``,
        ``hi``, ``stride``."""

class CsvChunks:
    """A contract recording in chunks of rows with the gaps found on the way."""

    def __init__(self, path: str, columns: Optional[List[str]] = None, rows: int = 65536, skip_lines: int = 0) -> None: ...
    @property
    def names(self) -> List[str]: ...
    @property
    def units(self) -> Dict[str, str]: ...
    @property
    def rate_hz(self) -> Optional[float]: ...
    def __iter__(self) -> "CsvChunks": ...
    def __next__(self) -> Dict[str, object]: ...

class NativeFit:
    """A finished noise-lab session (``noise_model::session``)."""

    def json(self) -> str:
        """The object ``imu-lab fit --json`` prints."""
    def verdict(self) -> str: ...
    def physics(self) -> List[Tuple[str, str]]: ...
    def param_units(self) -> List[List[Tuple[str, str]]]: ...
    def stages(self) -> List[Dict[str, object]]: ...

def fit(
    y: npt.NDArray[np.float64],
    rate: Optional[float] = None,
    unit: str = "",
    column: str = "y",
    t: Optional[npt.NDArray[np.float64]] = None,
    gap_before: Optional[npt.NDArray[np.float64]] = None,
    temp: Optional[npt.NDArray[np.float64]] = None,
    terms: List[str] = ...,
    add: List[str] = ...,
    effects: List[Tuple[str, str]] = ...,
    auto: bool = False,
    max_steps: int = 6,
    tolerance: Optional[float] = None,
) -> NativeFit:
    """The session on ``y`` (``rate`` Hz, or from ``t`` in s); ``effects``: (TOML text, name)."""

class NativeCalibration:
    """A finished calibration session (``imu_cal::session``)."""

    def json(self) -> str:
        """The object ``imu-lab calibrate --json`` prints."""
    def toml(self, existing: Optional[str] = None) -> str:
        """The calibration file with this run's section set (ValueError when implausible)."""
    def section(self) -> str: ...

def calibrate(
    sensor: str,
    columns: Dict[str, npt.NDArray[np.float64]],
    units: Dict[str, str],
    rate: float,
    segments: List[Tuple[int, int]],
    model: List[str] = ...,
    g: Optional[float] = None,
    field: Optional[float] = None,
    window: float = 1.0,
    threshold_k: float = 6.0,
    min_static: float = 1.5,
    saturation: Optional[float] = None,
    blocks: int = 50,
    auto: bool = False,
    max_steps: int = 4,
) -> NativeCalibration:
    """The session on ``columns`` (name → samples in ``units``) at ``rate`` Hz."""

class NativeDevice:
    """The device link (``imu_link``); the GIL is released while the device is waited for."""

    def __init__(self, port: str, timeout: float = 3.0) -> None: ...
    @property
    def port(self) -> str: ...
    @property
    def closed(self) -> bool: ...
    def close(self) -> None: ...
    @property
    def requests_sent(self) -> int: ...
    @property
    def frames_rejected(self) -> int: ...
    def take_warnings(self) -> List[str]: ...
    def identity(self) -> dict: ...
    def status(self) -> dict: ...
    def record(self, seconds: float, raw: bool = False) -> dict:
        """``names``, ``columns``, ``units``, ``t`` (s), ``rate_hz`` (Hz), ``segments``,
        ``timing``, ``summary``, ``span_s`` (s), ``before_mag``, ``losses``, ``events``,
        ``device_status``."""
    def tables(self, channels: List[str] = ..., timeout: float = 30.0) -> List[dict]: ...
    def reset_allan(self) -> None: ...
    def calibration(self) -> dict: ...
    def upload(self, content: bytes, is_blob: bool, persist: bool, what: str) -> dict: ...
    def orientation(self) -> dict: ...
    def set_orientation(self, declination_deg: Optional[float] = None, field_ut: Optional[float] = None,
                        dip_deg: Optional[float] = None, learn: bool = False) -> dict: ...

def write_record_csv(path: str, columns: Dict[str, npt.NDArray[np.float64]]) -> None:
    """A recording's columns as ``imu-lab record``'s CSV."""
