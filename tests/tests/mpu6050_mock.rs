//! MPU-6050 driver against embedded-hal-mock transaction lists, blocking and async.
//! Every expected byte is derived here from the Register Map (RM rev 4.2), not from the
//! driver's constants, so a wrong register value fails.

use embassy_futures::block_on;
use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};
use embedded_hal_mock::eh1::delay::{CheckedDelay, NoopDelay, Transaction as D};
use embedded_hal_mock::eh1::i2c::{Mock, Transaction as T};
use imu_drivers::mpu6050::{
    AccelRange, Address, ChipId, Config, Dlpf, Error, FifoFrame, GyroRange, InterruptConfig,
    RawSample,
};
use imu_drivers::{asynch, blocking};

const A: u8 = 0x68;

/// Default init on a chip answering `who`: RM 4.28 reset (the part is then asleep), burst
/// 0x19..0x1C (SMPLRT_DIV 0, DLPF_CFG 6, FS_SEL 0 → 0x00, AFS_SEL 1 → 0x08), INT_PIN_CFG 0,
/// INT_ENABLE DATA_RDY|FIFO_OFLOW = 0x11, FIFO reset, FIFO_EN accel+XYZ gyro = 0x78, FIFO on,
/// and last the wake-up CLKSEL=1 (the sample clock starts with it).
fn default_init(who: u8, burst: Vec<u8>) -> Vec<T> {
    vec![
        T::write_read(A, vec![0x75], vec![who]),
        T::write(A, vec![0x6B, 0x80]),
        T::write(A, burst),
        T::write(A, vec![0x37, 0x00]),
        T::write(A, vec![0x38, 0x11]),
        T::write(A, vec![0x6A, 0x04]),
        T::write(A, vec![0x23, 0x78]),
        T::write(A, vec![0x6A, 0x40]),
        T::write(A, vec![0x6B, 0x01]),
    ]
}

fn default_burst_6050() -> Vec<u8> {
    vec![0x19, 0x00, 0x06, 0x00, 0x08]
}

/// Run the same expectations through the blocking and the async driver.
fn both<R: PartialEq + std::fmt::Debug>(
    exp: &[T],
    b: impl FnOnce(&mut blocking::Mpu6050<Mock>) -> R,
    a: impl AsyncFnOnce(&mut asynch::Mpu6050<Mock>) -> R,
) -> R {
    let mut d1 = blocking::Mpu6050::new(Mock::new(exp), Address::Ad0Low);
    let r1 = b(&mut d1);
    d1.release().done();
    let mut d2 = asynch::Mpu6050::new(Mock::new(exp), Address::Ad0Low);
    let r2 = block_on(a(&mut d2));
    d2.release().done();
    assert_eq!(r1, r2, "blocking and async results differ");
    r1
}

/// `init` with `cfg`, blocking and async (the same result from both).
fn init_ok(exp: &[T], cfg: &Config) -> ChipId {
    both(
        exp,
        |d| d.init(&mut NoopDelay, cfg).unwrap(),
        async |d| d.init(&mut NoopDelay, cfg).await.unwrap(),
    )
}

/// `init` with `cfg` failing, blocking and async (the same error from both).
fn init_err(exp: &[T], cfg: &Config) -> Error<ErrorKind> {
    both(
        exp,
        |d| d.init(&mut NoopDelay, cfg).unwrap_err(),
        async |d| d.init(&mut NoopDelay, cfg).await.unwrap_err(),
    )
}

#[test]
fn default_init_sequence_and_reset_delay() {
    let exp = default_init(0x68, default_burst_6050());
    let chip = both(
        &exp,
        |d| {
            let mut delay = CheckedDelay::new(&[D::delay_ms(100)]);
            let r = d.init(&mut delay, &Config::default()).unwrap();
            delay.done();
            r
        },
        async |d| {
            let mut delay = CheckedDelay::new(&[D::delay_ms(100)]);
            let r = d.init(&mut delay, &Config::default()).await.unwrap();
            delay.done();
            r
        },
    );
    assert_eq!(chip, ChipId::Mpu6050);
}

