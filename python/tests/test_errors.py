"""Bad inputs: a ValueError (or OSError for files) that names what is wrong and where; no
panic crosses into Python."""
import numpy as np
import pytest

import pico_imu
from pico_imu import _native, allantools


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("data_type", ["freq", "phase"])
def test_a_non_finite_sample_is_refused_with_its_index(rng, bad, data_type):
    y = rng.normal(size=int(rng.integers(100, 5_000)))
    i = int(rng.integers(0, len(y)))
    y[i] = bad
    with pytest.raises(ValueError, match=rf"data\[{i}\] is not a finite number"):
        allantools.oadev(y, rate=10.0, data_type=data_type)
    with pytest.raises(ValueError, match=rf"data\[{i}\]"):
        pico_imu.deviation(y, rate=10.0, stat="mdev", data_type=data_type)


def test_bad_arguments_are_named():
    y = np.arange(100.0)
    with pytest.raises(ValueError, match="rate=0"):
        allantools.adev(y, rate=0.0)
    with pytest.raises(TypeError, match="rate='1000': the sample rate must be a number of Hz"):
        allantools.oadev(y, "1000")
    with pytest.raises(ValueError, match="rate=-1"):
        pico_imu.deviation(y, rate=-1.0)
    with pytest.raises(ValueError, match="data_type='phas'"):
        allantools.adev(y, data_type="phas")
    with pytest.raises(ValueError, match="data_type=\"x\""):
        pico_imu.deviation(y, rate=1.0, data_type="x")
    with pytest.raises(ValueError, match="taus='octaves'"):
        allantools.hdev(y, taus="octaves")
    with pytest.raises(ValueError, match=r"taus\[1\]"):
        allantools.hdev(y, taus=[1.0, np.nan])
    with pytest.raises(ValueError, match="no τ between"):
        allantools.oadev(y, rate=1.0, taus=[1000.0])
    with pytest.raises(ValueError, match="stat=\"allan\""):
        pico_imu.deviation(y, rate=1.0, stat="allan")
    for short in ([], [1.0], [1.0, 2.0]):
        with pytest.raises(ValueError, match=f"data has {len(short)} samples, at least 3"):
            allantools.totdev(short)
    with pytest.raises(ValueError, match="1-D"):
        allantools.oadev(np.ones((10, 10)))
    with pytest.raises(ValueError, match="data has 2 samples, at least 3 are needed"):
        pico_imu.deviation([1.0, 2.0], rate=1.0)
    with pytest.raises(ValueError, match="whole m"):
        pico_imu.deviation(y, rate=1.0, taus=[1.5])
    for m in (np.inf, 1e30):
        with pytest.raises(ValueError, match="whole m"):
            pico_imu.deviation(y, rate=1.0, taus=[m])
    # a τ beyond the record is an error, not an empty table
    with pytest.raises(ValueError, match=rf"taus: no averaging time fits the {len(y)} samples"):
        pico_imu.deviation(y, rate=1.0, taus=[len(y)])
    # 10⁹ points per octave is every m, at once (was out of memory)
    assert len(pico_imu.deviation(y[:200], rate=1.0, taus="1000000000/octave", stat="adev").m) > 0
    with pytest.raises(ValueError, match="N in N/octave"):
        pico_imu.deviation(y, rate=1.0, taus="x/octave")


def test_the_stream_refuses_what_is_not_a_count_and_keeps_its_state():
    s = pico_imu.Stream(rate=100.0)
    s.push(np.arange(50.0))
    with pytest.raises(ValueError, match=r"chunk\[3\] \(sample 53 of the stream\) is 0.5"):
        s.push([1.0, 2.0, 3.0, 0.5])
    with pytest.raises(ValueError, match=r"chunk\[0\].*NaN"):
        s.push([np.nan])
    with pytest.raises(ValueError, match=r"chunk\[1\]"):
        s.push([1.0, 2.0**40])
    for beyond in (2.0**31, -(2.0**31) - 1):
        with pytest.raises(ValueError, match=r"chunk\[0\].*not a whole count from −2\^31 to 2\^31 − 1"):
            s.push([beyond])
    assert s.samples == 50
    s.push([-(2.0**31), 2.0**31 - 1])  # the engine's i32 extremes are counts
    assert s.samples == 52
    with pytest.raises(ValueError, match="rate=0"):
        pico_imu.Stream(rate=0.0)
    with pytest.raises(ValueError, match="rate=1e-310: the sample rate"):
        pico_imu.Stream(rate=1e-310)
    with pytest.raises(ValueError, match="scale=-1"):
        pico_imu.Stream(rate=1.0, scale=-1.0)
    with pytest.raises(ValueError, match="scale=-1e-310: the value"):
        pico_imu.Stream(rate=1.0, scale=-1e-310)
    with pytest.raises(ValueError, match="stat=\"adev\""):
        s.table("adev")


def test_files(tmp_path):
    with pytest.raises(OSError, match="nope.csv"):
        pico_imu.read_csv(tmp_path / "nope.csv")
    p = tmp_path / "bad.csv"
    p.write_text("t,gx\n0.0,1.0\n0.01,abc\n0.02,1.0\n")
    with pytest.raises(ValueError, match=r"bad.csv: line 3: .*gx"):
        pico_imu.read_csv(p)
    q = tmp_path / "none.csv"
    q.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="no contract column"):
        pico_imu.read_csv(q)
    # a value no sensor reads, as imu-lab's reader refuses it
    r = tmp_path / "huge.csv"
    r.write_text("t,gx\n0.0,1.0\n0.01,1e300\n0.02,1.0\n")
    with pytest.raises(ValueError, match=r'huge.csv: column "gx", data row 2: 1e300: no sensor reads that much'):
        pico_imu.read_csv(r)


def test_a_panic_arrives_as_a_runtime_error():
    with pytest.raises(RuntimeError, match="internal error in pico_imu"):
        _native.panic_for_test()
