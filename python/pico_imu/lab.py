"""The noise lab from Python: :func:`fit` runs the session ``imu-lab fit`` runs (the same Rust
function, ``noise_model::session``) on an array of samples or a column of a recording."""
from __future__ import annotations

import html
import json
import os
from dataclasses import dataclass, field as _field
from typing import Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native


@dataclass
class Term:
    """One term of the fitted model. ``params``: parameter name → value; ``sigma``: its 1σ
    uncertainty; ``interval``: its 68.3 % interval (lo, hi) — all in the parameter's unit (an
    amplitude in the column's unit × s^k, e.g. N in deg/s·√s; a corner frequency in Hz; a time
    constant in s). ``detected``: the amplitude's interval excludes zero; ``upper_bound``: the
    95 % upper end of an undetected amplitude; ``known``: estimated outside the Allan fit (time
    domain or the data's lattice); ``tau_range_s``: where it dominates (s); ``reading``: what
    it says in words; ``units``: each parameter's unit."""

    effect: str
    params: Dict[str, Optional[float]]
    sigma: Dict[str, Optional[float]]
    interval: Dict[str, List[Optional[float]]]
    detected: bool
    upper_bound: Dict[str, Optional[float]]
    known: bool
    tau_range_s: Optional[List[float]]
    reading: str
    #: parameter name → its unit (e.g. ``{"N": "deg/s·√s"}``, ``{"cutoff_hz": "Hz"}``).
    units: Dict[str, str] = _field(default_factory=dict)


