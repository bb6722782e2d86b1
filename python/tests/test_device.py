"""`pico_imu.Device` against the emulated Pico: the firmware's release ELF on rp2040js with the
register-level sensor models (sim/), fed a stream of random constants and white noise written
here. One emulator serves the module (emulated time runs only while a test is connected).

The emulator needs PICO_IMU_ELF (the firmware, `cargo xtask firmware`) and PICO_IMU_SIM (sim/
with `npm ci` done); `cargo xtask test` sets both where node ≥ 20 is installed (CI). Without
them these tests skip, saying so; the argument and port checks at the end run everywhere."""
import _thread
import math
import os
import signal
import socket
import subprocess
import threading
import time

import numpy as np
import pytest

import pico_imu
from pico_imu import Device

ELF = os.environ.get("PICO_IMU_ELF")
SIM = os.environ.get("PICO_IMU_SIM")
needs_emulator = pytest.mark.skipif(
    not (ELF and SIM and os.path.isfile(ELF) and os.path.isfile(os.path.join(SIM or "", "src", "cli.js"))),
    reason="the emulated Pico needs PICO_IMU_ELF (the firmware ELF: cargo xtask firmware) and "
           "PICO_IMU_SIM (sim/ after npm ci); `cargo xtask test` sets both when node >= 20 is installed")

#: The CSV header `imu-lab record` writes.
HEADER = "t,ax,ay,az,gx,gy,gz,mx,my,mz,temp,gap_before,q0,q1,q2,q3,roll,pitch,heading,ahrs"
#: One gyro count at ±250 deg/s (MPU-6050: 131 LSB per deg/s), deg/s.
GYRO_LSB = 1.0 / 131.0


@pytest.fixture(scope="module")
def emu(tmp_path_factory):
    """The emulator on a random stream: a dict with `port` (tcp:127.0.0.1:P) and the stream's
    constants: gyro offsets and white-noise σ (deg/s), accel (m/s²), mag (µT), temp (°C)."""
    if not (ELF and SIM):
        pytest.skip("PICO_IMU_ELF and PICO_IMU_SIM not set")
    key = int(os.environ.get("PICO_IMU_TEST_KEY", np.random.SeedSequence().entropy % 2**32))
    print(f"PICO_IMU_TEST_KEY={key}")
    rng = np.random.default_rng(key)
    d = tmp_path_factory.mktemp("emu")
    rows = 30_000  # 30 s at 1 kHz; the models wrap around at its end
    tilt = rng.uniform(-0.15, 0.15, 2)  # rad
    g = 9.80665
    s = {
        "gyro": rng.uniform(-3.0, 3.0, 3),
        "gyro_sigma": rng.uniform(0.03, 0.15, 3),
        "accel": np.array([g * math.sin(tilt[0]), g * math.sin(tilt[1]) * math.cos(tilt[0]),
                           g * math.cos(tilt[1]) * math.cos(tilt[0])]),
        "mag": np.array([rng.uniform(15, 30), rng.uniform(-10, 10), rng.uniform(30, 50)]),
        "temp": rng.uniform(15.0, 35.0),
        "key": key,
    }
    t = np.arange(rows) / 1000.0
    cols = [t]
    cols += [np.full(rows, a) + rng.normal(0, 0.01, rows) for a in s["accel"]]
    cols += [np.full(rows, o) + rng.normal(0, sd, rows) for o, sd in zip(s["gyro"], s["gyro_sigma"])]
    cols += [np.full(rows, m) + rng.normal(0, 0.1, rows) for m in s["mag"]]
    cols += [np.full(rows, s["temp"])]
    stream = d / "stream.csv"
    np.savetxt(stream, np.column_stack(cols), delimiter=",", fmt="%.6f",
               header="t,ax,ay,az,gx,gy,gz,mx,my,mz,temp", comments="")
    port_file = d / "port"
    log = open(d / "emulator.log", "w")
    proc = subprocess.Popen(
        ["node", os.path.join(SIM, "src", "cli.js"), "run", "--elf", ELF, "--seconds", "3600",
         "--stream", str(stream), "--port-file", str(port_file), "--quiet"],
        stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT)
    try:
        start = time.monotonic()
        while not (port_file.exists() and port_file.read_text().strip()):
            if proc.poll() is not None:
                pytest.fail(f"the emulator exited ({proc.returncode}) before opening its port: "
                            f"{(d / 'emulator.log').read_text()[-2000:]}")
            if time.monotonic() - start > 300:
                pytest.fail("the emulator did not open its USB port within 300 s")
            time.sleep(0.1)
        s["port"] = f"tcp:127.0.0.1:{int(port_file.read_text())}"
        yield s
    finally:
        proc.terminate()
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        log.close()