#[test]
fn default_config_is_the_papers() {
    let c = Config::default();
    assert_eq!(c.gyro_range, GyroRange::Dps250);
    assert_eq!(c.accel_range, AccelRange::G4);
    assert_eq!(c.dlpf, Dlpf::Hz5);
    assert_eq!(c.sample_rate_divider, 0);
    assert_eq!(c.sample_rate_hz(), 1000.0);
    assert_eq!(c.fifo, Some(FifoFrame::AccelGyro));
}

#[test]
fn clone_ids_accepted_and_6500_family_gets_accel_config2() {
    // MPU-6500 family (0x70, 0x71, 0x72, 0x73) and ICM parts (0x98, 0x19): ACCEL_CONFIG2 (0x1D)
    // = A_DLPF_CFG 6 (5.05 Hz, RM-6500 register 29 (ACCEL_CONFIG 2)) appended to the burst.
    for (who, chip) in [
        (0x70, ChipId::Mpu6500),
        (0x71, ChipId::Mpu9250),
        (0x72, ChipId::Mpu92xxVariant),
        (0x73, ChipId::Mpu9255),
        (0x98, ChipId::Icm20689),
        (0x19, ChipId::Mpu6886),
    ] {
        let exp = default_init(who, vec![0x19, 0x00, 0x06, 0x00, 0x08, 0x06]);
        let got = init_ok(&exp, &Config::default());
        assert_eq!(got, chip, "WHO_AM_I 0x{who:02X}");
    }
}

#[test]
fn wrong_chip_stops_before_any_write() {
    for who in [0x00, 0xFF, 0x69, 0x34, 0xEA] {
        let exp = [T::write_read(A, vec![0x75], vec![who])];
        let e = init_err(&exp, &Config::default());
        assert_eq!(e, Error::WrongChip { found: who });
    }
}

#[test]
fn nack_on_address_is_a_bus_error() {
    let nack = ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address);
    let exp = [T::write_read(A, vec![0x75], vec![0]).with_error(nack)];
    let e = init_err(&exp, &Config::default());
    assert_eq!(e, Error::Bus(nack));
}

#[test]
fn nack_midway_through_init_is_reported() {
    let nack = ErrorKind::NoAcknowledge(NoAcknowledgeSource::Data);
    let exp = [
        T::write_read(A, vec![0x75], vec![0x68]),
        T::write(A, vec![0x6B, 0x80]),
        T::write(A, default_burst_6050()).with_error(nack),
    ];
    let e = init_err(&exp, &Config::default());
    assert_eq!(e, Error::Bus(nack));
}

#[test]
fn custom_config_bytes() {
    // ±2000 °/s (FS_SEL 3 → 0x18), ±16 g (AFS_SEL 3 → 0x18), DLPF 0 (260 Hz, 8 kHz gyro rate),
    // divider 7 → 1 kHz; FIFO with temperature (FIFO_EN 0xF8); interrupt active low, open
    // drain, latched, cleared by any read (INT_PIN_CFG 0xF0); only FIFO overflow enabled.
    let cfg = Config {
        gyro_range: GyroRange::Dps2000,
        accel_range: AccelRange::G16,
        dlpf: Dlpf::Hz260,
        sample_rate_divider: 7,
        fifo: Some(FifoFrame::AccelTempGyro),
        interrupt: InterruptConfig {
            data_ready: false,
            fifo_overflow: true,
            active_low: true,
            open_drain: true,
            latch: true,
            clear_on_any_read: true,
        },
    };
    assert_eq!(cfg.sample_rate_hz(), 1000.0);
    let exp = [
        T::write_read(A + 1, vec![0x75], vec![0x68]),
        T::write(A + 1, vec![0x6B, 0x80]),
        T::write(A + 1, vec![0x19, 0x07, 0x00, 0x18, 0x18]),
        T::write(A + 1, vec![0x37, 0xF0]),
        T::write(A + 1, vec![0x38, 0x10]),
        T::write(A + 1, vec![0x6A, 0x04]),
        T::write(A + 1, vec![0x23, 0xF8]),
        T::write(A + 1, vec![0x6A, 0x40]),
        T::write(A + 1, vec![0x6B, 0x01]),
    ];
    let mut d = blocking::Mpu6050::new(Mock::new(&exp), Address::Ad0High);
    d.init(&mut NoopDelay, &cfg).unwrap();
    d.release().done();
}

