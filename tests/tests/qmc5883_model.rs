//! QMC5883L/P driver against the register-level model on the simulated bus: measurement
//! rate, DRDY / DOR / OVL behaviour, ranges, temperature, detection on a shared bus.

use embassy_futures::block_on;
use imu_drivers::mpu6050::{self, Address};
use imu_drivers::qmc5883::{Chip, Config, Error, Odr, Range, Variant};
use imu_drivers::{asynch, blocking};
use pico_imu_tests::{Mpu6050Model, QmcModel, QmcVariant, SimBus};

fn init(bus: &SimBus, v: Variant, cfg: &Config) -> blocking::Qmc5883<SimBus> {
    let mut d = blocking::Qmc5883::new_variant(bus.clone(), v);
    d.init(&mut bus.delay(), cfg).unwrap();
    d
}

#[test]
fn l_default_reads_field_temperature_and_rate() {
    let bus = SimBus::new().with_mag(QmcModel::new(QmcVariant::L));
    let mut d = init(&bus, Variant::L, &Config::default());
    bus.mag(|m| {
        assert_eq!(m.reg(0x09), 0x0D, "CONTROL1");
        assert_eq!(m.reg(0x0B), 0x01, "SET/RESET period");
        assert_eq!(m.period_ns(), 5_000_000, "200 Hz");
    });
    assert_eq!(d.read(), Err(Error::NotReady));
    bus.advance_us(5_000);
    let s = d.read().unwrap();
    // (0.2, −0.1, 0.4) G × 12000 LSB/G (±2 G, QMC-L specification table).
    assert_eq!(s.xyz, [2400, -1200, 4800]);
    assert_eq!(s.temp, Some(2500), "25 °C × 100 LSB/°C");
    assert!(!s.overflow && !s.skipped);
    let ut = d.microtesla(&s);
    // 0.2 G = 20 µT etc. (tolerance 1e-4 µT for f32 rounding).
    for (got, want) in ut.iter().zip([20.0, -10.0, 40.0]) {
        assert!((got - want).abs() < 1e-4, "{ut:?}");
    }
    assert_eq!(
        d.read(),
        Err(Error::NotReady),
        "DRDY cleared by the data read"
    );
    // One second: 200 measurements (QMC-L ODR 200 Hz), counted by the model.
    let before = bus.mag(|m| m.measurements);
    bus.advance_us(1_000_000);
    assert_eq!(bus.mag(|m| m.measurements) - before, 200);
}

#[test]
fn l_roll_over_reads_status_and_data_in_one_transfer() {
    let mut m = QmcModel::new(QmcVariant::L);
    m.field = Box::new(|i| {
        if i < 2 {
            [0.1, 0.1, 0.1]
        } else {
            [0.2, -0.1, 0.4]
        }
    });
    let bus = SimBus::new().with_mag(m);
    let cfg = Config {
        roll_over: true,
        ..Config::default()
    };
    let mut d = init(&bus, Variant::L, &cfg);
    bus.mag(|m| assert_eq!(m.reg(0x0A), 0x40, "CONTROL2: ROL_PNT, DRDY pin on"));
    assert_eq!(d.read(), Err(Error::NotReady));
    bus.advance_us(10_000); // two measurements, the first overwritten
    let s = d.read().unwrap();
    assert_eq!(s.xyz, [1200, 1200, 1200]);
    assert!(s.skipped, "DOR read with the data, in the same transfer");
    assert_eq!(
        s.temp, None,
        "the roll-over read stops before the temperature"
    );
    assert_eq!(
        d.read(),
        Err(Error::NotReady),
        "the data bytes cleared DRDY"
    );
    bus.advance_us(5_000);
    let s = d.read().unwrap();
    assert_eq!(s.xyz, [2400, -1200, 4800]);
    assert!(!s.skipped);
}

#[test]
fn l_skipped_and_overflow_flags() {
    let mut m = QmcModel::new(QmcVariant::L);
    m.field = Box::new(|i| {
        if i < 4 {
            [0.1, 0.1, 0.1]
        } else {
            [2.5, 0.0, 0.0]
        }
    });
    let bus = SimBus::new().with_mag(m);
    let mut d = init(&bus, Variant::L, &Config::default());
    bus.advance_us(20_000); // four measurements, none read
    let s = d.read().unwrap();
    assert!(s.skipped, "DOR after unread measurements");
    assert!(!s.overflow);
    bus.advance_us(5_000); // fifth: 2.5 G on the ±2 G range
    let s = d.read().unwrap();
    assert!(!s.skipped);
    assert!(s.overflow, "OVL beyond ±2 G");
    assert_eq!(s.xyz[0], 30000);
}

