"""pico_imu.calibrate: the session `imu-lab calibrate` runs; .to_dict() is the CLI's --json on the
same file, .save() writes the CLI's --out file, refusals name what they refuse."""
import subprocess

import numpy as np
import pytest

import pico_imu
from test_fit import same
from test_record import imu_lab, write


def sphere(rng, tmp_path, hard=None):
    """A magnetometer turned slowly over the sphere (a spiral pole to pole, random turns) through
    random soft iron and hard iron, with white noise, at 100 Hz; the contract's CSV."""
    n = int(rng.integers(1_500, 4_000))
    z = 2 * (np.arange(n) + 0.5) / n - 1
    phi = np.arange(n) * rng.uniform(0.03, 0.08)
    r = np.sqrt(1 - z * z)
    f = rng.uniform(25, 60)
    b = f * np.stack([r * np.cos(phi), r * np.sin(phi), z])
    s = np.eye(3) + rng.uniform(-0.08, 0.08, (3, 3))
    s = (s + s.T) / 2
    h = rng.uniform(-30, 30, 3) if hard is None else hard
    m = s @ b + h[:, None] + rng.uniform(0.05, 0.3) * rng.normal(size=(3, n))
    p = tmp_path / "sphere.csv"
    write(p, np.arange(n) / 100.0, {"mx": m[0], "my": m[1], "mz": m[2]})
    return p


def cli(p, *flags):
    out = subprocess.run([imu_lab(), "calibrate", "mag", str(p), "--json", *flags],
                         check=True, capture_output=True, text=True)
    import json
    return json.loads(out.stdout)


@pytest.mark.parametrize("auto", [False, True])
def test_to_dict_and_save_are_the_clis(rng, tmp_path, auto):
    p = sphere(rng, tmp_path)
    cli_toml = tmp_path / "cli.toml"
    flags = ["--auto"] if auto else ["--model", "hard_iron,soft_iron"]
    c_json = cli(p, *flags, "--out", str(cli_toml))
    rec = pico_imu.read_csv(p)
    c = pico_imu.calibrate("mag", rec, auto=auto, model=[] if auto else ["hard_iron", "soft_iron"])
    same(c.to_dict(), c_json)
    assert c.sensor == "mag" and c.unit == "µT" and c.model == c_json["model"]
    assert c.residual_rms == c_json["residual_rms"] and c.adequate == c_json["diagnosis"]["adequate"]
    assert c.implausible is None and c_json["implausible"] is None
    if auto:
        assert len(c.steps) == len(c_json["steps"]) and c.stop == c_json["stop"]
        assert c._repr_html_().count("<tr>") == len(c.steps) + 1 if c.steps else True
    py_toml = tmp_path / "py.toml"
    c.save(py_toml)
    assert py_toml.read_text() == cli_toml.read_text()
    # a dict of arrays with its rate is the same session (the recording has no gap)
    d = pico_imu.calibrate("mag", {k: rec[k] for k in ("mx", "my", "mz")}, rate=rec.rate_hz,
                           auto=auto, model=[] if auto else ["hard_iron", "soft_iron"])
    same(d.to_dict(), c_json)


