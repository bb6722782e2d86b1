//! QMC5883L/P driver against embedded-hal-mock transaction lists, blocking and async.
//! Expected bytes are derived from the QST data sheets (QMC-L 9.2 and the QMC-P register map).

use embassy_futures::block_on;
use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};
use embedded_hal_mock::eh1::delay::{CheckedDelay, NoopDelay, Transaction as D};
use embedded_hal_mock::eh1::i2c::{Mock, Transaction as T};
use imu_drivers::qmc5883::{Chip, Config, Error, MagSample, Mode, Odr, Osr, Range, Variant};
use imu_drivers::{asynch, blocking};

const L: u8 = 0x0D;
const P: u8 = 0x2C;
const NACK: ErrorKind = ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address);

fn both<R: PartialEq + std::fmt::Debug>(
    variant: Variant,
    exp: &[T],
    b: impl FnOnce(&mut blocking::Qmc5883<Mock>) -> R,
    a: impl AsyncFnOnce(&mut asynch::Qmc5883<Mock>) -> R,
) -> R {
    let mut d1 = blocking::Qmc5883::new_variant(Mock::new(exp), variant);
    let r1 = b(&mut d1);
    d1.release().done();
    let mut d2 = asynch::Qmc5883::new_variant(Mock::new(exp), variant);
    let r2 = block_on(a(&mut d2));
    d2.release().done();
    assert_eq!(r1, r2, "blocking and async results differ");
    r1
}

/// `init` with `cfg`, blocking and async (the same result from both).
fn init_ok(variant: Variant, exp: &[T], cfg: &Config) {
    both(
        variant,
        exp,
        |d| d.init(&mut NoopDelay, cfg).unwrap(),
        async |d| d.init(&mut NoopDelay, cfg).await.unwrap(),
    )
}

/// `init` with `cfg` failing, blocking and async (the same error from both).
fn init_err(variant: Variant, exp: &[T], cfg: &Config) -> Error<ErrorKind> {
    both(
        variant,
        exp,
        |d| d.init(&mut NoopDelay, cfg).unwrap_err(),
        async |d| d.init(&mut NoopDelay, cfg).await.unwrap_err(),
    )
}

/// The traffic of `init` on `variant`: the chip id read, a soft reset (CONTROL2 = 0x80), the
/// variant's one setup write, then CONTROL2 = `control2` and CONTROL1 = `control1`.
fn init_traffic(variant: Variant, control2: u8, control1: u8) -> Vec<T> {
    // (address, chip id register and value, CONTROL2, setup write, CONTROL1)
    let (addr, id, ctrl2, setup, ctrl1) = match variant {
        // Chip id 0x0D = 0xFF; CONTROL2 0x0A; SET/RESET period (0x0B) = 0x01; CONTROL1 0x09.
        Variant::L => (L, [0x0D, 0xFF], 0x0A, [0x0B, 0x01], 0x09),
        // Chip id reg 0x00 = 0x80; CONTROL2 0x0B; axis sign (0x29) = 0x06; CONTROL1 0x0A.
        Variant::P => (P, [0x00, 0x80], 0x0B, [0x29, 0x06], 0x0A),
    };
    vec![
        T::write_read(addr, vec![id[0]], vec![id[1]]),
        T::write(addr, vec![ctrl2, 0x80]),
        T::write(addr, setup.to_vec()),
        T::write(addr, vec![ctrl2, control2]),
        T::write(addr, vec![ctrl1, control1]),
    ]
}

/// QMC5883L default configuration: CONTROL2 = 0x00 (DRDY pin on); CONTROL1 = OSR 512 (00) |
/// RNG 2 G (00) | ODR 200 Hz (11) | continuous (01) = 0b0000_1101 = 0x0D.
fn l_default() -> Vec<T> {
    init_traffic(Variant::L, 0x00, 0x0D)
}

#[test]
fn l_default_init() {
    both(
        Variant::L,
        &l_default(),
        |d| {
            let mut delay = CheckedDelay::new(&[D::delay_ms(1)]);
            d.init(&mut delay, &Config::default()).unwrap();
            delay.done();
        },
        async |d| {
            let mut delay = CheckedDelay::new(&[D::delay_ms(1)]);
            d.init(&mut delay, &Config::default()).await.unwrap();
            delay.done();
        },
    );
}

