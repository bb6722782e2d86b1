"""AllanTools-compatible deviations (see the module's docstring for the conventions).

Each function returns ``(taus_used, devs, errs, ns)``: τ in s; deviations and their simple
error bars devs/√ns in the data's rate unit (fractional frequency for phase in s; TDEV in s, or
rate unit × s for rate data); ns, the terms in each sum, as floats."""
from typing import Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

Taus = Union[None, str, Sequence[float], npt.NDArray[np.float64]]
Result = Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]

def tau_ms(n_phase: int, rate: float, taus: Taus = "octave") -> npt.NDArray[np.uint64]:
    """The averaging factors m (samples) AllanTools uses for ``taus`` (s or a keyword)."""

def adev(data: npt.ArrayLike, rate: float = 1.0, data_type: str = "phase", taus: Taus = None) -> Result:
    """Allan deviation (non-overlapping). ``data``: phase (s) or rate samples; ``rate``: Hz."""

def oadev(data: npt.ArrayLike, rate: float = 1.0, data_type: str = "phase", taus: Taus = None) -> Result:
    """Overlapping Allan deviation. ``data``: phase (s) or rate samples; ``rate``: Hz."""

def mdev(data: npt.ArrayLike, rate: float = 1.0, data_type: str = "phase", taus: Taus = None) -> Result:
    """Modified Allan deviation. ``data``: phase (s) or rate samples; ``rate``: Hz."""

def hdev(data: npt.ArrayLike, rate: float = 1.0, data_type: str = "phase", taus: Taus = None) -> Result:
    """Hadamard deviation (non-overlapping). ``data``: phase (s) or rate samples; ``rate``: Hz."""

def ohdev(data: npt.ArrayLike, rate: float = 1.0, data_type: str = "phase", taus: Taus = None) -> Result:
    """Overlapping Hadamard deviation. ``data``: phase (s) or rate samples; ``rate``: Hz."""

def tdev(data: npt.ArrayLike, rate: float = 1.0, data_type: str = "phase", taus: Taus = None) -> Result:
    """Time deviation τ·MDEV/√3 (s for phase data). ``rate``: Hz."""

def totdev(data: npt.ArrayLike, rate: float = 1.0, data_type: str = "phase", taus: Taus = None) -> Result:
    """Total deviation (reflected phase; ns = N − 2). ``data``: phase (s) or rate; ``rate``: Hz."""
