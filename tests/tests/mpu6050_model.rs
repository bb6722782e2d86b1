//! MPU-6050 driver against the register-level chip model on a simulated bus with a
//! simulated clock: FIFO filling at the configured rate, overflow after 1024 bytes, frame
//! alignment over long streams, data-ready, clone ids, temperature, self-test.

use embassy_futures::block_on;
use embedded_hal::i2c::NoAcknowledgeSource;
use embedded_hal_mock::eh1::delay::NoopDelay;
use imu_drivers::mpu6050::{
    Address, ChipId, Config, Dlpf, Error, FifoFrame, RawSample, SelfTestReport,
};
use imu_drivers::{asynch, blocking};
use pico_imu_tests::mpu6050_model::Motion;
use pico_imu_tests::{Mpu6050Model, SimBus, SimError};

/// Bus with one chip whose gyro X reads the sample index (1 LSB = 1/131 °/s at ±250 °/s).
fn bus_with(who: u8) -> SimBus {
    let mut m = Mpu6050Model::new(0x68, who);
    m.motion = Box::new(|i| Motion {
        accel_g: [0.0, -0.5, 1.0],
        gyro_dps: [(i % 30000) as f64 / 131.0, 1.0, -2.0],
        temp_c: 30.0,
    });
    SimBus::new().with_mpu(m)
}

fn init(bus: &SimBus, cfg: &Config) -> blocking::Mpu6050<SimBus> {
    let mut d = blocking::Mpu6050::new(bus.clone(), Address::Ad0Low);
    d.init(&mut bus.delay(), cfg).unwrap();
    d
}

#[test]
fn default_registers_land_in_the_chip() {
    let bus = bus_with(0x68);
    let _d = init(&bus, &Config::default());
    bus.mpu(|m| {
        assert_eq!(m.reg(0x6B), 0x01, "PWR_MGMT_1: awake, PLL gyro X");
        assert_eq!(m.reg(0x19), 0x00, "SMPLRT_DIV");
        assert_eq!(m.reg(0x1A), 0x06, "CONFIG DLPF_CFG 6");
        assert_eq!(m.reg(0x1B), 0x00, "GYRO_CONFIG ±250");
        assert_eq!(m.reg(0x1C), 0x08, "ACCEL_CONFIG ±4 g");
        assert_eq!(m.reg(0x23), 0x78, "FIFO_EN accel + gyro");
        assert_eq!(m.reg(0x6A), 0x40, "USER_CTRL FIFO_EN");
        assert_eq!(m.sample_period_ns(), 1_000_000, "1 kHz");
    });
}

#[test]
fn init_without_waiting_for_reset_fails_on_the_model() {
    // The model NACKs for 100 ms after DEVICE_RESET (PS 6.3): skipping the wait is caught.
    let bus = bus_with(0x68);
    let mut d = blocking::Mpu6050::new(bus.clone(), Address::Ad0Low);
    let e = d.init(&mut NoopDelay, &Config::default()).unwrap_err();
    assert_eq!(e, Error::Bus(SimError::Nack(NoAcknowledgeSource::Address)));
}

#[test]
fn fifo_fills_at_1khz_with_correct_values() {
    let bus = bus_with(0x68);
    let mut d = init(&bus, &Config::default());
    bus.advance_us(50_000);
    let mut out = [RawSample::default(); 64];
    let n = d.read_fifo(&mut out).unwrap();
    // 50 ms at 1 kHz: exactly 50 samples (the first falls 1 ms after wake-up).
    assert_eq!(n, 50);
    for (k, s) in out[..n].iter().enumerate() {
        // ±4 g: 8192 LSB/g → (0, -4096, 8192); ±250 °/s: 131 LSB/(°/s) → (k, 131, -262).
        assert_eq!(s.accel, [0, -4096, 8192]);
        assert_eq!(s.gyro, [k as i16, 131, -262]);
    }
    assert_eq!(d.fifo_count().unwrap(), 0);
}

