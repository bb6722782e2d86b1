//! Register-level model of the MPU-6050 (and WHO_AM_I-compatible clones), written from the
//! InvenSense "MPU-6000/MPU-6050 Register Map and Descriptions" rev 4.2 (RM):
//!
//! - samples are produced at Gyroscope Output Rate / (1 + SMPLRT_DIV), where the gyro output
//!   rate is 8 kHz for DLPF_CFG 0 or 7 and 1 kHz otherwise (RM 4.2); none while asleep or
//!   while DEVICE_RESET is in progress (100 ms, PS 6.3: the model NACKs in that window);
//! - each sample updates ACCEL_XOUT_H..GYRO_ZOUT_L (big-endian) and, with USER_CTRL.FIFO_EN,
//!   appends the FIFO_EN-selected outputs in register order (RM 4.6, 4.31);
//! - the FIFO holds `fifo_capacity` bytes (1024, RM 4.30); beyond that the oldest bytes are
//!   dropped and FIFO_OFLOW_INT is raised (if enabled) — frame alignment is then lost;
//! - INT_STATUS bits are set only for enabled interrupts and clear when INT_STATUS is read
//!   (RM 4.16); reads of FIFO_R_W pop the FIFO without advancing the register pointer;
//! - FIFO_RESET acts only while FIFO_EN is 0 in the same write (RM 4.27);
//! - self-test bits add a configured self-test response (LSB) to the outputs (RM 4.1).

use std::collections::VecDeque;

use embedded_hal::i2c::{NoAcknowledgeSource, Operation};

use crate::SimError;
use imu_drivers::mpu6050::reg;

/// Physical input at one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// Specific force, g.
    pub accel_g: [f64; 3],
    /// Angular rate, °/s.
    pub gyro_dps: [f64; 3],
    /// Die temperature, °C.
    pub temp_c: f64,
}

impl Default for Motion {
    /// At rest, Z up, 25 °C.
    fn default() -> Self {
        Motion {
            accel_g: [0.0, 0.0, 1.0],
            gyro_dps: [0.0; 3],
            temp_c: 25.0,
        }
    }
}

/// Source of the physical input, called with the sample index.
pub type MotionFn = Box<dyn FnMut(u64) -> Motion>;

/// The model.
pub struct Mpu6050Model {
    /// 7-bit address (0x68 or 0x69).
    pub address: u8,
    /// WHO_AM_I value.
    pub who_am_i: u8,
    /// FIFO size in bytes.
    pub fifo_capacity: usize,
    /// Physical input.
    pub motion: MotionFn,
    /// Self-test responses added to gyro outputs while XG/YG/ZG_ST are set, LSB.
    pub gyro_self_test_lsb: [f64; 3],
    /// Self-test responses added to accel outputs while XA/YA/ZA_ST are set, LSB.
    pub accel_self_test_lsb: [f64; 3],
    /// When false the chip NACKs everything (vanished sensor).
    pub present: bool,
    /// The oscillator's relative rate error (−0.013: 1.3 % slow).
    pub clock_error: f64,
    /// No sample is produced in `[from, until)` ns (a stalled part); its clock runs on.
    pub stall: Option<(u64, u64)>,
    /// Every sample produced: when (ns) and its outputs (ax ay az temp gx gy gz).
    pub log: Vec<(u64, [i16; 7])>,
    regs: [u8; 128],
    fifo: VecDeque<u8>,
    ptr: u8,
    /// Samples produced since power-up.
    pub samples: u64,
    /// FIFO bytes dropped by overflow.
    pub dropped_bytes: u64,
    /// Transactions addressed to this chip (each `transaction` call counts once).
    pub transactions: u64,
    next_sample_ns: Option<u64>,
    reset_until_ns: u64,
}

// The part's one register table is the driver's (`imu_drivers::mpu6050::reg`); the behaviour
// below is the model's own, from the Register Map.
const SMPLRT_DIV: usize = reg::SMPLRT_DIV as usize;
const CONFIG: usize = reg::CONFIG as usize;
const GYRO_CONFIG: usize = reg::GYRO_CONFIG as usize;
const ACCEL_CONFIG: usize = reg::ACCEL_CONFIG as usize;
const FIFO_EN: usize = reg::FIFO_EN as usize;
const INT_ENABLE: usize = reg::INT_ENABLE as usize;
use reg::{FIFO_COUNT_H, FIFO_COUNT_L, FIFO_R_W, INT_STATUS, PWR_MGMT_1, USER_CTRL, WHO_AM_I};

/// Reset duration the model enforces, ns (PS 6.3: 100 ms start-up for register access).
pub const RESET_NS: u64 = 100_000_000;

