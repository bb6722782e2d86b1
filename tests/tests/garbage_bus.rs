//! "No panic on any byte the bus returns": every driver entry point against a bus that
//! answers arbitrary bytes and fails arbitrary transactions (proptest, blocking and async).

use embassy_futures::block_on;
use embedded_hal::i2c::{ErrorKind, ErrorType, Operation};
use embedded_hal_mock::eh1::delay::NoopDelay;
use imu_drivers::mpu6050::{self, Address, RawSample};
use imu_drivers::qmc5883::{self, Variant};
use imu_drivers::{asynch, blocking};
use proptest::prelude::*;

/// Answers bytes from `data` (cycled) and fails transaction k when bit k of `fail` is set.
struct Garbage {
    data: Vec<u8>,
    pos: usize,
    fail: u64,
    n: u32,
}

impl Garbage {
    fn new(data: Vec<u8>, fail: u64) -> Self {
        Garbage {
            data,
            pos: 0,
            fail,
            n: 0,
        }
    }
    fn run(&mut self, ops: &mut [Operation<'_>]) -> Result<(), ErrorKind> {
        let k = self.n;
        self.n = self.n.wrapping_add(1);
        if k < 64 && self.fail >> k & 1 == 1 {
            return Err(ErrorKind::Other);
        }
        for op in ops {
            if let Operation::Read(buf) = op {
                for b in buf.iter_mut() {
                    *b = if self.data.is_empty() {
                        0
                    } else {
                        self.data[self.pos % self.data.len()]
                    };
                    self.pos += 1;
                }
            }
        }
        Ok(())
    }
}

impl ErrorType for Garbage {
    type Error = ErrorKind;
}
impl embedded_hal::i2c::I2c for Garbage {
    fn transaction(&mut self, _a: u8, ops: &mut [Operation<'_>]) -> Result<(), ErrorKind> {
        self.run(ops)
    }
}
impl embedded_hal_async::i2c::I2c for Garbage {
    async fn transaction(&mut self, _a: u8, ops: &mut [Operation<'_>]) -> Result<(), ErrorKind> {
        self.run(ops)
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn mpu_blocking_never_panics(data in proptest::collection::vec(any::<u8>(), 0..600), fail in any::<u64>(), room in 0usize..70) {
        let mut d = blocking::Mpu6050::new(Garbage::new(data.clone(), fail), Address::Ad0Low);
        match d.init(&mut NoopDelay, &mpu6050::Config::default()) {
            Err(mpu6050::Error::WrongChip { found }) => {
                prop_assert!(mpu6050::ChipId::from_who_am_i(found).is_none());
            }
            Ok(chip) => prop_assert_eq!(Some(chip), mpu6050::ChipId::from_who_am_i(data[0])),
            Err(_) => {}
        }
        let _ = d.read_all();
        let _ = d.read_if_ready();
        let _ = d.fifo_count();
        let mut out = vec![RawSample::default(); room];
        if let Ok(n) = d.read_fifo(&mut out) {
            prop_assert!(n <= room);
        }
        let _ = d.reset_fifo();
        if let Ok(r) = d.self_test(&mut NoopDelay) {
            let _ = r.passed();
        }
        let s = d.scale();
        let _ = s.convert(&RawSample { accel: [i16::MIN; 3], temp: Some(i16::MAX), gyro: [i16::MIN; 3] });
    }

    #[test]
    fn mpu_async_never_panics(data in proptest::collection::vec(any::<u8>(), 0..600), fail in any::<u64>(), room in 0usize..70) {
        let mut d = asynch::Mpu6050::new(Garbage::new(data, fail), Address::Ad0High);
        block_on(async {
            let _ = d.init(&mut NoopDelay, &mpu6050::Config::default()).await;
            let _ = d.read_all().await;
            let mut out = vec![RawSample::default(); room];
            if let Ok(n) = d.read_fifo(&mut out).await {
                assert!(n <= room);
            }
            let _ = d.reset_fifo().await;
            let _ = d.self_test(&mut NoopDelay).await;
        });
    }

    #[test]
    fn mag_never_panics(data in proptest::collection::vec(any::<u8>(), 0..64), fail in any::<u64>(), p in any::<bool>()) {
        let v = if p { Variant::P } else { Variant::L };
        let mut bus = Garbage::new(data.clone(), fail);
        let _ = blocking::Qmc5883::detect(&mut bus);
        let mut d = blocking::Qmc5883::new_variant(bus, v);
        let _ = d.init(&mut NoopDelay, &qmc5883::Config::default());
        for _ in 0..4 {
            if let Ok(s) = d.read() {
                let _ = d.microtesla(&s);
            }
        }
        let mut bus = Garbage::new(data, fail);
        block_on(async {
            let _ = asynch::Qmc5883::detect(&mut bus).await;
            let mut d = asynch::Qmc5883::new_variant(bus, v);
            let _ = d.init(&mut NoopDelay, &qmc5883::Config::default()).await;
            let _ = d.read().await;
        });
    }
}