#[test]
fn sample_rate_follows_divider_and_dlpf() {
    // (DLPF, divider, expected samples in 50 ms): RM 4.2 rate = 8 or 1 kHz / (1 + div).
    for (dlpf, div, expect) in [
        (Dlpf::Hz260, 7, 50),  // 8 kHz / 8 = 1 kHz
        (Dlpf::Hz260, 0, 85),  // 8 kHz: 400 frames would overflow; read at 85 (1020 bytes)
        (Dlpf::Hz260, 15, 25), // 8 kHz / 16 = 500 Hz
        (Dlpf::Hz5, 4, 10),    // 1 kHz / 5 = 200 Hz
        (Dlpf::Hz44, 9, 5),    // 1 kHz / 10 = 100 Hz
    ] {
        let cfg = Config {
            dlpf,
            sample_rate_divider: div,
            ..Config::default()
        };
        let bus = bus_with(0x68);
        let mut d = init(&bus, &cfg);
        let us = if div == 0 {
            assert_eq!(cfg.sample_rate_hz(), 8000.0);
            10_625 // 85 samples × 125 µs
        } else {
            assert_eq!(cfg.sample_rate_hz(), expect as f32 * 20.0);
            50_000
        };
        bus.advance_us(us);
        let mut out = [RawSample::default(); 128];
        assert_eq!(d.read_fifo(&mut out).unwrap(), expect, "{dlpf:?} div {div}");
    }
}

/// A chip answering `who`, initialised with the defaults (1 kHz, accel + gyro frames of 12
/// bytes), once `frames` samples have filled its FIFO.
fn fifo_filled(who: u8, frames: u16) -> (SimBus, blocking::Mpu6050<SimBus>) {
    let bus = bus_with(who);
    let mut d = init(&bus, &Config::default());
    bus.advance_us(u64::from(frames) * 1_000);
    assert_eq!(d.fifo_count().unwrap(), frames * 12);
    (bus, d)
}

#[test]
fn overflow_after_1024_bytes_is_detected_and_recovered() {
    // 85 frames = 1020 bytes fit; the 86th overflows (1032 > 1024).
    let (bus, mut d) = fifo_filled(0x68, 85);
    bus.advance_us(1_000);
    assert!(bus.mpu(|m| m.dropped_bytes) == 8);
    let mut out = [RawSample::default(); 128];
    assert_eq!(d.read_fifo(&mut out), Err(Error::FifoOverflow));
    d.reset_fifo().unwrap();
    assert_eq!(d.fifo_count().unwrap(), 0);
    bus.advance_us(10_000);
    let n = d.read_fifo(&mut out).unwrap();
    assert_eq!(n, 10);
    // Frames are aligned again: consecutive indices, after the 86 samples before the reset.
    for (k, s) in out[..n].iter().enumerate() {
        assert_eq!(s.gyro[0], 86 + k as i16);
        assert_eq!(s.accel, [0, -4096, 8192]);
    }
}

#[test]
fn long_stream_loses_and_repeats_nothing() {
    // 5 s at 1 kHz, polled every 7 ms (not a multiple of the sample period) into a
    // 16-frame buffer, so frames are often split across polls; every index must appear once.
    let bus = bus_with(0x68);
    let mut d = init(&bus, &Config::default());
    let mut next = 0i64;
    let mut out = [RawSample::default(); 16];
    for _ in 0..(5000 / 7) {
        bus.advance_us(7_000);
        loop {
            let n = d.read_fifo(&mut out).unwrap();
            for s in &out[..n] {
                assert_eq!(s.gyro[0] as i64, next, "sample index");
                assert_eq!(s.gyro[1], 131);
                next += 1;
            }
            if n < out.len() {
                break;
            }
        }
    }
    assert_eq!(next as u64, bus.mpu(|m| m.samples));
    assert!(next >= 4990, "{next} samples");
}

#[test]
fn async_driver_streams_the_same() {
    let bus = bus_with(0x68);
    let mut d = asynch::Mpu6050::new(bus.clone(), Address::Ad0Low);
    let chip = block_on(d.init(&mut bus.delay(), &Config::default())).unwrap();
    assert_eq!(chip, ChipId::Mpu6050);
    bus.advance_us(20_000);
    let mut out = [RawSample::default(); 32];
    let n = block_on(d.read_fifo(&mut out)).unwrap();
    assert_eq!(n, 20);
    assert_eq!(out[19].gyro, [19, 131, -262]);
    bus.advance_us(100_000);
    assert_eq!(block_on(d.read_fifo(&mut out)), Err(Error::FifoOverflow));
    block_on(d.reset_fifo()).unwrap();
    let s = block_on(d.read_all()).unwrap();
    assert_eq!(s.accel, [0, -4096, 8192]);
}