#[test]
fn l_other_settings() {
    // OSR 64 (11), 8 G (01), 10 Hz (00), standby (00) = 0b1101_0000 = 0xD0; pin off: 0x0A = 0x01.
    let cfg = Config {
        range: Range::G8,
        odr: Odr::Hz10,
        osr: Osr::Min,
        mode: Mode::Standby,
        set_reset_period: 0x01,
        drdy_pin: false,
        roll_over: false,
    };
    let exp = init_traffic(Variant::L, 0x01, 0xD0);
    init_ok(Variant::L, &exp, &cfg);
}

#[test]
fn p_default_init() {
    // CONTROL2 = RNG ±2 G (11 in bits 3:2) = 0x0C, set/reset on; CONTROL1 = OSR2 1 (00) |
    // OSR1 8 (00) | ODR 200 Hz (11) | continuous (11) = 0x0F.
    let exp = init_traffic(Variant::P, 0x0C, 0x0F);
    init_ok(Variant::P, &exp, &Config::default());
}

#[test]
fn p_30_gauss_range() {
    let cfg = Config {
        range: Range::G30,
        ..Config::default()
    };
    // CONTROL2 = RNG ±30 G (00 in bits 3:2), set/reset on.
    let exp = init_traffic(Variant::P, 0x00, 0x0F);
    let mut d = blocking::Qmc5883::new_variant(Mock::new(&exp), Variant::P);
    d.init(&mut NoopDelay, &cfg).unwrap();
    assert_eq!(d.lsb_per_gauss(), 1000.0);
    d.release().done();
}

#[test]
fn l_rejects_p_only_range_without_bus_traffic() {
    let cfg = Config {
        range: Range::G12,
        ..Config::default()
    };
    let e = both(
        Variant::L,
        &[],
        |d| d.init(&mut NoopDelay, &cfg).unwrap_err(),
        async |d| d.init(&mut NoopDelay, &cfg).await.unwrap_err(),
    );
    assert_eq!(e, Error::InvalidConfig);
}

#[test]
fn wrong_chip_id() {
    for (variant, addr, reg, found) in [(Variant::L, L, 0x0D, 0x00), (Variant::P, P, 0x00, 0xFF)] {
        let exp = [T::write_read(addr, vec![reg], vec![found])];
        let e = both(
            variant,
            &exp,
            |d| d.init(&mut NoopDelay, &Config::default()).unwrap_err(),
            async |d| {
                d.init(&mut NoopDelay, &Config::default())
                    .await
                    .unwrap_err()
            },
        );
        assert_eq!(e, Error::WrongChip { found });
    }
}

#[test]
fn nack_is_bus_error() {
    let exp = [T::write_read(L, vec![0x0D], vec![0]).with_error(NACK)];
    let e = init_err(Variant::L, &exp, &Config::default());
    assert_eq!(e, Error::Bus(NACK));
}

#[test]
fn l_read_with_flags() {
    // Status 0x07 = DRDY | OVL | DOR, temperature 2500 (0x09C4 LE), then X=-2 Y=1000 Z=32767.
    let exp = [
        T::write_read(L, vec![0x06], vec![0x07, 0xC4, 0x09]),
        T::write_read(L, vec![0x00], vec![0xFE, 0xFF, 0xE8, 0x03, 0xFF, 0x7F]),
    ];
    let s = both(
        Variant::L,
        &exp,
        |d| d.read().unwrap(),
        async |d| d.read().await.unwrap(),
    );
    assert_eq!(
        s,
        MagSample {
            xyz: [-2, 1000, 32767],
            temp: Some(2500),
            overflow: true,
            skipped: true
        }
    );
}

#[test]
fn l_not_ready_does_not_touch_data_registers() {
    let exp = [T::write_read(L, vec![0x06], vec![0x06, 0, 0])];
    let e = both(
        Variant::L,
        &exp,
        |d| d.read().unwrap_err(),
        async |d| d.read().await.unwrap_err(),
    );
    assert_eq!(e, Error::NotReady);
}