def _counts(y, scale):
    return np.round(np.asarray(y) / scale)


@needs_emulator
def test_identity_status_and_info(emu):
    with Device(emu["port"], timeout=5.0) as dev:
        ident = dev.identity
        assert ident["firmware"].startswith("pico-imu")
        assert (ident["imu_rate_hz"], ident["mag_rate_hz"]) == (1000, 200)
        assert ident["protocol"] >= 1 and ident["allan_overlap"] == 8
        info = dev.info()
        st = info["status"]
        assert st["uptime_s"] > 0
        assert st["imu"]["samples_lost"] == 0 and st["mag"]["samples_lost"] == 0
        assert st["calibration"].startswith("identity"), st["calibration"]
        assert info["calibration"]["source"] == "identity" and info["calibration"]["fitted_for"] is None
        assert info["link"]["requests_sent"] >= 3 and info["link"]["frames_rejected"] == 0
        assert repr(dev).startswith(f"<pico_imu.Device {emu['port']} (open")
    assert dev.closed
    with pytest.raises(OSError, match="closed"):
        dev.status()


@needs_emulator
def test_record_rows_rate_and_values_follow_the_stream(emu, tmp_path):
    rng = np.random.default_rng(emu["key"] + 1)
    seconds = float(rng.uniform(1.5, 3.0))
    with Device(emu["port"]) as dev:
        rec = dev.record(seconds)
    n = len(rec.t)
    # The recording ends with the first batch (25 samples) reaching `seconds` of device time.
    assert seconds * 1000 * 0.98 <= n <= seconds * 1000 * 1.02 + 30, (n, seconds)
    assert rec.rate_hz == pytest.approx(1000.0, rel=0.01)
    assert np.all(np.diff(rec.t) > 0) and np.all(rec["gap_before"] == 0)
    assert rec.losses["imu"] == {"received": n, "lost": 0, "causes": {}, "link": 0}
    # The magnetometer's samples over the rows' span (200 Hz), and those of batches that carry
    # no IMU row yet (right after boot the IMU's FIFO starts later).
    mags = rec.losses["mag"]["received"]
    span = rec.t[-1] - rec.t[0]
    assert span * 200 * 0.99 - 3 <= mags <= span * 200 * 1.01 + 30, (mags, span)
    assert rec.summary.startswith(f"{n} rows over ")
    assert rec.segments == [(0, n)] and rec.raw is False
    assert rec.device_status["mode"] == "off"
    assert list(rec.columns) == HEADER.split(",")
    assert rec.units["gx"] == "deg/s" and rec.units["ax"] == "m/s²" and rec.units["mx"] == "µT"
    # Values: the stream's constants through the sensor models (a one-pole filter, the counts).
    for k, c in enumerate(("gx", "gy", "gz")):
        y = rec[c]
        sd = emu["gyro_sigma"][k]
        # Filtered white noise averages like n/3 independent samples at most; one count of
        # rounding on top.
        tol = 5 * sd / math.sqrt(n / 3) + GYRO_LSB
        assert abs(y.mean() - emu["gyro"][k]) < tol, (c, y.mean(), emu["gyro"][k], tol)
        # The sensor's low-pass filter takes some of the white noise, never adds.
        assert 0.4 * sd < y.std() < 1.1 * sd + GYRO_LSB, (c, y.std(), sd)
    for k, c in enumerate(("ax", "ay", "az")):
        assert abs(rec[c].mean() - emu["accel"][k]) < 0.01, (c, rec[c].mean(), emu["accel"][k])
    for k, c in enumerate(("mx", "my", "mz")):
        assert abs(rec[c].mean() - emu["mag"][k]) < 0.2, (c, rec[c].mean(), emu["mag"][k])
    assert abs(np.nanmean(rec["temp"]) - emu["temp"]) < 0.05
    # The CSV `imu-lab record` writes, read back by read_csv.
    path = tmp_path / "rec.csv"
    rec.to_csv(path)
    assert path.read_text().splitlines()[0] == HEADER
    back = pico_imu.read_csv(path)
    assert np.max(np.abs(back.t - rec.t)) <= 0.5e-6
    for c in ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp", "gap_before"):
        np.testing.assert_allclose(back[c], rec[c], rtol=1e-6, atol=1e-9, err_msg=c)
    assert back.rate_hz == pytest.approx(rec.rate_hz, rel=1e-6)
    # Fit takes it as it takes a file.
    f = pico_imu.fit(rec, column="gx")
    assert f.table is not None and len(f.terms) > 0