impl Mpu6050Model {
    /// A chip at `address` answering `who_am_i`, at rest, 1024-byte FIFO (512 for WHO_AM_I
    /// 0x70..0x74), asleep as after
    /// power-up (PWR_MGMT_1 = 0x40, RM 4.28).
    pub fn new(address: u8, who_am_i: u8) -> Self {
        let mut m = Mpu6050Model {
            address,
            who_am_i,
            // RM 4.30: 1024 bytes; the MPU-6500 family has 512 (MPU-6500 product specification).
            fifo_capacity: if (0x70..=0x74).contains(&who_am_i) {
                512
            } else {
                1024
            },
            motion: Box::new(|_| Motion::default()),
            gyro_self_test_lsb: [0.0; 3],
            accel_self_test_lsb: [0.0; 3],
            present: true,
            clock_error: 0.0,
            stall: None,
            log: Vec::new(),
            regs: [0; 128],
            fifo: VecDeque::new(),
            ptr: 0,
            samples: 0,
            dropped_bytes: 0,
            transactions: 0,
            next_sample_ns: None,
            reset_until_ns: 0,
        };
        m.power_on_defaults();
        m
    }

    /// Set the factory-trim registers SELF_TEST_X/Y/Z/A (0x0D..0x10).
    pub fn set_trim_registers(&mut self, trim: [u8; 4]) {
        self.regs[0x0D..0x11].copy_from_slice(&trim);
    }

    /// Set the MPU-6500-family OTP self-test codes: SELF_TEST_X/Y/Z_GYRO (0x00..0x02) and
    /// SELF_TEST_X/Y/Z_ACCEL (0x0D..0x0F).
    pub fn set_otp_6500(&mut self, gyro: [u8; 3], accel: [u8; 3]) {
        self.regs[0x00..0x03].copy_from_slice(&gyro);
        self.regs[0x0D..0x10].copy_from_slice(&accel);
    }

    fn power_on_defaults(&mut self) {
        // Factory trim / OTP registers survive a reset.
        let mut trim = [0u8; 0x11];
        trim.copy_from_slice(&self.regs[..0x11]);
        self.regs = [0; 128];
        self.regs[..0x03].copy_from_slice(&trim[..0x03]);
        self.regs[0x0D..0x11].copy_from_slice(&trim[0x0D..0x11]);
        self.regs[PWR_MGMT_1 as usize] = 0x40;
        self.fifo.clear();
        self.next_sample_ns = None;
    }

    /// Register value (as the chip holds it, without read side effects).
    pub fn reg(&self, r: u8) -> u8 {
        match r {
            WHO_AM_I => self.who_am_i,
            _ => self.regs[(r & 0x7F) as usize],
        }
    }

    /// Bytes in the FIFO.
    pub fn fifo_len(&self) -> usize {
        self.fifo.len()
    }

    fn sleeping(&self) -> bool {
        self.regs[PWR_MGMT_1 as usize] & 0x40 != 0
    }

    /// Sample period, ns (RM 4.2), on the part's own oscillator (`clock_error`).
    pub fn sample_period_ns(&self) -> u64 {
        let dlpf = self.regs[CONFIG] & 0x07;
        let gyro_rate: u64 = if dlpf == 0 || dlpf == 7 { 8000 } else { 1000 };
        let nominal = 1_000_000_000 * (1 + self.regs[SMPLRT_DIV] as u64) / gyro_rate;
        (nominal as f64 / (1.0 + self.clock_error)).round() as u64
    }

    /// The ground truth of losses: each produced sample's slot on the part's grid,
    /// `round((t − t₀) / T)`, with its time.
    pub fn slots(&self) -> Vec<(u64, u64)> {
        let p = self.sample_period_ns() as f64;
        let t0 = self.log.first().map_or(0, |s| s.0) as f64;
        self.log
            .iter()
            .map(|(t, _)| (((*t as f64 - t0) / p).round() as u64, *t))
            .collect()
    }

    /// Produce every sample due up to `now_ns`.
    pub fn advance_to(&mut self, now_ns: u64) {
        if self.sleeping() || now_ns < self.reset_until_ns {
            self.next_sample_ns = None;
            return;
        }
        let period = self.sample_period_ns();
        let mut next = self.next_sample_ns.unwrap_or(now_ns + period);
        while next <= now_ns {
            if !self.stall.is_some_and(|(a, b)| next >= a && next < b) {
                self.produce_sample(next);
            }
            next += period;
        }
        self.next_sample_ns = Some(next);
    }

    fn temp_scale(&self) -> (f64, f64) {
        // (LSB/°C, °C at 0 LSB): RM 4.18 for 0x68; MPU-6500 family RM-6500 registers 65-66; ICM parts.
        match self.who_am_i {
            0x68 => (340.0, 36.53),
            0x70..=0x74 => (333.87, 21.0),
            _ => (326.8, 25.0),
        }
    }