#[test]
fn fifo_off_config_disables_fifo() {
    let cfg = Config {
        fifo: None,
        ..Config::default()
    };
    let exp = [
        T::write_read(A, vec![0x75], vec![0x68]),
        T::write(A, vec![0x6B, 0x80]),
        T::write(A, default_burst_6050()),
        T::write(A, vec![0x37, 0x00]),
        T::write(A, vec![0x38, 0x01]),
        T::write(A, vec![0x23, 0x00]),
        T::write(A, vec![0x6A, 0x00]),
        T::write(A, vec![0x6B, 0x01]),
    ];
    let mut d = blocking::Mpu6050::new(Mock::new(&exp), Address::Ad0Low);
    d.init(&mut NoopDelay, &cfg).unwrap();
    // With the FIFO off, FIFO reads are refused without touching the bus.
    let mut out = [RawSample::default(); 2];
    assert_eq!(d.read_fifo(&mut out), Err(Error::NotConfigured));
    assert_eq!(d.reset_fifo(), Err(Error::NotConfigured));
    d.release().done();
}

#[test]
fn read_all_is_one_14_byte_burst() {
    // accel (1000, -2, 8192), temp -521, gyro (131, -131, 32767), big-endian (RM 4.17-4.19).
    let bytes = vec![
        0x03, 0xE8, 0xFF, 0xFE, 0x20, 0x00, 0xFD, 0xF7, 0x00, 0x83, 0xFF, 0x7D, 0x7F, 0xFF,
    ];
    let exp = [T::write_read(A, vec![0x3B], bytes)];
    let s = both(
        &exp,
        |d| d.read_all().unwrap(),
        async |d| d.read_all().await.unwrap(),
    );
    assert_eq!(
        s,
        RawSample {
            accel: [1000, -2, 8192],
            temp: Some(-521),
            gyro: [131, -131, 32767]
        }
    );
}

#[test]
fn conversions_to_si_units() {
    let d = blocking::Mpu6050::new(Mock::new(&[]), Address::Ad0Low);
    let sc = d.scale();
    let s = sc.convert(&RawSample {
        accel: [8192, -8192, 0],
        temp: Some(-521),
        gyro: [131, -262, 0],
    });
    // ±4 g: 8192 LSB = 1 g = 9.80665 m/s² exactly in f32 rounding (tolerance 1e-5 m/s²).
    assert!((s.accel_ms2[0] - 9.80665).abs() < 1e-5);
    assert!((s.accel_ms2[1] + 9.80665).abs() < 1e-5);
    assert_eq!(s.gyro_dps, [1.0, -2.0, 0.0]);
    // RM 4.18: -521/340 + 36.53 = 34.9976 °C (tolerance 1e-4 °C, f32 rounding).
    assert!((s.temperature_c.unwrap() - 34.997_6).abs() < 1e-4);
    d.release().done();
}

#[test]
fn read_if_ready_respects_data_ready() {
    let bytes = vec![0u8; 14];
    let exp = [
        T::write_read(A, vec![0x3A], vec![0x00]),
        T::write_read(A, vec![0x3A], vec![0x01]),
        T::write_read(A, vec![0x3B], bytes),
    ];
    let r = both(
        &exp,
        |d| (d.read_if_ready(), d.read_if_ready().map(|s| s.accel)),
        async |d| {
            (
                d.read_if_ready().await,
                d.read_if_ready().await.map(|s| s.accel),
            )
        },
    );
    assert_eq!(r.0, Err(Error::NotReady));
    assert_eq!(r.1, Ok([0, 0, 0]));
}

fn inited(extra: &[T]) -> Vec<T> {
    let mut v = default_init(0x68, default_burst_6050());
    v.extend_from_slice(extra);
    v
}

fn frame12(i: i16) -> Vec<u8> {
    [i, i + 1, i + 2, i + 3, i + 4, i + 5]
        .iter()
        .flat_map(|v| v.to_be_bytes())
        .collect()
}