@needs_emulator
def test_tables_match_the_host_engine_on_the_same_stream(emu):
    with Device(emu["port"]) as dev:
        dev.reset_allan()
        rec = dev.record(2.0)
        tabs = dev.tables(["gx", "az"], timeout=20.0)
    assert sorted(tabs) == ["az", "gx"]
    n = len(rec.t)
    for c, t in tabs.items():
        assert t.unit == rec.units[c] and t.gaps == 0
        assert len({(x.snapshot, x.t_s) for x in tabs.values()}) == 1, "one snapshot"
        # The device's engine ate every sample since the reset: the recording's and a few
        # hundred ms around it (the stream's start and stop, the table request).
        assert n <= t.pushed <= n + 1000, (c, n, t.pushed)
        # τ grid: octaves of the measured period, the period the recording's stamps show.
        assert t.tau0_s == pytest.approx(1.0 / rec.rate_hz, rel=1e-4)
        np.testing.assert_array_equal(t.m, 2 ** np.arange(len(t.m)))
        np.testing.assert_allclose(t.tau, t.m * t.tau0_s, rtol=1e-12)
        # The host's streaming engine (the same integer engine, overlap 8) on as many samples
        # counts the same differences at every level.
        host = pico_imu.Stream(rate=1.0 / t.tau0_s, scale=t.scale, unit=t.unit)
        host.push(np.random.default_rng(emu["key"]).integers(-1000, 1000, t.pushed).astype(float))
        h = host.table("oadev")
        k = min(len(h.m), len(t.m))
        assert k >= 6
        np.testing.assert_array_equal(t.m[:k], h.m[:k])
        np.testing.assert_array_equal(t.n[:k], h.n[:k])
        np.testing.assert_array_equal(t.stride[:k], h.stride[:k])
        # The deviations: the device's sums against the host engine on the recording's counts
        # (most of the same samples), at short τ where both are tight: within both 68.3 %
        # half-widths, three times over.
        host = pico_imu.Stream(rate=1.0 / t.tau0_s, scale=t.scale, unit=t.unit)
        host.push(_counts(rec[c], t.scale))
        h = host.table("oadev")
        for j in range(4):
            both = math.hypot((t.hi[j] - t.lo[j]) / 2, (h.hi[j] - h.lo[j]) / 2)
            assert abs(t.dev[j] - h.dev[j]) < 3 * both, (c, j, t.dev[j], h.dev[j], both)
            assert t.lo[j] < t.dev[j] < t.hi[j] and t.edf[j] > 0
        if c == "gx":
            # White noise at the shortest τ: the filtered σ of the stream, at most the stream's.
            assert t.dev[0] < emu["gyro_sigma"][0] * 1.1 + GYRO_LSB
    assert "gx [deg/s]" in str(tabs["gx"])