#[test]
fn data_ready_flag() {
    let bus = bus_with(0x68);
    let mut d = init(&bus, &Config::default());
    bus.advance_us(1_000);
    let s = d.read_if_ready().unwrap();
    assert_eq!(s.gyro[0], 0);
    assert_eq!(d.read_if_ready(), Err(Error::NotReady));
    bus.advance_us(1_000);
    assert_eq!(d.read_if_ready().unwrap().gyro[0], 1);
}

#[test]
fn temperature_per_chip_family() {
    // Model at 30.0 °C. Quantisation is 1 LSB = 1/340 °C (6050), 1/333.87 (6500), 1/326.8
    // (ICM): the converted value must be within half an LSB, < 0.0016 °C.
    for (who, chip) in [
        (0x68, ChipId::Mpu6050),
        (0x70, ChipId::Mpu6500),
        (0x73, ChipId::Mpu9255),
        (0x98, ChipId::Icm20689),
        (0x19, ChipId::Mpu6886),
    ] {
        let bus = bus_with(who);
        let mut d = init(&bus, &Config::default());
        assert_eq!(d.chip(), Some(chip));
        bus.advance_us(1_000);
        let s = d.read_all().unwrap();
        let t = d.scale().temperature_c(s.temp.unwrap());
        assert!((t - 30.0).abs() < 0.0016, "0x{who:02X}: {t} °C");
    }
}

#[test]
fn clone_6500_family_gets_accel_dlpf() {
    let bus = bus_with(0x98);
    let _d = init(&bus, &Config::default());
    bus.mpu(|m| assert_eq!(m.reg(0x1D), 0x06, "ACCEL_CONFIG2 A_DLPF_CFG 6"));
    let bus = bus_with(0x68);
    let _d = init(&bus, &Config::default());
    bus.mpu(|m| assert_eq!(m.reg(0x1D), 0x00, "reserved on the MPU-6050: untouched"));
}

#[test]
fn fifo_with_temperature() {
    let bus = bus_with(0x68);
    let cfg = Config {
        fifo: Some(FifoFrame::AccelTempGyro),
        ..Config::default()
    };
    let mut d = init(&bus, &cfg);
    bus.advance_us(3_000);
    let mut out = [RawSample::default(); 8];
    assert_eq!(d.read_fifo(&mut out).unwrap(), 3);
    let t = d.scale().temperature_c(out[2].temp.unwrap());
    assert!((t - 30.0).abs() < 0.0016, "{t} °C");
    assert_eq!(out[2].gyro, [2, 131, -262]);
}

#[test]
fn vanished_sensor_is_a_bus_error_not_a_panic() {
    let bus = bus_with(0x68);
    let mut d = init(&bus, &Config::default());
    bus.advance_us(5_000);
    bus.mpu(|m| m.present = false);
    let mut out = [RawSample::default(); 8];
    assert!(matches!(d.read_fifo(&mut out), Err(Error::Bus(_))));
    assert!(matches!(d.read_all(), Err(Error::Bus(_))));
    bus.mpu(|m| m.present = true);
    assert_eq!(d.read_fifo(&mut out).unwrap(), 5);
}

/// Trim registers with every code = 1: SELF_TEST_X/Y/Z = 0x01 (XG_TEST = 1, XA_TEST[4:2] = 0),
/// SELF_TEST_A = 0b0001_0101 (XA/YA/ZA_TEST[1:0] = 01). RM 4.1 then gives FT gyro =
/// 25·131 = 3275 LSB (−3275 for Y) and FT accel = 4096·0.34 = 1392.64 LSB.
fn trimmed_bus(gyro_factor: [f64; 3], accel_factor: [f64; 3]) -> SimBus {
    let bus = bus_with(0x68);
    bus.mpu(|m| {
        m.motion = Box::new(|_| Motion::default());
        m.set_trim_registers([0x01, 0x01, 0x01, 0x15]);
        m.gyro_self_test_lsb = [
            3275.0 * gyro_factor[0],
            -3275.0 * gyro_factor[1],
            3275.0 * gyro_factor[2],
        ];
        m.accel_self_test_lsb = accel_factor.map(|f| 1392.64 * f);
    });
    bus
}

/// Every axis's change from trim within `tol` percentage points of `gyro` and `accel` (%).
#[track_caller]
fn assert_changes(r: &SelfTestReport, gyro: [f32; 3], accel: [f32; 3], tol: f32) {
    for i in 0..3 {
        assert!((r.gyro_change_pct[i] - gyro[i]).abs() < tol, "{r:?}");
        assert!((r.accel_change_pct[i] - accel[i]).abs() < tol, "{r:?}");
    }
}