#[test]
fn fifo_read_takes_whole_frames_only() {
    // 40 bytes waiting = 3 whole 12-byte frames + 4 bytes of a frame being written.
    let mut data = frame12(10);
    data.extend(frame12(20));
    data.extend(frame12(30));
    let exp = inited(&[
        T::write_read(A, vec![0x72], vec![0x00, 40]),
        T::write_read(A, vec![0x74], data),
    ]);
    let (n, out) = both(
        &exp,
        |d| {
            d.init(&mut NoopDelay, &Config::default()).unwrap();
            let mut out = [RawSample::default(); 8];
            (d.read_fifo(&mut out).unwrap(), out)
        },
        async |d| {
            d.init(&mut NoopDelay, &Config::default()).await.unwrap();
            let mut out = [RawSample::default(); 8];
            (d.read_fifo(&mut out).await.unwrap(), out)
        },
    );
    assert_eq!(n, 3);
    assert_eq!(out[1].accel, [20, 21, 22]);
    assert_eq!(out[1].gyro, [23, 24, 25]);
    assert_eq!(out[1].temp, None);
    assert_eq!(out[3], RawSample::default());
}

#[test]
fn fifo_read_limited_by_output_and_chunked() {
    // 40 frames waiting, room for 20: one 16-frame burst then one 4-frame burst.
    let burst = |from: i16, n: i16| -> Vec<u8> { (0..n).flat_map(|k| frame12(from + k)).collect() };
    let exp = inited(&[
        T::write_read(A, vec![0x72], vec![0x01, 0xE0]),
        T::write_read(A, vec![0x74], burst(0, 16)),
        T::write_read(A, vec![0x74], burst(16, 4)),
    ]);
    let (n, last) = both(
        &exp,
        |d| {
            d.init(&mut NoopDelay, &Config::default()).unwrap();
            let mut out = [RawSample::default(); 20];
            (d.read_fifo(&mut out).unwrap(), out[19])
        },
        async |d| {
            d.init(&mut NoopDelay, &Config::default()).await.unwrap();
            let mut out = [RawSample::default(); 20];
            (d.read_fifo(&mut out).await.unwrap(), out[19])
        },
    );
    assert_eq!(n, 20);
    assert_eq!(last.accel, [19, 20, 21]);
}

#[test]
fn fifo_full_count_is_overflow_then_reset() {
    // A full count (1024 bytes, RM 4.30) is an overflow: nothing is read from the FIFO. The
    // INT_STATUS flag is not consulted (one transfer fewer per read): a count below the FIFO
    // size proves no byte was overwritten, since only reads lower it.
    let exp = inited(&[
        T::write_read(A, vec![0x72], vec![0x04, 0x00]),
        // reset_fifo: FIFO_RESET with FIFO_EN = 0, FIFO_EN again, clear INT_STATUS.
        T::write(A, vec![0x6A, 0x04]),
        T::write(A, vec![0x6A, 0x40]),
        T::write_read(A, vec![0x3A], vec![0x11]),
        T::write_read(A, vec![0x72], vec![0x00, 0x00]),
    ]);
    let r = both(
        &exp,
        |d| {
            d.init(&mut NoopDelay, &Config::default()).unwrap();
            let mut out = [RawSample::default(); 4];
            let first = d.read_fifo(&mut out);
            d.reset_fifo().unwrap();
            (first, d.read_fifo(&mut out))
        },
        async |d| {
            d.init(&mut NoopDelay, &Config::default()).await.unwrap();
            let mut out = [RawSample::default(); 4];
            let first = d.read_fifo(&mut out).await;
            d.reset_fifo().await.unwrap();
            (first, d.read_fifo(&mut out).await)
        },
    );
    assert_eq!(r, (Err(Error::FifoOverflow), Ok(0)));
}

#[test]
fn fifo_count_one_below_full_is_read() {
    // 1023 bytes = 85 whole 12-byte frames + 3 bytes: not full, so no byte was lost; the four
    // frames asked for are read.
    let data: Vec<u8> = (0..4).flat_map(|k| frame12(10 * k)).collect();
    let exp = inited(&[
        T::write_read(A, vec![0x72], vec![0x03, 0xFF]),
        T::write_read(A, vec![0x74], data),
    ]);
    let mut d = blocking::Mpu6050::new(Mock::new(&exp), Address::Ad0Low);
    d.init(&mut NoopDelay, &Config::default()).unwrap();
    let mut out = [RawSample::default(); 4];
    assert_eq!(d.read_fifo(&mut out), Ok(4));
    assert_eq!(out[3].accel, [30, 31, 32]);
    d.release().done();
}