@needs_emulator
def test_upload_a_fitted_gyro_bias_and_the_device_applies_it(emu):
    with Device(emu["port"]) as dev:
        before = dev.calibration()
        assert before["source"] == "identity" and before["fitted_for"] is None
        raw = dev.record(1.5, raw=True)
        assert raw.raw is True
        cal = pico_imu.calibrate("gyro", raw)
        bias = np.array(cal.params["bias"])
        assert np.all(np.abs(bias - emu["gyro"]) < 0.05), (bias, emu["gyro"])
        sent = dev.requests_sent
        answer = dev.upload(cal, persist=True)
        assert dev.requests_sent == sent + 2  # the upload and the read-back
        assert answer["source"] == "flash"
        assert answer["fitted_for"]["gyro_range_dps"] == 250
        # The device's corrections: its offset is the bias in counts (131 LSB per deg/s).
        np.testing.assert_allclose(answer["gyro"]["offset_lsb"], bias * 131.0, atol=0.01)
        again = dev.calibration()
        assert again["blob"] == answer["blob"] and again["blob"] != before["blob"]
        assert dev.status()["calibration"] == "from flash"
        # Corrected samples now: the gyro reads zero on average.
        rec = dev.record(1.0)
        for k, c in enumerate(("gx", "gy", "gz")):
            tol = 5 * emu["gyro_sigma"][k] / math.sqrt(len(rec.t) / 3) + 2 * GYRO_LSB + 0.05
            assert abs(rec[c].mean()) < tol, (c, rec[c].mean(), tol)
        # Back to identity, by its blob.
        back = dev.upload(before["blob"], persist=True)
        assert back["blob"] == before["blob"]


@needs_emulator
def test_an_implausible_calibration_is_refused_and_nothing_sent(emu, tmp_path):
    rng = np.random.default_rng(emu["key"] + 2)
    axis = int(rng.integers(0, 3))
    value = float(rng.choice([rng.uniform(1.15, 1.8), rng.uniform(0.3, 0.85)]))
    scale = [1.0, 1.0, 1.0]
    scale[axis] = value
    toml = f"""version = 1
[accel]
part = "MPU-6050"
lsb_per_unit = {8192.0 / 9.80665!r}
offset = [0.0, 0.0, 0.0]
scale = {scale!r}
misalignment_deg = [0.0, 0.0, 0.0]
[gyro]
part = "MPU-6050"
lsb_per_unit = 131.0
bias = [0.0, 0.0, 0.0]
temp_coeff = [0.0, 0.0, 0.0]
temp_ref = 25.0
temp_lsb_per_c = 340.0
temp_offset_c = 36.53
[mag]
part = "QMC5883L"
lsb_per_unit = 120.0
hard_iron = [0.0, 0.0, 0.0]
soft_iron = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
"""
    path = tmp_path / "bad.toml"
    path.write_text(toml)
    with Device(emu["port"]) as dev:
        blob = dev.calibration()["blob"]
        sent = dev.requests_sent
        with pytest.raises(ValueError) as e:
            dev.upload(path)
        msg = str(e.value)
        assert f"accel.scale[{axis}] = {value:.4g}"[:16] in msg and "0.91–1.09" in msg, msg
        assert str(path) in msg and "nothing uploaded" in msg
        # A corrupt blob (one flipped bit) is refused the same way.
        bad = bytearray(blob)
        bad[int(rng.integers(0, len(bad)))] ^= 1 << int(rng.integers(0, 8))
        with pytest.raises(ValueError, match="refused, nothing uploaded"):
            dev.upload(bytes(bad))
        with pytest.raises(ValueError, match="calibration: a pico_imu.Calibration"):
            dev.upload(42)
        assert dev.requests_sent == sent, "nothing was sent"
        assert dev.calibration()["blob"] == blob
        # The same file with a plausible scale is taken.
        path.write_text(toml.replace(repr(scale), repr([1.0, 1.0, 1.0])))
        assert dev.upload(path, persist=False)["source"] == "host"
        assert dev.upload(blob)["blob"] == blob


@needs_emulator
def test_orientation_settings(emu):
    rng = np.random.default_rng(emu["key"] + 3)
    decl = round(float(rng.uniform(-30, 30)), 2)
    with Device(emu["port"]) as dev:
        dev.declination = decl
        assert dev.declination == pytest.approx(decl, abs=0.005)
        field, dip = round(float(rng.uniform(30, 60)), 3), round(float(rng.uniform(-70, 70)), 2)
        o = dev.set_orientation(field_ut=field, dip_deg=dip)
        assert o["field_ut"] == pytest.approx(field, abs=1e-3) and o["dip_deg"] == pytest.approx(dip, abs=0.005)
        assert o["learnt"] is False and o["declination_deg"] == pytest.approx(decl, abs=0.005)
        sent = dev.requests_sent
        for kw, says in [({"declination_deg": 200.0}, "declination 200"),
                         ({"field_ut": 5000.0, "dip_deg": 10.0}, "field 5000"),
                         ({"field_ut": 50.0}, "give both"),
                         ({"field_ut": 50.0, "dip_deg": 10.0, "learn": True}, "not both")]:
            with pytest.raises(ValueError, match=says):
                dev.set_orientation(**kw)
        assert dev.requests_sent == sent, "refused before anything was sent"
        assert dev.set_orientation(declination_deg=0.0, learn=True)["field_ut"] is None