@dataclass
class Step:
    """One step of the walk: effects ``added`` and ``removed``, χ²/dof and RMS log-residual
    before and after, adequacy before and after, the p-value of the step (NaN → None for a step
    asked by hand) and the added effect's reading."""

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
    """The result of :func:`fit`: the last model of the session with every estimate.

    * ``terms`` (:class:`Term` list), ``chi2_dof`` (χ² per degree of freedom, 1 when the
      model matches the estimates' scatter), ``dof``, ``p_value`` (global), ``rms_log_residual``;
    * ``adequate`` (the verdict), ``missing`` (the effect the diagnosis names, or None),
      ``verdict`` (the sentence the CLI prints), ``explanation`` and ``evidence`` (the
      diagnosis in words), ``physics`` (effect name → the
      physical mechanism, for the model's effects and the missing one);
    * ``table``: the per-τ comparison (dict of arrays: ``tau_s`` s, ``dev``/``lo``/``hi``/``model``
      in ``unit``, ``residual`` = (measured − model)/CI half-width, ``z``, ``edf``);
    * ``steps`` (:class:`Step` list) and ``stop`` (why the automatic walk stopped);
    * :meth:`to_dict` — the object ``imu-lab fit --json`` prints; :meth:`plot`; in Jupyter the
      step table and the terms (``_repr_html_``)."""

    def __init__(self, native):
        self._native = native
        self._d = json.loads(native.json())
        d = self._d
        self.column: str = d["column"]
        self.unit: str = d["unit"]
        self.rate_hz: float = d["rate_hz"]
        self.samples: int = d["samples"]
        self.terms: List[Term] = [Term(**t, units=dict(u)) for t, u in zip(d["terms"], native.param_units())]
        self.chi2_dof: float = d["chi2_dof"]
        self.dof: float = d["dof"]
        self.p_value: Optional[float] = d["p_value"]
        self.rms_log_residual: float = d["rms_log_residual"]
        diag = d["diagnosis"]
        self.adequate: bool = diag["adequate"]
        self.missing: Optional[str] = diag["missing"]
        self.explanation: str = diag["explanation"]
        self.evidence: List[str] = diag["evidence"]
        self.physics: Dict[str, str] = dict(native.physics())
        #: The verdict sentence, as ``imu-lab fit`` prints it.
        self.verdict: str = native.verdict()
        self.table: Dict[str, np.ndarray] = {
            k: np.array([np.nan if r[k] is None else r[k] for r in d["adev"]], dtype=float)
            for k in ("tau_s", "dev", "lo", "hi", "model", "model_sigma", "residual", "z", "edf",
                      "edf_model")
        }
        self.steps: List[Step] = [Step(**s) for s in d["steps"]]
        self.stop: Optional[str] = d["stop"]

    def term(self, effect: str) -> Term:
        """The term called ``effect`` (``KeyError`` naming the model's terms otherwise)."""
        for t in self.terms:
            if t.effect == effect:
                return t
        raise KeyError(f"no term {effect!r} in the model ({', '.join(t.effect for t in self.terms)})")

    def to_dict(self) -> dict:
        """The JSON object ``imu-lab fit --json`` prints (NaN and infinities as None)."""
        return json.loads(self._native.json())

    def stages(self) -> List[dict]:
        """Every model of the session (the start model first): ``effects``, ``tau`` (s),
        ``dev``/``lo``/``hi``/``model`` (in ``unit``), ``residual``, ``terms`` (name → each
        term's deviation at the points, in ``unit``), ``adequate``."""
        return self._native.stages()

    def __repr__(self) -> str:
        verdict = "adequate" if self.adequate else f"not adequate, missing {self.missing}"
        return (f"<Fit {self.column} [{self.unit}]: {' + '.join(t.effect for t in self.terms)}; "
                f"χ²/dof = {self.chi2_dof:.3g}; {verdict}; {len(self.steps)} step(s)>")

    def steps_text(self) -> str:
        """The walk as text, as ``imu-lab fit --auto`` prints its steps: per step the edit,
        χ²/dof and RMS log-residual before → after, adequacy before → after, and on the next line
        the added effect's reading; then why the walk stopped. Empty for a fit without a walk."""
        lines = []
        for i, s in enumerate(self.steps, 1):
            edit = ", ".join([f"+ {a}" for a in s.added] + [f"− {r}" for r in s.removed])
            lines.append(
                f"  {i}. {edit:<24} χ²/dof {s.chi2_dof_before:.3g} → {s.chi2_dof_after:.3g}   "
                f"RMS log-residual {s.rms_log_residual_before:.3g} → {s.rms_log_residual_after:.3g}   "
                f"adequate {'yes' if s.adequate_before else 'no'} → {'yes' if s.adequate_after else 'no'}")
            lines.append(f"     {s.reading}")
        if self.stop:
            lines.append(f"Stop: {self.stop}.")
        return "\n".join(lines)

    def terms_text(self) -> str:
        """The model's terms, one a line: every parameter with its 1σ and unit, and
        ``(not detected)`` where the amplitude's interval includes zero."""
        return "\n".join(f"  {t.effect:<18} {_estimates(t)}{'' if t.detected else '  (not detected)'}"
                         for t in self.terms)

    def __str__(self) -> str:
        """The session in text: the walk (:meth:`steps_text`), the model (:meth:`terms_text`),
        the verdict and the diagnosis."""
        out = [f"{self.column} [{self.unit}]: {self.samples} samples at {self.rate_hz:.6g} Hz"]
        if self.steps or self.stop:
            out += ["Automatic walk: diagnose → add the named effect → refit", self.steps_text()]
        out += [f"Model of {self.column} [{self.unit}]:", self.terms_text(),
                f"Verdict: {self.verdict}", f"Diagnosis: {self.explanation}"]
        return "\n".join(out)

    def _repr_html_(self) -> str:
        e = html.escape
        out = [f"<p><b>{e(self.column)} [{e(self.unit)}]</b>: {self.samples} samples at "
               f"{self.rate_hz:.6g} Hz; χ²/dof = {self.chi2_dof:.3g}; "
               f"{'ADEQUATE' if self.adequate else 'NOT ADEQUATE'}</p>"]
        if self.steps:
            rows = "".join(
                f"<tr><td>{i + 1}</td><td>{e(', '.join('+ ' + a for a in s.added))}"
                f"{e(''.join(', − ' + r for r in s.removed))}</td>"
                f"<td>{s.chi2_dof_before:.3g} → {s.chi2_dof_after:.3g}</td>"
                f"<td>{s.rms_log_residual_before:.3g} → {s.rms_log_residual_after:.3g}</td>"
                f"<td>{'yes' if s.adequate_before else 'no'} → {'yes' if s.adequate_after else 'no'}</td>"
                f"<td>{e(s.reading)}</td></tr>"
                for i, s in enumerate(self.steps)
            )
            out.append("<table><tr><th>step</th><th>edit</th><th>χ²/dof</th><th>RMS log-residual</th>"
                       f"<th>adequate</th><th>reading</th></tr>{rows}</table>")
            if self.stop:
                out.append(f"<p>Stop: {e(self.stop)}.</p>")
        rows = "".join(
            f"<tr><td>{e(t.effect)}</td><td>{e(_estimates(t))}</td>"
            f"<td>{'yes' if t.detected else 'no'}</td><td>{e(t.reading)}</td></tr>"
            for t in self.terms
        )
        out.append(f"<table><tr><th>term</th><th>estimate ± 1σ</th><th>detected</th><th>reading</th></tr>{rows}</table>")
        out.append(f"<p>Diagnosis{' — missing effect: ' + e(self.missing) if self.missing else ''}: "
                   f"{e(self.explanation)}</p>")
        return "".join(out)

    def plot(self, fig=None, stage: int = -1):
        """The Allan figure of a model (default the last; 0 the start model): the measured
        deviation with its 68.3 % bounds, the model and each term (in ``unit`` against τ in s,
        log-log), and below it the residuals (measured − model)/CI half-width. matplotlib (the
        ``plot`` extra). Returns the figure."""
        try:
            import matplotlib.pyplot as plt
        except ImportError:
            raise ImportError("Fit.plot needs matplotlib: pip install './python[plot]'") from None
        stages = self.stages()
        if not -len(stages) <= stage < len(stages):
            raise ValueError(f"stage={stage}: the session has {len(stages)} model(s)")
        s = stages[stage]
        if fig is None:
            fig = plt.figure(figsize=(7, 6))
        ax, rx = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
        tau = s["tau"]
        ax.errorbar(tau, s["dev"], yerr=[s["dev"] - s["lo"], s["hi"] - s["dev"]], fmt="o", ms=3,
                    capsize=2, color="k", label="measured (68.3 %)")
        ax.plot(tau, s["model"], "-", lw=2, label="model")
        for name, dev in s["terms"].items():
            ok = dev > 0
            if ok.any():
                ax.plot(tau[ok], dev[ok], "--", lw=1, label=name)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_ylabel(f"Allan deviation [{self.unit}]" if self.unit else "Allan deviation")
        ax.set_title(f"{self.column}: {' + '.join(s['effects'])} — "
                     f"{'adequate' if s['adequate'] else 'not adequate'}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize="small")
        rx.axhspan(-1, 1, color="0.9")
        rx.plot(tau, s["residual"], "o-", ms=3, color="k")
        rx.axhline(0, color="0.5", lw=0.8)
        rx.set_xscale("log")
        rx.set_xlabel("τ [s]")
        rx.set_ylabel("residual [CI half-widths]")
        rx.grid(True, which="both", alpha=0.3)
        return fig


def _fmt(v) -> str:
    return "—" if v is None else f"{v:.4g}"


def _estimates(t: Term) -> str:
    """``name = value ± σ unit`` of each parameter of a term."""
    return ", ".join(f"{k} = {_fmt(v)} ± {_fmt(t.sigma.get(k))} {t.units.get(k, '')}".rstrip()
                     for k, v in t.params.items())


def fit(y, rate: Optional[float] = None, unit: Optional[str] = None, terms: Sequence[str] = (),
        add: Sequence[str] = (), effects: Sequence[Union[str, os.PathLike]] = (), auto: bool = False,
        max_steps: int = 6, tolerance: Optional[float] = None, column: Optional[str] = None,
        t=None, temp=None) -> Fit:
    """Fits the noise model to rate samples as ``imu-lab fit`` does and returns a :class:`Fit`.

    ``y``: a 1-D array of samples (e.g. deg/s) with ``rate`` in Hz, or a
    :class:`~pico_imu.Recording` with ``column`` (its ``t``, ``gap_before`` and ``temp``, its
    rate and unit are used). ``t`` (s) and ``temp`` (°C) may also be given beside an array.
    ``terms``: the start model's effects (default the five terms of Jaime et al. plus the
    resolution when the values sit on a lattice); ``add``: effects added one step each;
    ``auto``: walk diagnose → add → refit (at most ``max_steps``); ``effects``: paths of user
    effect files (TOML); ``tolerance``: a bias tolerance in ``unit`` for the recalibration
    period. Bad data (NaN with its index) and options raise ``ValueError`` naming them; an
    effect file that cannot be read, ``OSError``."""
    from . import Recording, _as_samples

    gap_before = None
    if isinstance(y, Recording):
        rec = y
        if column is None:
            raise ValueError("column: give the column of the recording to fit (e.g. column='gx')")
        data = rec[column]
        # Times given beside a recording replace its own, and their rate with them.
        if rate is None and t is None:
            rate = rec.rate_hz
        t = rec.t if t is None else t
        gap_before = rec.columns.get("gap_before")
        if temp is None:
            temp = rec.columns.get("temp")
        unit = rec.units.get(column, "") if unit is None else unit
    else:
        data = y
    x = _as_samples(data, "y")
    arr = lambda a, n: None if a is None else _as_samples(a, n)  # noqa: E731
    texts = []
    for p in effects:
        with open(p, encoding="utf-8") as f:
            texts.append((f.read(), os.fspath(p)))
    if isinstance(terms, str) or isinstance(add, str):
        raise ValueError("terms and add: give a list of effect names, e.g. add=['lowpass']")
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or not 1 <= max_steps <= 20:
        raise ValueError(f"max_steps={max_steps!r}: give a whole number from 1 to 20")
    native = _native.fit(x, None if rate is None else float(rate), unit or "", column or "y",
                         arr(t, "t"), arr(gap_before, "gap_before"), arr(temp, "temp"),
                         list(terms), list(add), texts, bool(auto), int(max_steps),
                         None if tolerance is None else float(tolerance))
    return Fit(native)


#: The contract's unit of each sensor column (the calibration file holds these).
_CONTRACT_UNITS = {"ax": "m/s²", "ay": "m/s²", "az": "m/s²", "gx": "deg/s", "gy": "deg/s",
                   "gz": "deg/s", "mx": "µT", "my": "µT", "mz": "µT", "temp": "°C"}


def _g(x: Optional[float], digits: int) -> str:
    """``x`` with ``digits`` significant digits; "n/a" where the JSON had none (a NaN, e.g. no
    noise floor from a single pose)."""
    return "n/a" if x is None else f"{x:.{digits}g}"


class Calibration:
    """The result of :func:`calibrate`: the last model of the calibration session.

    ``sensor``, ``unit`` (of the columns and of offsets/biases), ``model`` (effect names),
    ``params`` and ``sigma`` (1σ) by parameter (offsets in ``unit``; scale factors and
    misalignments dimensionless; the soft-iron matrix dimensionless), ``residual_rms`` and
    ``noise_floor`` (in ``unit``: what the model leaves and what the data's own noise would),
    ``adequate``, ``verdict``, ``missing`` (the effect the diagnosis names), ``explanation``,
    ``steps`` and ``stop`` of the walk, ``implausible`` (``None`` when the model is within the
    parts' datasheet bounds, else why :meth:`save` and an upload refuse it). :meth:`to_dict` is ``imu-lab calibrate --json``'s object;
    :meth:`save` writes the TOML calibration file the CLI and the device read."""

    def __init__(self, native):
        self._native = native
        d = json.loads(native.json())
        self.sensor: str = d["sensor"]
        self.unit: str = d["unit"]
        self.model: List[str] = d["model"]
        self.params: dict = d["params"]
        self.sigma: dict = d["sigma"]
        self.residual_rms: float = d["residual_rms"]
        self.noise_floor: float = d["noise_floor"]
        diag = d["diagnosis"]
        self.adequate: bool = diag["adequate"]
        self.verdict: str = diag["verdict"]
        self.missing: Optional[str] = diag["missing"]
        self.explanation: str = diag["explanation"]
        self.steps: List[dict] = d.get("steps") or []
        self.stop: Optional[str] = d.get("stop")
        self.implausible: Optional[str] = d.get("implausible")

    def to_dict(self) -> dict:
        """The JSON object ``imu-lab calibrate --json`` prints."""
        return json.loads(self._native.json())

    def save(self, path) -> None:
        """Writes (or updates this sensor's section of) the TOML calibration file at ``path``,
        as ``imu-lab calibrate --out`` does. The device must be able to hold it within the
        parts' datasheet bounds: otherwise ``ValueError`` naming the key, axis, value and bound,
        and nothing is written. A file that cannot be read or written raises ``OSError``."""
        existing = None
        if os.path.exists(path):
            with open(path, encoding="utf-8") as f:
                existing = f.read()
        try:
            text = self._native.toml(existing)
        except ValueError as e:
            raise ValueError(f"{os.fspath(path)}: {e}") from None
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)

    def __repr__(self) -> str:
        return (f"<Calibration {self.sensor} [{self.unit}]: {' + '.join(self.model)}; residual "
                f"{_g(self.residual_rms, 3)} {self.unit} against a noise floor of "
                f"{_g(self.noise_floor, 3)} {self.unit}; "
                f"{'adequate' if self.adequate else 'not adequate'}>")

    def _repr_html_(self) -> str:
        e = html.escape
        out = [f"<p><b>{e(self.sensor)}</b> [{e(self.unit)}]: {e(' + '.join(self.model))}; residual "
               f"RMS {_g(self.residual_rms, 4)} {e(self.unit)}, noise floor {_g(self.noise_floor, 4)} "
               f"{e(self.unit)}; {'ADEQUATE' if self.adequate else 'NOT ADEQUATE'}</p>"]
        if self.steps:
            rows = "".join(
                f"<tr><td>{i + 1}</td><td>{e(', '.join(s['added']))}</td>"
                f"<td>{s['rms_residual_before']:.4g} → {s['rms_residual_after']:.4g} {e(s['rms_unit'])}</td>"
                f"<td>{'yes' if s['adequate_before'] else 'no'} → {'yes' if s['adequate_after'] else 'no'}</td></tr>"
                for i, s in enumerate(self.steps)
            )
            out.append(f"<table><tr><th>step</th><th>added</th><th>residual RMS</th><th>adequate</th></tr>{rows}</table>")
        out.append(f"<p>{e(self.explanation)}</p>")
        return "".join(out)