/// ROL_PNT (CONTROL2 bit 6 → 0x40 with the DRDY pin on): the measurement is one 7-byte read
/// from 06H, status then X, Y, Z (the pointer rolls from 06H to 00H).
#[test]
fn l_roll_over_read_is_one_transfer() {
    let cfg = Config {
        roll_over: true,
        ..Config::default()
    };
    // CONTROL2 = 0x40: pointer roll-over on, DRDY pin on.
    let mut exp = init_traffic(Variant::L, 0x40, 0x0D);
    exp.push(T::write_read(
        L,
        vec![0x06],
        vec![0x05, 0xFE, 0xFF, 0xE8, 0x03, 0xFF, 0x7F],
    ));
    exp.push(T::write_read(L, vec![0x06], vec![0x00, 1, 2, 3, 4, 5, 6]));
    let (s, e) = both(
        Variant::L,
        &exp,
        |d| {
            d.init(&mut NoopDelay, &cfg).unwrap();
            (d.read().unwrap(), d.read().unwrap_err())
        },
        async |d| {
            d.init(&mut NoopDelay, &cfg).await.unwrap();
            (d.read().await.unwrap(), d.read().await.unwrap_err())
        },
    );
    assert_eq!(
        s,
        MagSample {
            xyz: [-2, 1000, 32767],
            temp: None,
            overflow: false,
            skipped: true
        }
    );
    assert_eq!(
        e,
        Error::NotReady,
        "DRDY clear: the data bytes are discarded"
    );
}

#[test]
fn p_read() {
    // P status 0x09: DRDY; bit 2 means nothing on the P (no DOR) and must not be reported.
    let exp = [
        T::write_read(P, vec![0x09], vec![0x05]),
        T::write_read(P, vec![0x01], vec![0x01, 0x00, 0x00, 0x80, 0x10, 0x27]),
        T::write_read(P, vec![0x09], vec![0x00]),
    ];
    let (s, e) = both(
        Variant::P,
        &exp,
        |d| (d.read().unwrap(), d.read().unwrap_err()),
        async |d| (d.read().await.unwrap(), d.read().await.unwrap_err()),
    );
    assert_eq!(
        s,
        MagSample {
            xyz: [1, -32768, 10000],
            temp: None,
            overflow: false,
            skipped: false
        }
    );
    assert_eq!(e, Error::NotReady);
}

#[test]
fn microtesla_conversion() {
    let d = blocking::Qmc5883::new(Mock::new(&[]));
    // L ±2 G: 12000 LSB/G (QMC-L specification table), 1 G = 100 µT: 12000 → 100 µT, -600 → -5 µT.
    let ut = d.microtesla(&MagSample {
        xyz: [12000, -600, 0],
        ..MagSample::default()
    });
    assert_eq!(ut, [100.0, -5.0, 0.0]);
    d.release().done();
}

#[test]
fn detect_each_chip() {
    // QMC5883L present.
    let exp = [T::write_read(L, vec![0x0D], vec![0xFF])];
    let mut m = Mock::new(&exp);
    assert_eq!(blocking::Qmc5883::detect(&mut m), Chip::Qmc5883L);
    m.done();
    // Only a QMC5883P.
    let exp = [
        T::write_read(L, vec![0x0D], vec![0]).with_error(NACK),
        T::write_read(P, vec![0x00], vec![0x80]),
    ];
    let mut m = Mock::new(&exp);
    assert_eq!(block_on(asynch::Qmc5883::detect(&mut m)), Chip::Qmc5883P);
    m.done();
    // Only an HMC5883L.
    let exp = [
        T::write_read(L, vec![0x0D], vec![0]).with_error(NACK),
        T::write_read(P, vec![0x00], vec![0]).with_error(NACK),
        T::write_read(0x1E, vec![10], b"H43".to_vec()),
    ];
    let mut m = Mock::new(&exp);
    assert_eq!(blocking::Qmc5883::detect(&mut m), Chip::Hmc5883L);
    m.done();
    // Something answers everywhere with the wrong identity: none.
    let exp = [
        T::write_read(L, vec![0x0D], vec![0x00]),
        T::write_read(P, vec![0x00], vec![0x00]),
        T::write_read(0x1E, vec![10], b"H44".to_vec()),
    ];
    let mut m = Mock::new(&exp);
    assert_eq!(blocking::Qmc5883::detect(&mut m), Chip::None);
    m.done();
}