#[test]
fn fifo_with_temperature_frames() {
    let cfg = Config {
        fifo: Some(FifoFrame::AccelTempGyro),
        ..Config::default()
    };
    let mut exp = default_init(0x68, default_burst_6050());
    exp[6] = T::write(A, vec![0x23, 0xF8]);
    let frame: Vec<u8> = [1i16, 2, 3, -100, 4, 5, 6]
        .iter()
        .flat_map(|v| v.to_be_bytes())
        .collect();
    exp.extend([
        T::write_read(A, vec![0x72], vec![0x00, 14]),
        T::write_read(A, vec![0x74], frame),
    ]);
    let mut d = blocking::Mpu6050::new(Mock::new(&exp), Address::Ad0Low);
    d.init(&mut NoopDelay, &cfg).unwrap();
    let mut out = [RawSample::default(); 4];
    assert_eq!(d.read_fifo(&mut out), Ok(1));
    assert_eq!(
        out[0],
        RawSample {
            accel: [1, 2, 3],
            temp: Some(-100),
            gyro: [4, 5, 6]
        }
    );
    d.release().done();
}

#[test]
fn fifo_count_masks_to_13_bits() {
    let exp = [T::write_read(A, vec![0x72], vec![0xFF, 0xFF])];
    let n = both(
        &exp,
        |d| d.fifo_count().unwrap(),
        async |d| d.fifo_count().await.unwrap(),
    );
    assert_eq!(n, 0x1FFF);
}

#[test]
fn self_test_refused_on_icm_parts() {
    let exp = [T::write_read(A, vec![0x75], vec![0x98])];
    let mut d = blocking::Mpu6050::new(Mock::new(&exp), Address::Ad0Low);
    assert_eq!(d.probe(), Ok(ChipId::Icm20689));
    assert_eq!(d.self_test(&mut NoopDelay), Err(Error::SelfTestUnsupported));
    d.release().done();
}

fn sample_bytes(accel: [i16; 3], gyro: [i16; 3]) -> Vec<u8> {
    accel
        .iter()
        .chain([0i16].iter())
        .chain(gyro.iter())
        .flat_map(|v| v.to_be_bytes())
        .collect()
}

/// Self-test traffic up to the trim reads, on a chip answering `who`: GYRO_CONFIG = XG/YG/ZG_ST
/// | FS_SEL 0 = 0xE0 and ACCEL_CONFIG = `accel[0]`, 16 sample reads answering `on`, self-test off
/// (GYRO_CONFIG = 0x00, ACCEL_CONFIG = `accel[1]`), 16 sample reads answering `off`.
fn self_test_averages(who: u8, accel: [u8; 2], on: &[u8], off: &[u8]) -> Vec<T> {
    let mut exp = vec![
        T::write_read(A, vec![0x75], vec![who]),
        T::write(A, vec![0x1B, 0xE0]),
        T::write(A, vec![0x1C, accel[0]]),
    ];
    exp.extend((0..16).map(|_| T::write_read(A, vec![0x3B], on.to_vec())));
    exp.push(T::write(A, vec![0x1B, 0x00]));
    exp.push(T::write(A, vec![0x1C, accel[1]]));
    exp.extend((0..16).map(|_| T::write_read(A, vec![0x3B], off.to_vec())));
    exp
}

