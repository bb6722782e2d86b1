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
    """``columns`` (contract units: m/s², deg/s, µT, °C), ``units``, ``t`` (s), ``rate_hz``
    (Hz), ``segments`` (row ranges between gaps), ``timing``."""

    path: str
    columns: Dict[str, npt.NDArray[np.float64]]
    units: Dict[str, str]
    t: Optional[npt.NDArray[np.float64]]
    rate_hz: Optional[float]
    segments: List[Tuple[int, int]] = ...
    timing: Optional[dict] = ...
    def __getitem__(self, name: str) -> npt.NDArray[np.float64]: ...

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
