"""pico_imu.fit: the session `imu-lab fit` runs, on arrays; its .to_dict() is the CLI's --json on
the same data, its errors name the option or the sample."""
import json
import math
import subprocess

import numpy as np
import pytest

import pico_imu
from test_record import imu_lab, write


def same(ours, cli, path="$"):
    """Equal JSON values: strings, booleans and nulls exactly, numbers to 1e-9 relative."""
    if isinstance(cli, dict):
        assert isinstance(ours, dict) and list(ours) == list(cli), path
        for k in cli:
            same(ours[k], cli[k], f"{path}.{k}")
    elif isinstance(cli, list):
        assert isinstance(ours, list) and len(ours) == len(cli), path
        for i, (a, b) in enumerate(zip(ours, cli)):
            same(a, b, f"{path}[{i}]")
    elif isinstance(cli, bool) or cli is None or isinstance(cli, str):
        assert ours == cli, (path, ours, cli)
    else:
        assert isinstance(ours, (int, float)) and not isinstance(ours, bool), path
        assert math.isclose(ours, cli, rel_tol=1e-9, abs_tol=1e-300), (path, ours, cli)


def record(rng, tmp_path):
    """A gyro column with white noise, a rate random walk, a first-order Gauss–Markov process of
    random size and time constant, and a gap of random length, with a temperature column."""
    rate = float(rng.choice([100.0, 200.0, 400.0]))
    n = int(rng.integers(8_000, 16_000))
    white = rng.uniform(0.005, 0.05)
    y = rng.uniform(-1, 1) + rng.normal(0, white, n)
    y += white * rng.uniform(1e-4, 3e-3) * np.cumsum(rng.normal(size=n))
    tc = rng.uniform(0.2, 5.0) * rate  # samples
    a = math.exp(-1.0 / tc)
    gm = np.zeros(n)
    e = rng.normal(0, white * rng.uniform(0.0, 0.3), n)
    for i in range(1, n):
        gm[i] = a * gm[i - 1] + e[i]
    y += gm
    cut, lost = int(rng.integers(n // 4, 3 * n // 4)), int(rng.integers(2, 50))
    k = np.arange(n)
    t = np.where(k < cut, k, k + lost) / rate
    temp = 30 + 0.01 * np.cumsum(rng.normal(size=n)) / math.sqrt(n)
    p = tmp_path / "rec.csv"
    write(p, t, {"gx": y, "temp": temp})
    return p


def cli_json(path, *flags):
    out = subprocess.run([imu_lab(), "fit", str(path), "--column", "gx", "--json", *flags],
                         check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


@pytest.mark.parametrize("how", ["default", "auto", "add"])
def test_to_dict_is_the_clis_json(rng, tmp_path, how):
    p = record(rng, tmp_path)
    rec = pico_imu.read_csv(p)
    tol = float(rng.uniform(1e-3, 1e-1))
    if how == "default":
        flags, kw = ["--tolerance", repr(tol)], dict(tolerance=tol)
    elif how == "auto":
        flags, kw = ["--auto", "--max-steps", "3"], dict(auto=True, max_steps=3)
    else:
        flags, kw = ["--terms", "white,rate_random_walk", "--add", "markov"], \
            dict(terms=["white", "rate_random_walk"], add=["markov"])
    cli = cli_json(p, *flags)
    f = pico_imu.fit(rec, column="gx", **kw)
    same(f.to_dict(), cli)
    # the attributes are the object's
    assert f.unit == "deg/s" and f.samples == len(rec["gx"]) and f.rate_hz == cli["rate_hz"]
    assert [t.effect for t in f.terms] == [t["effect"] for t in cli["terms"]]
    assert f.adequate == cli["diagnosis"]["adequate"] and f.missing == cli["diagnosis"]["missing"]
    np.testing.assert_allclose(f.table["dev"], [r["dev"] for r in cli["adev"]], rtol=1e-12)
    assert len(f.steps) == len(cli["steps"]) and len(f.stages()) == len(f.steps) + 1
    assert f.verdict.startswith("ADEQUATE" if f.adequate else "NOT ADEQUATE")
    for t in f.terms:
        assert t.effect in f.physics and f.physics[t.effect]
        assert list(t.units) == list(t.params) and t.units[next(iter(t.units))], t
    if how == "add":
        assert f.steps[0].added == ["markov"]
    # an array with its rate (no time column: no timing, one segment) is the same session as a
    # recording without `t`
    g = pico_imu.fit(rec["gx"][: rec.segments[0][1]], rate=rec.rate_hz, unit="deg/s", **kw)
    assert g.to_dict()["timing"] is None and g.samples == rec.segments[0][1]


def test_repr_html_and_plot_show_the_walk(rng, tmp_path):
    p = record(rng, tmp_path)
    f = pico_imu.fit(pico_imu.read_csv(p), column="gx", auto=True, max_steps=2)
    h = f._repr_html_()
    assert h.count("<tr>") == (len(f.steps) + 1 if f.steps else 0) + len(f.terms) + 1
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    for stage in (0, -1):
        s = f.stages()[stage]
        fig = f.plot(stage=stage)
        ax, rx = fig.axes
        model = [ln for ln in ax.lines if ln.get_label() == "model"][0]
        np.testing.assert_allclose(model.get_ydata(), s["model"], rtol=1e-12)
        np.testing.assert_allclose(ax.lines[0].get_ydata(), s["dev"], rtol=1e-12)
        labels = {ln.get_label() for ln in ax.lines}
        assert set(k for k, v in s["terms"].items() if (v > 0).any()) <= labels
        np.testing.assert_allclose(rx.lines[0].get_ydata(), s["residual"], rtol=1e-12)
        assert ax.get_ylabel() == "Allan deviation [deg/s]"
    with pytest.raises(ValueError, match="stage=9"):
        f.plot(stage=9)


def test_text_forms_carry_the_walk_and_every_estimate(rng, tmp_path):
    rec = pico_imu.read_csv(record(rng, tmp_path))
    for f in (pico_imu.fit(rec, column="gx", terms=["white", "rate_random_walk"], add=["markov"]),
              pico_imu.fit(rec, column="gx", auto=True, max_steps=2)):
        steps = f.steps_text().splitlines()
        assert len(steps) == 2 * len(f.steps) + (1 if f.stop else 0), steps
        for i, s in enumerate(f.steps):
            line = steps[2 * i]
            assert line.startswith(f"  {i + 1}. "), line
            assert all(f"+ {a}" in line for a in s.added) and all(f"− {r}" in line for r in s.removed)
            assert f"χ²/dof {s.chi2_dof_before:.3g} → {s.chi2_dof_after:.3g}" in line
            assert steps[2 * i + 1].strip() == s.reading.strip()
        terms = f.terms_text().splitlines()
        assert [ln.split()[0] for ln in terms] == [t.effect for t in f.terms]
        for ln, t in zip(terms, f.terms):
            for k, v in t.params.items():
                assert f"{k} = " in ln and t.units.get(k, "") in ln, (ln, k)
            assert ln.endswith("(not detected)") == (not t.detected), ln
        text = str(f)
        assert f.terms_text() in text and f.steps_text() in text and f.verdict in text
    assert f.steps or f.stop


def test_bad_inputs_are_named(rng, tmp_path):
    y = rng.normal(0, 0.01, int(rng.integers(3_000, 8_000)))
    i = int(rng.integers(0, len(y)))
    bad = y.copy()
    bad[i] = rng.choice([np.nan, np.inf, -np.inf])
    with pytest.raises(ValueError, match=rf"y\[{i}\] = (nan|NaN|inf|-inf): not a finite sample"):
        pico_imu.fit(bad, rate=100.0)
    with pytest.raises(ValueError, match='terms "whit"'):
        pico_imu.fit(y, rate=100.0, terms=["whit"])
    with pytest.raises(ValueError, match='add "lowpas"'):
        pico_imu.fit(y, rate=100.0, add=["lowpas"])
    with pytest.raises(ValueError, match="add white: the model already has it"):
        pico_imu.fit(y, rate=100.0, add=["white"])
    with pytest.raises(ValueError, match="add drift"):
        pico_imu.fit(y, rate=100.0, add=["drift"])
    with pytest.raises(ValueError, match="add with the automatic walk"):
        pico_imu.fit(y, rate=100.0, add=["markov"], auto=True)
    for steps in (0, 21, -3, 2.5):
        with pytest.raises(ValueError, match=rf"max_steps={steps}"):
            pico_imu.fit(y, rate=100.0, auto=True, max_steps=steps)
    for tol, shown in ((-1.0, "-1"), (0.0, "0"), (float("nan"), "NaN")):
        with pytest.raises(ValueError, match=rf"tolerance {shown}: must be a positive number"):
            pico_imu.fit(y, rate=100.0, tolerance=tol)
    for rate, shown in ((0.0, "0"), (-5.0, "-5"), (float("inf"), "inf")):
        with pytest.raises(ValueError, match=rf"rate={shown}: the sample rate"):
            pico_imu.fit(y, rate=rate)
    with pytest.raises(ValueError, match="rate: give the sample rate"):
        pico_imu.fit(y)
    # a rate that contradicts the stamps (here 10×) is refused, not fitted off by √10
    t = np.arange(len(y)) / 100.0
    with pytest.raises(ValueError, match=r"rate=1000: disagrees with t, whose spacing is 0\.01 s \(100 Hz\)"):
        pico_imu.fit(y, rate=1000.0, t=t)
    assert pico_imu.fit(y, t=t).rate_hz == pytest.approx(100.0)
    # a temperature no IMU reads is refused by sample
    temp = np.full(len(y), 25.0)
    temp[i] = 1e6
    with pytest.raises(ValueError, match=rf"temperature sample {i} = 1000000 °C is outside"):
        pico_imu.fit(y, rate=100.0, temp=temp)
    with pytest.raises(ValueError, match=rf"temp: {len(y) - 1} values for {len(y)} samples"):
        pico_imu.fit(y, rate=100.0, temp=np.zeros(len(y) - 1))
    with pytest.raises(ValueError, match="column: give the column"):
        pico_imu.fit(pico_imu.read_csv(record(rng, tmp_path)))
    e = tmp_path / "bad_effect.toml"
    e.write_text("name = 3\n")
    with pytest.raises(ValueError, match="effects: .*bad_effect.toml"):
        pico_imu.fit(y, rate=100.0, effects=[e])
    with pytest.raises(OSError):
        pico_imu.fit(y, rate=100.0, effects=[tmp_path / "missing.toml"])
    with pytest.raises(ValueError, match=r"y: expected a 1-D array"):
        pico_imu.fit(np.zeros((3, 3)), rate=1.0)
