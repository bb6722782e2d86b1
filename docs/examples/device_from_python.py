"""The demo's walk from Python, against the device: `pico_imu.Device` (the link `imu-lab record`
and `imu-lab device` use) records the calibrated stream, reads the device's own Allan table of
the gyro, and the noise lab's walk runs on the recording (`imu-lab fit recording.csv --column gx
--auto`): the five-term model of Jaime et al. fitted, diagnosed, the named effect added and
refitted until adequate. With `--calibrate` it also records raw counts at rest, fits the gyro
bias (`pico_imu.calibrate`), uploads it to the device's RAM (the CLI's plausibility checks
first), records again and shows the gyro before → after; the device's previous calibration is
put back at the end.

On the emulated Pico W, as `cargo xtask demo` sets it up (gyro noise inside the five-term model;
the MPU-6050's own low-pass filter is the hidden effect):

    cargo xtask firmware                                 # the ELF the emulator runs
    imu-lab simulate --rate 1000 --samples 90000 --seed 11 --columns gx,gy,gz \\
        --white 0.01 --rrw 0.002 --output stream.csv
    node sim/src/cli.js run --elf target/thumbv6m-none-eabi/release/pico-imu --seconds 3600 \\
        --stream stream.csv --port-file port --quiet &
    python docs/examples/device_from_python.py tcp:127.0.0.1:$(cat port) --seconds 60 \\
        --calibrate --plot gyro.png

The demo's stream has no gyro offset, so the bias step changes little there; `--step 0.001,1.5`
added to `imu-lab simulate` gives the gyro 1.5 deg/s of bias for the calibration to remove
(docs/img/python-device-gyro-bias.png was drawn so). On a real Pico W running the firmware:
`python docs/examples/device_from_python.py /dev/ttyACM0`.
"""
import argparse
import time

import numpy as np

import pico_imu


def walk(rec: pico_imu.Recording, column: str) -> None:
    t = time.perf_counter()
    f = pico_imu.fit(rec, column=column, auto=True)
    print(f"\n== Automatic walk on {column} (computed in {time.perf_counter() - t:.1f} s): "
          "diagnose → add the named effect → refit")
    print(f.steps_text())
    print(f.terms_text())
    print(f"Verdict: {f.verdict}")


def gyro_means(rec: pico_imu.Recording) -> str:
    n = len(rec.t)
    return ", ".join(f"{c} {rec[c].mean():+.4f} ± {rec[c].std() / np.sqrt(n):.4f} deg/s"
                     for c in ("gx", "gy", "gz"))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("port", help="serial device (/dev/ttyACM0) or tcp:HOST:PORT (the emulator)")
    p.add_argument("--seconds", type=float, default=60.0, help="device time recorded, s")
    p.add_argument("--column", default="gx")
    p.add_argument("--calibrate", action="store_true", help="fit, upload and check a gyro bias")
    p.add_argument("--plot", help="PNG of the gyro before → after the calibration (matplotlib)")
    a = p.parse_args()

    with pico_imu.Device(a.port, timeout=5.0) as dev:
        i, s = dev.identity, dev.status()
        print(f"device: {i['firmware']} on {i['board']}, protocol {i['protocol']}, IMU {i['imu_rate_hz']} Hz, "
              f"magnetometer {i['mag_rate_hz']} Hz; up {s['uptime_s']:.3f} s, calibration {s['calibration']}")
        dev.reset_allan()
        t = time.perf_counter()
        rec = dev.record(a.seconds)
        print(f"recorded in {time.perf_counter() - t:.1f} s wall: {rec.summary}")
        table = dev.tables([a.column])[a.column]
        print(f"\n== The device's own Allan table of {a.column} (since the reset)\n{table}")
        walk(rec, a.column)

        if a.calibrate:
            before_cal = dev.calibration()
            raw = dev.record(min(a.seconds, 5.0), raw=True)
            cal = pico_imu.calibrate("gyro", raw)
            print(f"\n== Gyro bias from {len(raw.t)} raw samples at rest: "
                  + ", ".join(f"{b:+.4f} ± {s:.4f} deg/s" for b, s in zip(cal.params["bias"], cal.sigma["bias"])))
            dev.upload(cal, persist=False)
            try:
                after = dev.record(min(a.seconds, 5.0))
            finally:
                dev.upload(before_cal["blob"], persist=before_cal["source"] == "flash")
            print(f"before (raw):       {gyro_means(raw)}")
            print(f"after (corrected):  {gyro_means(after)}")
            if a.plot:
                import matplotlib
                matplotlib.use("Agg")
                import matplotlib.pyplot as plt
                # Means over 0.25 s blocks: the white noise averaged down, the bias left standing.
                fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 6))
                for ax, c in zip(axes, ("gx", "gy", "gz")):
                    for r, label in ((raw, "before (raw)"), (after, "after (bias uploaded)")):
                        k = len(r.t) // 250
                        tb = (r.t[:k * 250] - r.t[0]).reshape(k, 250).mean(axis=1)
                        yb = r[c][:k * 250].reshape(k, 250).mean(axis=1)
                        ax.plot(tb, yb, "o-", ms=3, label=label)
                    ax.axhline(0.0, color="k", lw=0.5)
                    ax.set_ylabel(f"{c} [deg/s]")
                axes[0].legend(loc="upper right")
                axes[-1].set_xlabel("t since the recording's start [s]")
                fig.suptitle("Gyro at rest, 0.25 s means, before → after the fitted bias (on the device)")
                fig.tight_layout()
                fig.savefig(a.plot, dpi=110)
                print(f"wrote {a.plot}")


if __name__ == "__main__":
    main()