    fn produce_sample(&mut self, t_ns: u64) {
        let m = (self.motion)(self.samples);
        self.samples += 1;
        let afs = (self.regs[ACCEL_CONFIG] >> 3) & 3;
        let fs = (self.regs[GYRO_CONFIG] >> 3) & 3;
        let lsb_per_g = 16384.0 / f64::from(1u16 << afs);
        let lsb_per_dps = [131.0, 65.5, 32.8, 16.4][fs as usize];
        let sat = |v: f64| v.round().clamp(-32768.0, 32767.0) as i16;
        let mut out = [0i16; 7];
        for i in 0..3 {
            let a_st = if self.regs[ACCEL_CONFIG] & (0x80 >> i) != 0 {
                self.accel_self_test_lsb[i]
            } else {
                0.0
            };
            let g_st = if self.regs[GYRO_CONFIG] & (0x80 >> i) != 0 {
                self.gyro_self_test_lsb[i]
            } else {
                0.0
            };
            out[i] = sat(m.accel_g[i] * lsb_per_g + a_st);
            out[4 + i] = sat(m.gyro_dps[i] * lsb_per_dps + g_st);
        }
        let (t_sens, t_off) = self.temp_scale();
        out[3] = sat((m.temp_c - t_off) * t_sens);
        self.log.push((t_ns, out));
        for (k, v) in out.iter().enumerate() {
            let [h, l] = v.to_be_bytes();
            self.regs[0x3B + 2 * k] = h;
            self.regs[0x3C + 2 * k] = l;
        }
        let int_en = self.regs[INT_ENABLE];
        if int_en & 0x01 != 0 {
            self.regs[INT_STATUS as usize] |= 0x01;
        }
        if self.regs[USER_CTRL as usize] & 0x40 != 0 {
            let en = self.regs[FIFO_EN];
            let mut push = |idx: usize| {
                self.fifo.extend(out[idx].to_be_bytes());
            };
            if en & 0x08 != 0 {
                push(0);
                push(1);
                push(2);
            }
            if en & 0x80 != 0 {
                push(3);
            }
            for (axis, bit) in [(4, 0x40), (5, 0x20), (6, 0x10)] {
                if en & bit != 0 {
                    push(axis);
                }
            }
            while self.fifo.len() > self.fifo_capacity {
                self.fifo.pop_front();
                self.dropped_bytes += 1;
                if int_en & 0x10 != 0 {
                    self.regs[INT_STATUS as usize] |= 0x10;
                }
            }
        }
    }

    fn read_byte(&mut self) -> u8 {
        let r = self.ptr;
        let v = match r {
            FIFO_R_W => return self.fifo.pop_front().unwrap_or(0xFF),
            FIFO_COUNT_H => (self.fifo.len() >> 8) as u8,
            FIFO_COUNT_L => self.fifo.len() as u8,
            WHO_AM_I => self.who_am_i,
            INT_STATUS => {
                let v = self.regs[INT_STATUS as usize];
                self.regs[INT_STATUS as usize] = 0;
                v
            }
            _ => self.regs[r as usize],
        };
        self.ptr = (r + 1) & 0x7F;
        v
    }

    fn write_byte(&mut self, now_ns: u64, v: u8) {
        let r = self.ptr;
        match r {
            PWR_MGMT_1 if v & 0x80 != 0 => {
                self.power_on_defaults();
                self.reset_until_ns = now_ns + RESET_NS;
            }
            PWR_MGMT_1 => {
                let was_sleeping = self.sleeping();
                self.regs[r as usize] = v;
                if was_sleeping && !self.sleeping() {
                    // First sample one period after wake-up.
                    self.next_sample_ns = Some(now_ns + self.sample_period_ns());
                }
            }
            USER_CTRL => {
                if v & 0x04 != 0 && v & 0x40 == 0 {
                    self.fifo.clear();
                }
                self.regs[r as usize] = v & !0x07;
            }
            FIFO_R_W => self.fifo.push_back(v),
            WHO_AM_I | INT_STATUS | 0x3B..=0x48 | FIFO_COUNT_H | FIFO_COUNT_L => {}
            _ => self.regs[r as usize] = v,
        }
        if r != FIFO_R_W {
            self.ptr = (r + 1) & 0x7F;
        }
    }

    /// Execute one I²C transaction addressed to this chip.
    pub fn transaction(&mut self, now_ns: u64, ops: &mut [Operation<'_>]) -> Result<(), SimError> {
        self.transactions += 1;
        if !self.present || now_ns < self.reset_until_ns {
            return Err(SimError::Nack(NoAcknowledgeSource::Address));
        }
        for op in ops {
            match op {
                Operation::Write(bytes) => {
                    if let Some((&r, data)) = bytes.split_first() {
                        self.ptr = r & 0x7F;
                        for &v in data {
                            self.write_byte(now_ns, v);
                        }
                    }
                }
                Operation::Read(buf) => {
                    for b in buf.iter_mut() {
                        *b = self.read_byte();
                    }
                }
            }
        }
        Ok(())
    }
}
