"""The device: a Pico running pico-imu's firmware on its USB serial port, or the emulated one
(``tcp:HOST:PORT``), through the same link code as ``imu-lab record`` and ``imu-lab device``
(the ``imu-link`` crate). See :class:`Device`."""
from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from typing import Dict, Optional, Sequence, Union

from . import _native
from . import Recording, Table

__all__ = ["Device", "DeviceTable"]


@dataclass
class DeviceTable(Table):
    """One channel's Allan table as the device computed it (its streaming engine's integer
    sums; deviation, EDF and 68.3 % bounds derived on the host as ``imu-lab device tables``
    does). The :class:`Table` arrays — ``tau`` (s, m·τ0 with the sensor's measured period),
    ``m`` (samples), ``dev``, ``lo``, ``hi`` (OADEV and its bounds in ``unit``), ``n``
    (second differences summed), ``alpha`` (noise exponent used for the EDF), ``edf``,
    ``stride`` (samples between differences) — and the table's facts: ``channel``,
    ``snapshot`` (the round, one instant for every channel), ``t_s`` (device time of the
    snapshot, s since boot), ``tau0_s`` (the sensor's measured sample period, s), ``scale``
    (``unit`` per count), ``pushed`` (samples since the last Allan reset), ``gaps`` (gaps
    marked since then)."""

    channel: str = ""
    snapshot: int = 0
    t_s: float = 0.0
    tau0_s: float = 0.0
    scale: float = 0.0
    pushed: int = 0
    gaps: int = 0

    def __str__(self) -> str:
        head = (f"{self.channel} [{self.unit}]: τ0 = {self.tau0_s * 1e6:.3f} µs (measured), "
                f"{self.pushed} samples, {self.gaps} gaps; snapshot {self.snapshot} at "
                f"{self.t_s:.3f} s device time")
        return head + "\n" + super().__str__()


