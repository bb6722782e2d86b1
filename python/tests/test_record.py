"""read_csv: the recording contract into numpy arrays, and tables as the CLI prints them."""
import json
import os
import subprocess

import numpy as np
import pytest

import pico_imu


def write(path, t, cols):
    names = list(cols)
    with open(path, "w") as f:
        f.write(",".join(["t"] + names) + "\n")
        for i in range(len(t)):
            f.write(",".join([repr(float(t[i]))] + [repr(float(cols[c][i])) for c in names]) + "\n")


def test_read_csv_units_rate_and_gaps(rng, tmp_path):
    n = int(rng.integers(2_000, 6_000))
    rate = float(rng.choice([100.0, 200.0, 1000.0]))
    cut = int(rng.integers(500, n - 500))
    lost = int(rng.integers(3, 40))
    k = np.arange(n)
    t = np.where(k < cut, k, k + lost) / rate  # `lost` samples missing before row `cut`
    gx = rng.normal(0, 0.05, n)
    temp = rng.normal(30, 0.1, n)
    p = tmp_path / "rec.csv"
    write(p, t, {"gx": gx, "temp": temp})
    rec = pico_imu.read_csv(p)
    np.testing.assert_array_equal(rec["gx"], gx)
    np.testing.assert_array_equal(rec.t, t)
    assert rec.units["gx"] == "deg/s" and rec.units["temp"] == "°C" and rec.units["t"] == "s"
    assert rec.rate_hz == pytest.approx(rate, rel=1e-9)
    assert rec.segments == [(0, cut), (cut, n)]
    assert rec.timing["gaps"] == 1 and rec.timing["missing_samples"] == lost
    with pytest.raises(KeyError, match="no column 'gz'"):
        rec["gz"]


def imu_lab():
    exe = os.environ.get("IMU_LAB")
    if not exe:
        pytest.skip("IMU_LAB (the imu-lab binary) not set; `cargo xtask test` sets it")
    return exe


@pytest.mark.parametrize("stat", ["oadev", "mdev", "ohdev", "totdev"])
def test_deviation_table_is_the_clis(rng, tmp_path, stat):
    n = int(rng.integers(3_000, 20_000))
    gz = rng.normal(0, 0.05, n) + 1e-3 * np.cumsum(rng.normal(size=n))
    p = tmp_path / "rec.csv"
    write(p, np.arange(n) / 200.0, {"gz": gz})
    out = subprocess.run([imu_lab(), "adev", str(p), "--column", "gz", "--stat", stat, "--json"],
                         check=True, capture_output=True, text=True)
    cli = json.loads(out.stdout)
    rec = pico_imu.read_csv(p)
    table = pico_imu.deviation(rec["gz"], rate=rec.rate_hz, stat=stat, unit=rec.units["gz"])
    assert len(table) == len(cli["adev"])
    for k, row in enumerate(cli["adev"]):
        assert table.m[k] == row["m"] and table.n[k] == row["n"] and table.alpha[k] == row["alpha"]
        for ours, key in ((table.tau, "tau_s"), (table.dev, "dev"), (table.lo, "lo"), (table.hi, "hi"),
                          (table.edf, "edf")):
            assert ours[k] == pytest.approx(row[key], rel=1e-12), (stat, key, row["m"])
    assert "±" not in str(table) and "[deg/s]" in str(table)
    d = table.to_dict()
    assert d["unit"] == "deg/s" and len(d["dev"]) == len(table)


def test_table_plot_draws_the_rows_with_their_bounds(rng):
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    y = rng.normal(0, 0.05, int(rng.integers(2_000, 10_000)))
    table = pico_imu.deviation(y, rate=100.0, stat="oadev", unit="deg/s")
    ax = table.plot()
    line = ax.lines[0]
    ok = np.isfinite(table.lo)
    np.testing.assert_array_equal(line.get_xdata(), table.tau[ok])
    np.testing.assert_array_equal(line.get_ydata(), table.dev[ok])
    assert ax.get_xscale() == "log" and ax.get_ylabel() == "OADEV [deg/s]"
    # the error bars reach the bounds
    segs = ax.collections[0].get_segments()
    lows = np.array([s[0][1] for s in segs])
    highs = np.array([s[1][1] for s in segs])
    np.testing.assert_allclose(lows, table.lo[ok], rtol=1e-12)
    np.testing.assert_allclose(highs, table.hi[ok], rtol=1e-12)


def test_to_csv_refuses_what_it_cannot_write_by_column_and_row(rng, tmp_path):
    n = int(rng.integers(200, 2_000))
    t = np.arange(n) / 100.0
    cols = {c: rng.normal(0, 1, n) for c in ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz")}
    cols["gap_before"] = np.zeros(n)
    p = tmp_path / "rec.csv"
    write(p, t, cols)
    rec = pico_imu.read_csv(p)
    out = tmp_path / "out.csv"
    rec.to_csv(out)
    np.testing.assert_allclose(pico_imu.read_csv(out)["gx"], cols["gx"], rtol=1e-6)
    good = out.read_text()
    k = int(rng.integers(1, n))
    for col, value, why in (("gx", np.inf, "not a value"), ("mz", 1e300, "beyond the file's single precision"),
                            ("gap_before", -3.0, "not a count"), ("gap_before", 0.5, "not a count"),
                            ("t", -1.0, "before the row above it"), ("t", np.nan, "not a time")):
        bad = pico_imu.read_csv(p)
        bad.columns[col] = bad.columns[col].copy()
        bad.columns[col][k] = value
        with pytest.raises(ValueError, match=rf"column {col} row {k} = .*: {why}"):
            bad.to_csv(out)
        assert out.read_text() == good, f"{col}: the file was touched"