@pytest.fixture
def python_sigint():
    """Python's own Ctrl-C handler for the test, whatever the process inherited: a runner
    started in the background of a shell without job control has SIGINT ignored, and then
    `_thread.interrupt_main` does nothing."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@needs_emulator
def test_ctrl_c_interrupts_a_long_recording_and_the_gil_is_free(emu, python_sigint):
    ticks = [0]
    stop = threading.Event()

    def count():
        while not stop.is_set():
            ticks[0] += 1

    with Device(emu["port"]) as dev:
        counter = threading.Thread(target=count)
        counter.start()
        timer = threading.Timer(1.0, _thread.interrupt_main)
        start = time.monotonic()
        timer.start()
        try:
            with pytest.raises(KeyboardInterrupt):
                dev.record(600.0)
            elapsed = time.monotonic() - start
        finally:
            stop.set()
            counter.join()
            timer.cancel()
        assert elapsed < 5.0, elapsed
        # The stream was switched off, and the device still answers.
        assert dev.status()["mode"] == "off"
    # Alone, the counter thread would have counted for `elapsed` s; with the GIL held by the
    # recording it would have had a few switch intervals per 0.1 s check.
    solo = [0]
    t0 = time.monotonic()
    while time.monotonic() - t0 < 0.2:
        solo[0] += 1
    rate_solo = solo[0] / 0.2
    assert ticks[0] > 0.3 * rate_solo * elapsed, (ticks[0], rate_solo, elapsed)


def test_a_dead_port_or_wrong_address_is_an_oserror_naming_it(tmp_path):
    # A port nothing listens on: connection refused.
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    free = s.getsockname()[1]
    s.close()
    with pytest.raises(OSError, match=f"tcp:127.0.0.1:{free}"):
        Device(f"tcp:127.0.0.1:{free}")
    missing = str(tmp_path / "ttyACM9")
    with pytest.raises(OSError, match=missing):
        Device(missing)
    # Something that listens but never answers: a TimeoutError (an OSError) after `timeout`.
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    port = f"tcp:127.0.0.1:{srv.getsockname()[1]}"
    start = time.monotonic()
    try:
        with pytest.raises(TimeoutError, match=port):
            Device(port, timeout=0.3)
    finally:
        srv.close()
    assert time.monotonic() - start < 3.0


@pytest.mark.parametrize("port,timeout,says", [
    ("tcp:127.0.0.1", 3.0, "tcp:HOST:PORT"),
    ("tcp::5000", 3.0, "tcp:HOST:PORT"),
    ("tcp:127.0.0.1:99999", 3.0, "tcp:HOST:PORT"),
    ("", 3.0, "port: empty"),
    ("tcp:127.0.0.1:5000", 0.0, "timeout=0"),
    ("tcp:127.0.0.1:5000", float("nan"), "timeout=NaN"),
    ("tcp:127.0.0.1:5000", -1.0, "timeout=-1"),
    ("tcp:127.0.0.1:5000", 1e300, "timeout=1e300: a positive number of seconds below 1e9$"),
])
def test_bad_arguments_to_open_are_valueerrors(port, timeout, says):
    with pytest.raises(ValueError, match=says):
        Device(port, timeout=timeout)
    with pytest.raises(ValueError, match="port="):
        Device(5000)


@needs_emulator
def test_bad_arguments_to_calls_are_valueerrors_and_send_nothing(emu):
    with Device(emu["port"]) as dev:
        sent = dev.requests_sent
        for bad in (0, -1.0, float("nan"), float("inf"), "2", True):
            with pytest.raises(ValueError, match="seconds"):
                dev.record(bad)
        with pytest.raises(ValueError, match="unknown channel `gq`"):
            dev.tables(["gx", "gq"])
        with pytest.raises(ValueError, match="timeout=-1"):
            dev.tables(timeout=-1.0)
        assert dev.requests_sent == sent