def test_an_implausible_calibration_is_refused_naming_key_axis_value_and_bound(rng, tmp_path):
    # hard iron beyond the QMC5883L's ±2 G (200 µT) range on a random axis
    axis = int(rng.integers(0, 3))
    hard = rng.uniform(-20, 20, 3)
    hard[axis] = rng.choice([-1, 1]) * rng.uniform(400, 900)
    p = sphere(rng, tmp_path, hard=hard)
    c = pico_imu.calibrate("mag", pico_imu.read_csv(p), model=["hard_iron"])
    assert c.params["hard_iron"][axis] == pytest.approx(hard[axis], rel=0.05)
    # the session says so before anything is saved, as the CLI's report does
    assert c.implausible is not None and f"mag.hard_iron[{axis}]" in c.implausible
    out = tmp_path / "cal.toml"
    with pytest.raises(ValueError, match=rf"mag\.hard_iron.*\[{axis}\].*refused, not written|refused, not written.*mag\.hard_iron.*\[{axis}\]"):
        c.save(out)
    assert not out.exists()
    # the CLI refuses it the same way
    r = subprocess.run([imu_lab(), "calibrate", "mag", str(p), "--model", "hard_iron", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode != 0 and "mag.hard_iron" in r.stderr and not out.exists()


def test_bad_inputs_are_named(rng, tmp_path):
    rec = pico_imu.read_csv(sphere(rng, tmp_path))
    cols = {k: rec[k].copy() for k in ("mx", "my", "mz")}
    i = int(rng.integers(0, len(cols["my"])))
    cols["my"][i] = np.nan
    with pytest.raises(ValueError, match=rf"column my row {i}: NaN is not a finite number"):
        pico_imu.calibrate("mag", cols, rate=100.0)
    with pytest.raises(ValueError, match="sensor='compass'"):
        pico_imu.calibrate("compass", rec)
    with pytest.raises(ValueError, match="model: .*hard_irn"):
        pico_imu.calibrate("mag", rec, model=["hard_irn"])
    with pytest.raises(ValueError, match="field 5000 µT: the field magnitude must be between"):
        pico_imu.calibrate("mag", rec, field=5000.0)
    with pytest.raises(ValueError, match="max_steps 0: give 1 to 20"):
        pico_imu.calibrate("mag", rec, auto=True, max_steps=0)
    with pytest.raises(ValueError, match="rate: give the sample rate"):
        pico_imu.calibrate("mag", {k: rec[k] for k in ("mx", "my", "mz")})
    with pytest.raises(ValueError, match="columns: my has 3 samples, mx has"):
        pico_imu.calibrate("mag", {"mx": rec["mx"], "my": rec["my"][:3], "mz": rec["mz"]}, rate=100.0)
    acc = {k: rng.normal(0, 0.01, 5_000) for k in ("ax", "ay", "az")}
    with pytest.raises(ValueError, match=r"g 30 m/s²: gravity must be between 9.7 and 9.9"):
        pico_imu.calibrate("accel", acc, rate=100.0, g=30.0)
    with pytest.raises(ValueError, match=r"window 0: must be between"):
        pico_imu.calibrate("accel", acc, rate=100.0, window=0.0)
    with pytest.raises(ValueError, match=r"column mx missing"):
        pico_imu.calibrate("mag", acc, rate=100.0)


def test_a_calibration_the_data_do_not_determine_shows_and_is_not_saved(rng, tmp_path):
    # one pose (the board never turned): offset and scale have no finite σ; a column of exact
    # zeros has no noise floor either (shown as n/a, where repr raised a TypeError)
    n = int(rng.integers(2_000, 6_000))
    g = rng.normal(0, 0.01, (3, n)) + np.array([[0.1], [-0.2], [9.8]])
    c = pico_imu.calibrate("accel", {"ax": g[0], "ay": g[1], "az": g[2]}, rate=100.0)
    assert not c.adequate and repr(c) and c._repr_html_()
    z = np.zeros(n)
    zeros = pico_imu.calibrate("accel", {"ax": z, "ay": z, "az": z}, rate=100.0)
    assert "n/a" in repr(zeros) and "n/a" in zeros._repr_html_()
    assert c.implausible is not None and "do not determine" in c.implausible
    out = tmp_path / "cal.toml"
    with pytest.raises(ValueError, match="refused, not written: the data do not determine offset.x"):
        c.save(out)
    assert not out.exists()


def test_the_recordings_part_judges_the_fit_and_is_saved(rng, tmp_path):
    # hard iron between the HMC5883L's ±0.88 G bound (18 µT) and its ±1.3 G one (60 µT) on a
    # random axis: within the bounds at its power-on gain, as the CLI's --part says too
    axis = int(rng.integers(0, 3))
    hard = rng.uniform(-10, 10, 3)
    hard[axis] = rng.choice([-1, 1]) * rng.uniform(25, 55)
    p = sphere(rng, tmp_path, hard=hard)
    rec = pico_imu.read_csv(p)
    c = pico_imu.calibrate("mag", rec, model=["hard_iron"], part="hmc5883l")
    c_json = cli(p, "--model", "hard_iron", "--part", "HMC5883L")
    same(c.to_dict(), c_json)
    assert c.to_dict()["judged_part"] == "HMC5883L" and c.implausible is None
    out = tmp_path / "cal.toml"
    c.save(out)
    text = out.read_text()
    assert 'part = "HMC5883L"' in text and "lsb_per_unit = 10.9" in text
    # without it the firmware's part is judged, and said to be assumed
    d = pico_imu.calibrate("mag", rec, model=["hard_iron"])
    assert d.to_dict()["judged_part"].startswith("QMC5883L (assumed")
    with pytest.raises(ValueError, match=r"part= BMI160.*QMC5883L, HMC5883L"):
        pico_imu.calibrate("mag", rec, part="BMI160")
    with pytest.raises(ValueError, match=r"part="):
        pico_imu.calibrate("mag", rec, part=5883)