#[test]
fn l_8_gauss_range_and_lower_rate() {
    let bus = SimBus::new().with_mag(QmcModel::new(QmcVariant::L));
    let cfg = Config {
        range: Range::G8,
        odr: Odr::Hz50,
        ..Config::default()
    };
    let mut d = init(&bus, Variant::L, &cfg);
    bus.advance_us(19_000);
    assert_eq!(
        d.read(),
        Err(Error::NotReady),
        "50 Hz: nothing before 20 ms"
    );
    bus.advance_us(1_000);
    assert_eq!(d.read().unwrap().xyz, [600, -300, 1200], "3000 LSB/G");
    assert_eq!(d.lsb_per_gauss(), 3000.0);
}

#[test]
fn p_variant_async() {
    let bus = SimBus::new().with_mag(QmcModel::new(QmcVariant::P));
    let mut d = asynch::Qmc5883::new_variant(bus.clone(), Variant::P);
    block_on(d.init(&mut bus.delay(), &Config::default())).unwrap();
    bus.mag(|m| {
        assert_eq!(m.reg(0x0A), 0x0F, "CONTROL1");
        assert_eq!(m.reg(0x0B), 0x0C, "CONTROL2 ±2 G");
        assert_eq!(m.reg(0x29), 0x06, "axis sign");
    });
    bus.advance_us(5_000);
    let s = block_on(d.read()).unwrap();
    assert_eq!(s.xyz, [3000, -1500, 6000], "15000 LSB/G at ±2 G (QMC-P)");
    assert_eq!(s.temp, None);
    assert_eq!(block_on(d.read()), Err(Error::NotReady));
}

#[test]
fn wrong_variant_is_wrong_chip_or_nack() {
    // A P at 0x2C, driven as an L at 0x0D: nobody answers.
    let bus = SimBus::new().with_mag(QmcModel::new(QmcVariant::P));
    let mut d = blocking::Qmc5883::new(bus.clone());
    assert!(matches!(
        d.init(&mut bus.delay(), &Config::default()),
        Err(Error::Bus(_))
    ));
    // An L whose id register reads 0x00 (counterfeit / damaged).
    let mut m = QmcModel::new(QmcVariant::L);
    m.chip_id = 0x00;
    let bus = SimBus::new().with_mag(m);
    let mut d = blocking::Qmc5883::new(bus.clone());
    assert_eq!(
        d.init(&mut bus.delay(), &Config::default()),
        Err(Error::WrongChip { found: 0x00 })
    );
}

#[test]
fn detect_on_a_shared_bus() {
    let mpu = || Mpu6050Model::new(0x68, 0x68);
    let cases = [
        (
            SimBus::new()
                .with_mpu(mpu())
                .with_mag(QmcModel::new(QmcVariant::L)),
            Chip::Qmc5883L,
        ),
        (
            SimBus::new()
                .with_mpu(mpu())
                .with_mag(QmcModel::new(QmcVariant::P)),
            Chip::Qmc5883P,
        ),
        (
            SimBus::new().with_mpu(mpu()).with_hmc5883l(),
            Chip::Hmc5883L,
        ),
        (SimBus::new().with_mpu(mpu()), Chip::None),
    ];
    for (bus, want) in cases {
        let mut b = bus.clone();
        assert_eq!(blocking::Qmc5883::detect(&mut b), want);
        assert_eq!(block_on(asynch::Qmc5883::detect(&mut b)), want);
    }
}

#[test]
fn both_sensors_share_one_bus() {
    let bus = SimBus::new()
        .with_mpu(Mpu6050Model::new(0x68, 0x70))
        .with_mag(QmcModel::new(QmcVariant::L));
    let mut imu = blocking::Mpu6050::new(bus.clone(), Address::Ad0Low);
    let mut mag = blocking::Qmc5883::new(bus.clone());
    assert_eq!(
        imu.init(&mut bus.delay(), &mpu6050::Config::default()),
        Ok(mpu6050::ChipId::Mpu6500)
    );
    mag.init(&mut bus.delay(), &Config::default()).unwrap();
    // 100 ms: 20 magnetometer samples at 200 Hz, read every 5 ms together with the IMU FIFO;
    // the IMU also sampled during the magnetometer's 1 ms soft-reset wait: 101 frames.
    let mut frames = [mpu6050::RawSample::default(); 16];
    let (mut n_imu, mut n_mag) = (0, 0);
    for _ in 0..20 {
        bus.advance_us(5_000);
        n_imu += imu.read_fifo(&mut frames).unwrap();
        n_mag += usize::from(mag.read().is_ok());
    }
    assert_eq!((n_imu, n_mag), (101, 20));
}