#[test]
fn self_test_sequence_mpu6050() {
    // RM 4.1: GYRO_CONFIG = XG/YG/ZG_ST | FS_SEL 0 = 0xE0; ACCEL_CONFIG = XA/YA/ZA_ST | AFS_SEL 2
    // (±8 g) = 0xF0; wait, average; self-test off (0x00, 0x10); wait, average; read the four
    // SELF_TEST registers; restore the default ranges (0x00, 0x08).
    // Trim codes 1 everywhere: FT gyro = 3275 LSB (−3275 for Y), FT accel = 1392.64 LSB.
    let on = sample_bytes([1393, 1393, 1393 + 4096], [3275, -3275, 3275]);
    let off = sample_bytes([0, 0, 4096], [0, 0, 0]);
    let mut exp = self_test_averages(0x68, [0xF0, 0x10], &on, &off);
    exp.push(T::write_read(A, vec![0x0D], vec![0x01, 0x01, 0x01, 0x15]));
    exp.push(T::write(A, vec![0x1B, 0x00]));
    exp.push(T::write(A, vec![0x1C, 0x08]));
    let mut delays = vec![D::delay_ms(250)];
    delays.extend((0..16).map(|_| D::delay_ms(2)));
    delays.push(D::delay_ms(250));
    delays.extend((0..16).map(|_| D::delay_ms(2)));
    let r = both(
        &exp,
        |d| {
            d.probe().unwrap();
            let mut delay = CheckedDelay::new(&delays);
            let r = d.self_test(&mut delay).unwrap();
            delay.done();
            r
        },
        async |d| {
            d.probe().await.unwrap();
            let mut delay = CheckedDelay::new(&delays);
            let r = d.self_test(&mut delay).await.unwrap();
            delay.done();
            r
        },
    );
    // Gyro exactly at trim: 0 %. Accel 1393 vs 1392.64: +0.026 % (tolerance 0.001 points).
    assert_eq!(r.gyro_change_pct, [0.0; 3]);
    for c in r.accel_change_pct {
        assert!((c - 0.0259).abs() < 1e-3, "{r:?}");
    }
    assert_eq!(r.gyro_limits_pct, [-14.0, 14.0]);
    assert!(r.passed());
}

#[test]
fn self_test_sequence_mpu6500() {
    // AN-MPU-6500A-02: ±250 °/s (0xE0 with ST bits), ±2 g (0xE0 with ST bits); OTP codes from
    // 0x00..0x02 (gyro) and 0x0D..0x0F (accel). Code 1: ST_OTP = 2620 LSB.
    // Responses: gyro 1310 (ratio 0.5 → −50 %, on the limit), accel 3930 (ratio 1.5 → +50 %).
    let on = sample_bytes([3930, 3930, 3930 + 16384], [1310, 2620, 2620]);
    let off = sample_bytes([0, 0, 16384], [0, 0, 0]);
    let mut exp = self_test_averages(0x70, [0xE0, 0x00], &on, &off);
    exp.push(T::write_read(A, vec![0x00], vec![1, 1, 1]));
    exp.push(T::write_read(A, vec![0x0D], vec![1, 1, 1]));
    exp.push(T::write(A, vec![0x1B, 0x00]));
    exp.push(T::write(A, vec![0x1C, 0x08]));
    let r = both(
        &exp,
        |d| {
            d.probe().unwrap();
            d.self_test(&mut NoopDelay).unwrap()
        },
        async |d| {
            d.probe().await.unwrap();
            d.self_test(&mut NoopDelay).await.unwrap()
        },
    );
    assert_eq!(r.gyro_change_pct, [-50.0, 0.0, 0.0]);
    assert_eq!(r.accel_change_pct, [50.0, 50.0, 50.0]);
    assert!(r.passed(), "limits are inclusive: {r:?}");
}

#[test]
fn error_messages_name_the_register() {
    let e: Error<ErrorKind> = Error::WrongChip { found: 0x42 };
    let msg = e.to_string();
    assert!(msg.contains("WHO_AM_I") && msg.contains("0x42"), "{msg}");
}