class Device:
    """A link to a device running pico-imu's firmware: ``port`` is a serial device (a Pico W's
    USB port, e.g. ``/dev/ttyACM0``, ``COM5``) or ``tcp:HOST:PORT`` (the emulator,
    ``node sim/src/cli.js run --elf … --port-file F``). ``timeout`` (s) is how long a request
    waits for its answer. Opening asks the device who it is (:attr:`identity`).

    A context manager (``with Device(port) as dev: ...`` closes it); :meth:`close` is
    idempotent. While a call waits for the device the GIL is released; Ctrl-C interrupts a
    :meth:`record` within 0.1 s (``KeyboardInterrupt``, the stream switched off first).

    Errors: ``ValueError`` for a bad argument and for a calibration refused (by the host's
    checks before anything is sent, naming key, axis, value and bound, or by the device);
    ``TimeoutError`` (an ``OSError``) when the device does not answer in time; ``OSError``
    for a port that cannot be opened, a link that fails or a closed device; every message
    names the port."""

    def __init__(self, port: str, timeout: float = 3.0):
        if not isinstance(port, str):
            raise ValueError(f"port={port!r}: give a serial device path (str) or 'tcp:HOST:PORT'")
        self._dev = _native.NativeDevice(port, float(timeout))
        self._warn()

    def _warn(self) -> None:
        for w in self._dev.take_warnings():
            warnings.warn(f"{self.port}: {w}", RuntimeWarning, stacklevel=3)

    def __enter__(self) -> "Device":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self.closed else "open"
        return f"<pico_imu.Device {self.port} ({state}; firmware {self.identity['firmware']})>"

    @property
    def port(self) -> str:
        """The port given when opening."""
        return self._dev.port

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return self._dev.closed

    def close(self) -> None:
        """Closes the link (a second call does nothing). Later calls raise ``OSError``."""
        self._dev.close()

    @property
    def identity(self) -> dict:
        """Who the device is, as it answered when opened: ``protocol`` (version), ``firmware``,
        ``board``, ``imu_rate_hz`` and ``mag_rate_hz`` (Hz), ``allan_overlap`` (P),
        ``allan_levels`` and ``allan_levels_mag`` (octave levels of its Allan engines)."""
        return self._dev.identity()

    @property
    def requests_sent(self) -> int:
        """Requests written to the device since opening (a refused upload adds none)."""
        return self._dev.requests_sent

    def status(self) -> dict:
        """The device's counters and health now: ``uptime_s`` (s); ``imu`` and ``mag``, each
        ``state`` (ok, missing, stalled, unknown), ``samples_taken``, ``samples_lost`` (with
        the IMU's ``fifo_overflows``) and ``period_s`` (the sample period its clock measures,
        s; None before it is measured); ``i2c_errors``, ``bus_faults``, ``bus_recoveries``,
        ``host_frames_rejected``, ``frames_unsent`` (counts since boot); ``cpu_load_percent``
        (%); ``temperature_c`` (°C, None before a sample carried one); ``calibration`` (where
        the corrections in use came from, in words); ``mode`` (off, calibrated, raw)."""
        s = self._dev.status()
        self._warn()
        return s

    def info(self) -> dict:
        """Everything about the device and the link in one dict: ``port``, ``identity``
        (:attr:`identity`: protocol version, firmware, rates), ``status`` (:meth:`status`: the
        counters since boot, losses and their causes' counters — FIFO overflows, I2C errors,
        bus faults), ``calibration`` (:meth:`calibration`: where it came from and the parts and
        ranges it was fitted for; the protocol names the parts nowhere else), and ``link``:
        ``requests_sent`` and ``frames_rejected`` (frames from the device skipped as corrupt or
        unknown, with their causes given as ``RuntimeWarning`` s as they happen). A
        recording's losses by cause are in its ``losses`` (:meth:`record`)."""
        status = self.status()
        calibration = self.calibration()
        return {
            "port": self.port,
            "identity": self.identity,
            "status": status,
            "calibration": calibration,
            "link": {"requests_sent": self._dev.requests_sent,
                     "frames_rejected": self._dev.frames_rejected},
        }

    def record(self, seconds: float, raw: bool = False) -> Recording:
        """Records ``seconds`` of device time (s, > 0) from the device's stream: the rows of
        ``imu-lab record --seconds S [--raw]``, as a :class:`~pico_imu.Recording` (which
        :func:`~pico_imu.fit` and :func:`~pico_imu.calibrate` take):

        * ``columns``: ``t`` (s since boot, the sensor's own sample clock from the device's
          stamps), ``ax ay az`` (m/s²), ``gx gy gz`` (deg/s), ``mx my mz`` (µT, the latest
          200 Hz sample held), ``temp`` (°C), ``gap_before`` (IMU samples missing right before
          the row), ``q0 … q3`` (the device's attitude quaternion, body → NED), ``roll``,
          ``pitch``, ``heading`` (deg), ``ahrs`` (0 converging, 1 tracking, 2/3 magnetic
          disturbance); NaN where the device had no value; ``units`` names each;
        * ``rate_hz`` (Hz, from the stamps), ``segments`` (row ranges between gaps),
          ``timing``;
        * ``losses``: for ``imu`` and ``mag``, samples ``received`` and ``lost``, the device's
          ``causes`` (cause → samples) and those lost on the ``link``; ``summary`` (the line
          ``imu-lab record`` prints); ``events`` (the device's events, as text);
          ``device_status`` (:meth:`status` after the recording, None if it did not answer).

        ``raw=True`` records the uncorrected counts converted with the nominal sensitivities
        (what calibration fitting needs). ``Recording.to_csv(path)`` writes the CSV
        ``imu-lab record`` writes. Ctrl-C raises ``KeyboardInterrupt`` within 0.1 s, after
        switching the stream off."""
        if isinstance(seconds, bool) or not isinstance(seconds, (int, float)):
            raise ValueError(f"seconds={seconds!r}: a positive number of seconds")
        d = self._dev.record(float(seconds), bool(raw))
        self._warn()
        return Recording(path=f"{self.port} ({'raw' if raw else 'calibrated'} recording)",
                         columns=d["columns"], units=d["units"], t=d["t"], rate_hz=d["rate_hz"],
                         segments=[tuple(s) for s in d["segments"]], timing=d["timing"],
                         losses=d["losses"], summary=d["summary"], events=d["events"],
                         device_status=d["device_status"], raw=bool(raw))

    def tables(self, channels: Optional[Sequence[str]] = None, timeout: float = 30.0) -> Dict[str, DeviceTable]:
        """The device's Allan tables, all of one snapshot (one instant), for ``channels``
        (``ax ay az gx gy gz mx my mz temp``; all ten by default), waiting at most ``timeout``
        s for them: channel → :class:`DeviceTable` (overlapping ADEV at octave τ with EDF and
        68.3 % bounds, as ``imu-lab device tables`` shows them). The tables cover every sample
        since the last Allan reset (:meth:`reset_allan`, a calibration upload, or boot)."""
        if isinstance(channels, str):
            channels = [c for c in channels.replace(",", " ").split() if c]
        got = self._dev.tables(list(channels or []), float(timeout))
        self._warn()
        out = {}
        for d in got:
            out[d["channel"]] = DeviceTable(
                stat="oadev", unit=d["unit"], tau=d["tau"], m=d["m"], dev=d["dev"], n=d["n"],
                alpha=d["alpha"], edf=d["edf"], lo=d["lo"], hi=d["hi"], stride=d["stride"],
                channel=d["channel"], snapshot=d["snapshot"], t_s=d["t_s"], tau0_s=d["tau0_s"],
                scale=d["scale"], pushed=d["pushed"], gaps=d["gaps"])
        return out

    def reset_allan(self) -> None:
        """Forgets the device's Allan state: every channel's engine starts again."""
        self._dev.reset_allan()

    def calibration(self) -> dict:
        """The calibration in use: ``blob`` (bytes, what the device stores), ``source``
        (identity, flash, host), ``status`` (in words, with a stored record's fault),
        ``fitted_for`` (parts and full-scale ranges: ``accel_range_g`` g, ``gyro_range_dps``
        deg/s, ``mag_range_gauss`` G; None for identity) and the corrections ``accel``,
        ``gyro``, ``mag``: out = ``matrix``·raw − ``offset_lsb`` in nominal LSB (the gyro's
        temperature term ``kappa``, LSB per temperature LSB, about ``t_ref_lsb``)."""
        return self._dev.calibration()

    def upload(self, calibration: Union[object, str, "os.PathLike[str]", bytes, bytearray],
               persist: bool = True) -> dict:
        """Uploads a calibration after the checks ``imu-lab device calibrate --upload`` makes:
        a :class:`~pico_imu.Calibration` (the file its ``save`` writes to a new path: this
        sensor's section, identity for the others), a path to a TOML calibration file or to a
        ``.bin`` blob, or the blob's bytes. A calibration the device could not hold within the
        parts' datasheet bounds is refused with a ``ValueError`` naming key, axis, value and
        bound, and nothing is sent (:attr:`requests_sent` unchanged). ``persist``: also write
        it to the device's flash (sampling pauses a moment); otherwise it is lost at a reset.
        Returns the device's :meth:`calibration` read back, whose ``blob`` is the one sent
        (checked; an ``OSError`` otherwise). The device resets its Allan state."""
        from .lab import Calibration

        if isinstance(calibration, Calibration):
            what = f"the {calibration.sensor} calibration"
            try:
                content = calibration._native.toml(None).encode()
            except ValueError as e:
                raise ValueError(f"{what}: {e}; nothing sent to {self.port}") from None
            is_blob = False
        elif isinstance(calibration, (bytes, bytearray)):
            what, content, is_blob = "the blob", bytes(calibration), True
        elif isinstance(calibration, (str, os.PathLike)):
            what = os.fspath(calibration)
            with open(what, "rb") as f:
                content = f.read()
            is_blob = what.endswith(".bin")
        else:
            raise ValueError(f"calibration: a pico_imu.Calibration, a path (.toml or .bin) or the blob's "
                             f"bytes, not {type(calibration).__name__}")
        out = self._dev.upload(content, is_blob, bool(persist), what)
        self._warn()
        return out

    def orientation(self) -> dict:
        """The attitude filter's settings: ``declination_deg`` (deg, east positive, added to
        the magnetic heading), the expected field ``field_ut`` (µT) and ``dip_deg`` (deg,
        positive down; both None while the device learns them) and ``learnt`` (True: learnt by
        the device). Held in the device's RAM: a reset forgets them."""
        return self._dev.orientation()

    def set_orientation(self, declination_deg: Optional[float] = None, field_ut: Optional[float] = None,
                        dip_deg: Optional[float] = None, learn: bool = False) -> dict:
        """Sets the declination (deg within ±180) and the expected field (``field_ut`` µT
        within 1–1000 with ``dip_deg`` within ±90: outside ±10 % of it or ±5° of dip the device
        reports a magnetic disturbance), or ``learn=True`` to let the device learn the field;
        what is not given is kept (``imu-lab device orientation``). Returns
        :meth:`orientation` as the device then reports it. A value out of range is a
        ``ValueError`` and nothing is sent."""
        return self._dev.set_orientation(declination_deg, field_ut, dip_deg, bool(learn))

    @property
    def declination(self) -> float:
        """The declination, deg (east positive), added to the heading."""
        return self.orientation()["declination_deg"]

    @declination.setter
    def declination(self, deg: float) -> None:
        self.set_orientation(declination_deg=float(deg))