#[test]
fn self_test_passes_and_reports_the_deviation() {
    let bus = trimmed_bus([1.05, 0.97, 1.0], [1.10, 0.90, 1.0]);
    let mut d = init(&bus, &Config::default());
    let r = d.self_test(&mut bus.delay()).unwrap();
    // Rounding of the response to whole LSB: ≤ 0.5/1392 = 0.04 %; tolerance 0.05 points.
    assert_changes(&r, [5.0, -3.0, 0.0], [10.0, -10.0, 0.0], 0.05);
    assert!(r.passed());
    // Configured ranges are back.
    bus.mpu(|m| {
        assert_eq!(m.reg(0x1B), 0x00);
        assert_eq!(m.reg(0x1C), 0x08);
    });
}

#[test]
fn self_test_fails_a_weak_axis() {
    let bus = trimmed_bus([1.0, 1.0, 0.8], [1.0, 1.0, 1.0]);
    let mut d = init(&bus, &Config::default());
    let r = d.self_test(&mut bus.delay()).unwrap();
    assert!((r.gyro_change_pct[2] + 20.0).abs() < 0.05, "{r:?}");
    assert!(!r.passed());
}

#[test]
fn wrong_chip_on_model() {
    let bus = bus_with(0xEA); // ICM-20948: different register banks, not compatible
    let mut d = blocking::Mpu6050::new(bus.clone(), Address::Ad0Low);
    assert_eq!(
        d.init(&mut bus.delay(), &Config::default()),
        Err(Error::WrongChip { found: 0xEA })
    );
    // Wrong address: NACK.
    let mut d = blocking::Mpu6050::new(bus.clone(), Address::Ad0High);
    assert!(matches!(
        d.init(&mut bus.delay(), &Config::default()),
        Err(Error::Bus(SimError::Nack(NoAcknowledgeSource::Address)))
    ));
}

/// MPU-6500 on the model: OTP codes 1 → ST_OTP 2620 LSB (AN-MPU-6500A-02).
fn otp_bus(gyro_factor: [f64; 3], accel_factor: [f64; 3]) -> SimBus {
    let bus = bus_with(0x70);
    bus.mpu(|m| {
        m.motion = Box::new(|_| Motion::default());
        m.set_otp_6500([1, 1, 1], [1, 1, 1]);
        m.gyro_self_test_lsb = gyro_factor.map(|f| 2620.0 * f);
        m.accel_self_test_lsb = accel_factor.map(|f| 2620.0 * f);
    });
    bus
}

#[test]
fn self_test_mpu6500_family() {
    let bus = otp_bus([1.2, 0.6, 1.0], [1.3, 0.7, 1.0]);
    let mut d = init(&bus, &Config::default());
    assert_eq!(d.chip(), Some(ChipId::Mpu6500));
    let r = d.self_test(&mut bus.delay()).unwrap();
    // Responses are whole LSB of 2620·factor, exact here; tolerance 0.01 points for f32.
    assert_changes(&r, [20.0, -40.0, 0.0], [30.0, -30.0, 0.0], 0.01);
    assert!(r.passed());
    // A weak gyro (ratio 0.4) and a strong accelerometer (ratio 1.6) each fail.
    for (g, a) in [([0.4, 1.0, 1.0], [1.0; 3]), ([1.0; 3], [1.0, 1.6, 1.0])] {
        let bus = otp_bus(g, a);
        let mut d = init(&bus, &Config::default());
        assert!(!d.self_test(&mut bus.delay()).unwrap().passed());
    }
}

#[test]
fn mpu6500_overflows_at_512_bytes() {
    // 42 frames (504 bytes) fit the MPU-6500's 512-byte FIFO; the 43rd overflows it.
    let (bus, mut d) = fifo_filled(0x70, 42);
    let mut out = [RawSample::default(); 64];
    assert_eq!(d.read_fifo(&mut out).unwrap(), 42);
    bus.advance_us(43_000);
    assert_eq!(d.read_fifo(&mut out), Err(Error::FifoOverflow));
    d.reset_fifo().unwrap();
    bus.advance_us(3_000);
    assert_eq!(d.read_fifo(&mut out).unwrap(), 3);
    assert_eq!(out[2].gyro[0], 42 + 43 + 2);
}