/// `config_intact` reads CONTROL1 and CONTROL2 in one burst (L: 0x09, 0x0A; P: 0x0A, 0x0B) and
/// compares them with what `init` wrote; a soft reset's zeros do not match.
#[test]
fn config_intact_reads_back_both_controls() {
    for (variant, addr, c1, written) in [
        (Variant::L, L, 0x09, [0x0D, 0x00]),
        (Variant::P, P, 0x0A, [0x0F, 0x0C]),
    ] {
        for (back, intact) in [(written, true), ([0x00, 0x00], false)] {
            let control2 = written[1];
            let mut exp = init_traffic(variant, control2, written[0]);
            exp.push(T::write_read(addr, vec![c1], back.to_vec()));
            let got = both(
                variant,
                &exp,
                |d| {
                    d.init(&mut NoopDelay, &Config::default()).unwrap();
                    d.config_intact().unwrap()
                },
                async |d| {
                    d.init(&mut NoopDelay, &Config::default()).await.unwrap();
                    d.config_intact().await.unwrap()
                },
            );
            assert_eq!(got, intact, "{variant:?} read back {back:02x?}");
        }
    }
}

/// `status` reads the status register alone (L 0x06: DRDY bit 0, OVL bit 1, DOR bit 2; P 0x09:
/// DOR does not exist) and `read_data` the six data bytes alone (L from 0x00, P from 0x01),
/// little-endian.
#[test]
fn status_and_data_alone() {
    for (variant, addr, status_reg, data_reg, skipped) in [
        (Variant::L, L, 0x06, 0x00, true),
        (Variant::P, P, 0x09, 0x01, false),
    ] {
        let exp = [
            T::write_read(addr, vec![status_reg], vec![0b0000_0111]),
            T::write_read(
                addr,
                vec![data_reg],
                vec![0x01, 0x02, 0xFF, 0xFF, 0x00, 0x80],
            ),
        ];
        let (st, xyz) = both(
            variant,
            &exp,
            |d| (d.status().unwrap(), d.read_data().unwrap()),
            async |d| (d.status().await.unwrap(), d.read_data().await.unwrap()),
        );
        assert!(st.ready && st.overflow, "{variant:?}");
        assert_eq!(st.skipped, skipped, "{variant:?}");
        assert_eq!(xyz, [0x0201, -1, i16::MIN], "{variant:?}");
    }
}

/// `status_and_data`: one transaction, the status register's byte, then after a repeated START
/// the six data bytes (L: 0x06 then 0x00; P: 0x09 then 0x01); a clear DRDY is reported as read
/// (the caller decides what the data mean).
#[test]
fn status_and_data_in_one_transaction() {
    for (variant, addr, status_reg, data_reg, status, ready) in [
        (Variant::L, L, 0x06, 0x00, 0b0000_0001, true),
        (Variant::L, L, 0x06, 0x00, 0b0000_0000, false),
        (Variant::P, P, 0x09, 0x01, 0b0000_0001, true),
    ] {
        let exp = [
            T::transaction_start(addr),
            T::write(addr, vec![status_reg]),
            T::read(addr, vec![status]),
            T::write(addr, vec![data_reg]),
            T::read(addr, vec![0x01, 0x02, 0xFF, 0xFF, 0x00, 0x80]),
            T::transaction_end(addr),
        ];
        let (st, xyz) = both(
            variant,
            &exp,
            |d| d.status_and_data().unwrap(),
            async |d| d.status_and_data().await.unwrap(),
        );
        assert_eq!(st.ready, ready, "{variant:?}");
        assert_eq!(xyz, [0x0201, -1, i16::MIN], "{variant:?}");
    }
}