def calibrate(sensor: str, samples, model: Sequence[str] = (), auto: bool = False,
              rate: Optional[float] = None, units: Optional[Dict[str, str]] = None,
              g: Optional[float] = None, field: Optional[float] = None, window: float = 1.0,
              threshold_k: float = 6.0, min_static: float = 1.5, saturation: Optional[float] = None,
              blocks: int = 50, max_steps: int = 4, part: Optional[str] = None) -> Calibration:
    """Calibrates ``sensor`` (``"accel"``, ``"gyro"``, ``"mag"``) as ``imu-lab calibrate`` does
    and returns a :class:`Calibration`.

    ``samples``: a :class:`~pico_imu.Recording` (its rate, gaps and units are used) or a dict of
    column name → array (``ax ay az`` m/s², ``gx gy gz`` deg/s, ``mx my mz`` µT, ``temp`` °C; or
    other units given in ``units``) with ``rate`` in Hz. ``model``: effect names (default
    offset,scale | bias | hard_iron); ``auto``: walk diagnose → add → refit (at most
    ``max_steps``). ``g`` and ``field`` in the columns' unit; ``window`` and ``min_static`` in
    s; ``threshold_k`` a multiple of the at-rest variance; ``saturation`` in deg/s; ``blocks``
    for the gyro at rest. ``part``: the part the recording was made with (``"QMC5883L"`` or
    ``"HMC5883L"`` for the magnetometer, ``"MPU-6050"`` otherwise; default: the firmware's),
    whose datasheet bounds judge the fit and which ``save`` writes into the file. Bad data (a
    non-finite sample with its row) and options raise ``ValueError`` naming them."""
    from . import Recording, _as_samples

    if isinstance(samples, Recording):
        cols, u = samples.columns, dict(samples.units)
        rate = samples.rate_hz if rate is None else rate
        segments = list(samples.segments)
    elif isinstance(samples, dict):
        cols, u = samples, {}
        segments = None
    else:
        raise ValueError("samples: give a Recording (pico_imu.read_csv) or a dict of column → array")
    if rate is None:
        raise ValueError("rate: give the sample rate in Hz")
    u.update(units or {})
    wanted = {"accel": ["ax", "ay", "az"], "gyro": ["gx", "gy", "gz", "ax", "ay", "az", "temp"],
              "mag": ["mx", "my", "mz"]}.get(sensor)
    if wanted is None:
        raise ValueError(f"sensor={sensor!r}: expected \"accel\", \"gyro\" or \"mag\"")
    if isinstance(model, str):
        raise ValueError("model: give a list of effect names, e.g. model=['hard_iron', 'soft_iron']")
    for k in wanted[:3]:
        if k not in cols:
            raise ValueError(f"samples: column {k} missing (columns: {', '.join(cols)})")
    arrays = {k: _as_samples(cols[k], k) for k in wanted if k in cols}
    n = len(next(iter(arrays.values()))) if arrays else 0
    if segments is None:
        segments = [(0, n)]
    for name, v in (("window", window), ("threshold_k", threshold_k), ("min_static", min_static)):
        if not isinstance(v, (int, float, np.integer, np.floating)) or isinstance(v, bool):
            raise ValueError(f"{name}={v!r}: give a number")
    for name, v in (("blocks", blocks), ("max_steps", max_steps)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ValueError(f"{name}={v!r}: give a whole number")
    if part is not None and not isinstance(part, str):
        raise ValueError(f"part={part!r}: give the part's name, e.g. part='HMC5883L'")
    units_of = {k: u.get(k, _CONTRACT_UNITS.get(k, "")) for k in arrays}
    native = _native.calibrate(sensor, arrays, units_of, float(rate), segments, list(model),
                               None if g is None else float(g), None if field is None else float(field),
                               float(window), float(threshold_k), float(min_static),
                               None if saturation is None else float(saturation), int(blocks),
                               bool(auto), int(max_steps), part)
    return Calibration(native)