/// `config_intact` reads back SMPLRT_DIV..ACCEL_CONFIG (one burst), FIFO_EN, then USER_CTRL and
/// PWR_MGMT_1 together; what `init` wrote reads as intact, a part back at its power-on values
/// (PWR_MGMT_1 = 0x40, asleep, RM 4.28) or with the FIFO off does not.
#[test]
fn config_intact_reads_back_what_init_wrote() {
    let readback = |power: u8, user: u8| {
        inited(&[
            T::write_read(A, vec![0x19], vec![0x00, 0x06, 0x00, 0x08]),
            T::write_read(A, vec![0x23], vec![0x78]),
            T::write_read(A, vec![0x6A], vec![user, power]),
        ])
    };
    let check = |exp: &[T]| {
        both(
            exp,
            |d| {
                d.init(&mut NoopDelay, &Config::default()).unwrap();
                d.config_intact().unwrap()
            },
            async |d| {
                d.init(&mut NoopDelay, &Config::default()).await.unwrap();
                d.config_intact().await.unwrap()
            },
        )
    };
    assert!(check(&readback(0x01, 0x40)));
    assert!(!check(&readback(0x40, 0x40)), "asleep after a power cycle");
    assert!(!check(&readback(0x01, 0x00)), "FIFO off");
}

/// `stop_fifo` writes USER_CTRL = FIFO_RESET alone (0x04, RM 4.27: the reset acts only with
/// FIFO_EN clear) and `start_fifo` USER_CTRL = FIFO_EN (0x40); `int_status` reads INT_STATUS
/// (0x3A) and names its bits (FIFO_OFLOW_INT bit 4, DATA_RDY_INT bit 0, RM 4.16).
#[test]
fn fifo_stop_start_and_interrupt_status_transactions() {
    let exp = inited(&[
        T::write(A, vec![0x6A, 0x04]),
        T::write(A, vec![0x6A, 0x40]),
        T::write_read(A, vec![0x3A], vec![0x11]),
    ]);
    let st = both(
        &exp,
        |d| {
            d.init(&mut NoopDelay, &Config::default()).unwrap();
            d.stop_fifo().unwrap();
            d.start_fifo().unwrap();
            d.int_status().unwrap()
        },
        async |d| {
            d.init(&mut NoopDelay, &Config::default()).await.unwrap();
            d.stop_fifo().await.unwrap();
            d.start_fifo().await.unwrap();
            d.int_status().await.unwrap()
        },
    );
    assert!(st.fifo_overflow && st.data_ready && !st.i2c_master);
}

/// The count and the frames in one transaction (RM 4.30, 4.31): FIFO_COUNT_H/L, then after a
/// repeated START the frames asked for from FIFO_R_W; what the count covers is reported, and a
/// full count is an overflow.
#[test]
fn counted_fifo_read_is_one_transaction_with_a_repeated_start() {
    let frames: Vec<u8> = (0..3).flat_map(|k| frame12(10 * k)).collect();
    let one = |count: [u8; 2], data: Vec<u8>| {
        vec![
            T::transaction_start(A),
            T::write(A, vec![0x72]),
            T::read(A, count.to_vec()),
            T::write(A, vec![0x74]),
            T::read(A, data),
            T::transaction_end(A),
        ]
    };
    let run = |tail: Vec<T>| {
        let exp = inited(&tail);
        both(
            &exp,
            |d| {
                d.init(&mut NoopDelay, &Config::default()).unwrap();
                let (mut head, mut out) = ([0u8; 2], [0u8; 64]);
                let r = d.read_counted_fifo_raw(3, &mut head, &mut out);
                (r, out[24..36].to_vec())
            },
            async |d| {
                d.init(&mut NoopDelay, &Config::default()).await.unwrap();
                let (mut head, mut out) = ([0u8; 2], [0u8; 64]);
                let r = d.read_counted_fifo_raw(3, &mut head, &mut out).await;
                (r, out[24..36].to_vec())
            },
        )
    };
    // 40 bytes: the three frames asked for and part of a fourth; all three covered.
    let (r, third) = run(one([0, 40], frames.clone()));
    let c = r.unwrap();
    assert_eq!((c.count, c.read, c.covered, c.whole()), (40, 3, 3, true));
    assert_eq!(third, frame12(20));
    // 30 bytes: only two whole frames were there at the count; the third is not covered.
    let (r, _) = run(one([0, 30], frames.clone()));
    let c = r.unwrap();
    assert_eq!((c.count, c.read, c.covered, c.whole()), (30, 3, 2, false));
    // A full count: an overflow.
    let (r, _) = run(one([0x04, 0x00], frames));
    assert_eq!(r, Err(Error::FifoOverflow));
}
