"""A recording read in chunks (bounded memory) and streamed: the same as reading it whole, and
the same table as `imu-lab adev --bounded`."""
import json
import os
import subprocess

import numpy as np
import pytest

import pico_imu

from test_record import write


def recording(rng, tmp_path, n):
    rate = float(rng.choice([200.0, 1000.0]))
    k = np.arange(n)
    t = k.astype(float)
    cuts = sorted(int(c) for c in rng.choice(np.arange(100, n - 100), size=int(rng.integers(1, 4)), replace=False))
    for c in cuts:
        t[c:] += int(rng.integers(2, 50))  # samples lost before row c
    gz = np.round(rng.normal(0, 300, n) + np.cumsum(rng.normal(0, 3, n)))
    gx = rng.normal(0, 0.02, n)
    p = tmp_path / "rec.csv"
    write(p, t / rate, {"gx": gx, "gz": gz})
    return p, rate, cuts, gx, gz


def test_chunks_are_the_whole_file(rng, tmp_path):
    n = int(rng.integers(5_000, 20_000))
    p, rate, cuts, gx, gz = recording(rng, tmp_path, n)
    whole = pico_imu.read_csv(p)
    rows = int(rng.integers(1, 3_000))
    chunks = pico_imu.read_csv_chunks(p, rows=rows)
    assert chunks.rate_hz == pytest.approx(whole.rate_hz, rel=1e-12)
    assert chunks.units["gz"] == "deg/s"
    got = {name: [] for name in chunks.names}
    starts = []
    for c in chunks:
        assert len(c["columns"]["gz"]) <= rows
        for name, v in c["columns"].items():
            got[name].append(v)
        starts.extend(c["start"] + int(g) for g in c["gaps"])
    np.testing.assert_array_equal(np.concatenate(got["gx"]), gx)
    np.testing.assert_array_equal(np.concatenate(got["gz"]), gz)
    assert starts == cuts == [s for s, _ in whole.segments[1:]]


def test_stream_csv_is_the_clis_bounded_table(rng, tmp_path):
    exe = os.environ.get("IMU_LAB")
    if not exe:
        pytest.skip("IMU_LAB (the imu-lab binary) not set; `cargo xtask test` sets it")
    n = int(rng.integers(20_000, 60_000))
    p, rate, cuts, gx, gz = recording(rng, tmp_path, n)
    scale = 1 / 131.0
    s = pico_imu.stream_csv(p, "gz", scale=scale, rows=int(rng.integers(100, 10_000)))
    assert s.gaps == len(cuts) and s.samples == n
    out = subprocess.run([exe, "adev", str(p), "--column", "gz", "--bounded", "--scale", repr(scale), "--json"],
                         check=True, capture_output=True, text=True)
    cli = json.loads(out.stdout)["adev"]
    table = s.table("oadev")
    assert len(table) == len(cli)
    for k, row in enumerate(cli):
        assert table.m[k] == row["m"] and table.n[k] == row["n"], row["m"]
        assert table.dev[k] == pytest.approx(row["dev"], rel=1e-12)
        assert table.edf[k] == pytest.approx(row["edf"], rel=1e-12)


def test_chunk_errors_name_the_line(tmp_path):
    p = tmp_path / "back.csv"
    p.write_text("t,gz\n" + "".join(f"{i * 0.01},{i}\n" for i in range(10)) + "0.05,3\n")
    with pytest.raises(ValueError, match=r"back.csv: column \"t\""):
        list(pico_imu.read_csv_chunks(p))
    with pytest.raises(ValueError, match="rows=0"):
        pico_imu.read_csv_chunks(p, rows=0)
    q = tmp_path / "frac.csv"
    q.write_text("t,gz\n" + "".join(f"{i * 0.01},{i + 0.5 * (i == 7)}\n" for i in range(20)))
    with pytest.raises(ValueError, match=r"rows from 0: chunk\[7\] \(sample 7 of the stream\) is 7.5"):
        pico_imu.stream_csv(q, "gz")
