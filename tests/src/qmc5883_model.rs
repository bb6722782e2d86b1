//! Register-level model of the QMC5883L (QST datasheet rev C, 9.1/9.2) and QMC5883P (QST
//! datasheet rev A, section 8):
//!
//! - in continuous mode a measurement is made every 1/ODR (10/50/100/200 Hz from ODR[3:2]);
//! - each measurement writes X/Y/Z little-endian, sets DRDY; if DRDY was still set (the last
//!   result was never read) the L sets DOR ("data skipped");
//! - OVL is set when any axis exceeds the configured range (and cleared by an in-range result);
//! - reading any data register clears DRDY and DOR;
//! - SOFT_RST in CONTROL2 restores the power-on registers (all zero: standby);
//! - the L has a relative temperature sensor at 0x07/0x08, 100 LSB/°C;
//! - with ROL_PNT (L, CONTROL2 bit 6) a read rolls over from 06H to 00H.

use embedded_hal::i2c::{NoAcknowledgeSource, Operation};
use imu_drivers::qmc5883::{reg_l, reg_p};

use crate::SimError;

/// Which chip is modelled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QmcVariant {
    /// QMC5883L at 0x0D.
    L,
    /// QMC5883P at 0x2C.
    P,
}

/// Field source: sample index → field in gauss.
pub type FieldFn = Box<dyn FnMut(u64) -> [f64; 3]>;

/// The model.
pub struct QmcModel {
    /// Variant.
    pub variant: QmcVariant,
    /// Field source.
    pub field: FieldFn,
    /// Die temperature, °C (L only; the model's uncalibrated offset is 0).
    pub temp_c: f64,
    /// Chip-id byte answered (0xFF on the L, 0x80 on the P unless a test changes it).
    pub chip_id: u8,
    /// When false the chip NACKs everything.
    pub present: bool,
    /// The oscillator's relative rate error (−0.013: 1.3 % slow).
    pub clock_error: f64,
    /// No measurement completes in `[from, until)` ns (DRDY never set); the clock runs on.
    pub stall: Option<(u64, u64)>,
    /// Every measurement: when (ns) and its outputs (x y z).
    pub log: Vec<(u64, [i16; 3])>,
    regs: [u8; 0x30],
    ptr: u8,
    next_ns: Option<u64>,
    /// Measurements made.
    pub measurements: u64,
    /// Reads of the status register (each a DRDY poll).
    pub status_reads: u64,
    /// Transactions addressed to this chip (each `transaction` call counts once).
    pub transactions: u64,
    /// Bus time per byte moved, ns (0: a transaction is instantaneous). With it a measurement
    /// can complete between the bytes of one transaction, as on a 400 kHz bus (22 500 ns).
    pub byte_ns: u64,
    /// An oscillator glitch: the first measurement due at or after `.0` ns comes `.1` ns late,
    /// and the grid goes on from there.
    pub glitch: Option<(u64, u64)>,
    /// The measurements (indices into `log`) a reader was served, as the emulator's model
    /// counts them: all six data bytes of the latest measurement read after a status read
    /// that showed DRDY (a reader uses the data only after it has seen DRDY set).
    pub served: Vec<usize>,
    /// A status read showed DRDY since the last measurement was served.
    ready_seen: bool,
    /// Data registers read since the latest measurement (bit per register).
    data_read: u8,
}

impl QmcModel {
    /// A chip of `variant` in a constant field of (0.2, −0.1, 0.4) G, 25 °C.
    pub fn new(variant: QmcVariant) -> Self {
        QmcModel {
            variant,
            field: Box::new(|_| [0.2, -0.1, 0.4]),
            temp_c: 25.0,
            chip_id: match variant {
                QmcVariant::L => 0xFF,
                QmcVariant::P => 0x80,
            },
            present: true,
            clock_error: 0.0,
            stall: None,
            log: Vec::new(),
            regs: [0; 0x30],
            ptr: 0,
            next_ns: None,
            measurements: 0,
            status_reads: 0,
            transactions: 0,
            byte_ns: 0,
            glitch: None,
            served: Vec::new(),
            ready_seen: false,
            data_read: 0,
        }
    }

    /// 7-bit address.
    pub fn address(&self) -> u8 {
        match self.variant {
            QmcVariant::L => 0x0D,
            QmcVariant::P => 0x2C,
        }
    }

    /// Register value without side effects.
    pub fn reg(&self, r: u8) -> u8 {
        self.regs[r as usize % 0x30]
    }

    fn ctrl1(&self) -> u8 {
        match self.variant {
            QmcVariant::L => self.regs[reg_l::CONTROL1 as usize],
            QmcVariant::P => self.regs[reg_p::CONTROL1 as usize],
        }
    }

    fn status_reg(&self) -> usize {
        match self.variant {
            QmcVariant::L => reg_l::STATUS as usize,
            QmcVariant::P => reg_p::STATUS as usize,
        }
    }

    fn data_regs(&self) -> std::ops::RangeInclusive<u8> {
        match self.variant {
            QmcVariant::L => reg_l::DATA_X_LSB..=reg_l::DATA_X_LSB + 5,
            QmcVariant::P => reg_p::DATA_X_LSB..=reg_p::DATA_X_LSB + 5,
        }
    }

    fn continuous(&self) -> bool {
        let mode = self.ctrl1() & 0x03;
        match self.variant {
            QmcVariant::L => mode == 0x01,
            QmcVariant::P => mode == 0x01 || mode == 0x03,
        }
    }

    /// Measurement period, ns.
    pub fn period_ns(&self) -> u64 {
        let hz = [10u64, 50, 100, 200][((self.ctrl1() >> 2) & 3) as usize];
        ((1_000_000_000 / hz) as f64 / (1.0 + self.clock_error)).round() as u64
    }

    /// (LSB per gauss, full scale in gauss) of the configured range.
    pub fn range(&self) -> (f64, f64) {
        match self.variant {
            QmcVariant::L => match (self.regs[reg_l::CONTROL1 as usize] >> 4) & 3 {
                0 => (12000.0, 2.0),
                _ => (3000.0, 8.0),
            },
            QmcVariant::P => match (self.regs[reg_p::CONTROL2 as usize] >> 2) & 3 {
                0 => (1000.0, 30.0),
                1 => (2500.0, 12.0),
                2 => (3750.0, 8.0),
                _ => (15000.0, 2.0),
            },
        }
    }

    /// Make every measurement due by `now_ns`.
    pub fn advance_to(&mut self, now_ns: u64) {
        if !self.continuous() {
            self.next_ns = None;
            return;
        }
        let period = self.period_ns();
        let mut next = self.next_ns.unwrap_or(now_ns + period);
        if let Some((at, late)) = self.glitch {
            if next >= at {
                next += late;
                self.glitch = None;
            }
        }
        while next <= now_ns {
            if !self.stall.is_some_and(|(a, b)| next >= a && next < b) {
                self.measure(next);
            }
            next += period;
        }
        self.next_ns = Some(next);
    }

    /// The ground truth of losses: each measurement's slot on the part's grid.
    pub fn slots(&self) -> Vec<(u64, u64)> {
        let p = self.period_ns() as f64;
        let t0 = self.log.first().map_or(0, |s| s.0) as f64;
        self.log
            .iter()
            .map(|(t, _)| (((*t as f64 - t0) / p).round() as u64, *t))
            .collect()
    }

    fn measure(&mut self, t_ns: u64) {
        let f = (self.field)(self.measurements);
        self.measurements += 1;
        let (lsb, fs) = self.range();
        let base = *self.data_regs().start() as usize;
        let mut over = false;
        let mut xyz = [0i16; 3];
        for (i, &g) in f.iter().enumerate() {
            over |= g.abs() > fs;
            let raw = (g * lsb).round().clamp(-32768.0, 32767.0) as i16;
            xyz[i] = raw;
            let [lo, hi] = raw.to_le_bytes();
            self.regs[base + 2 * i] = lo;
            self.regs[base + 2 * i + 1] = hi;
        }
        self.log.push((t_ns, xyz));
        self.data_read = 0;
        let st = self.status_reg();
        let mut s = self.regs[st];
        if s & 0x01 != 0 && self.variant == QmcVariant::L {
            s |= 0x04;
        }
        s |= 0x01;
        s = if over { s | 0x02 } else { s & !0x02 };
        self.regs[st] = s;
        if self.variant == QmcVariant::L {
            let t = (self.temp_c * 100.0).round().clamp(-32768.0, 32767.0) as i16;
            let [lo, hi] = t.to_le_bytes();
            self.regs[reg_l::TEMP_LSB as usize] = lo;
            self.regs[reg_l::TEMP_LSB as usize + 1] = hi;
        }
    }

    fn read_byte(&mut self) -> u8 {
        let r = self.ptr;
        let v = if (self.variant == QmcVariant::L && r == reg_l::CHIP_ID)
            || (self.variant == QmcVariant::P && r == reg_p::CHIP_ID)
        {
            self.chip_id
        } else {
            self.regs[r as usize % 0x30]
        };
        if self.data_regs().contains(&r) {
            let st = self.status_reg();
            self.regs[st] &= !0x05;
            self.data_read |= 1 << (r - *self.data_regs().start());
            if self.data_read == 0x3f && !self.log.is_empty() {
                let latest = self.log.len() - 1;
                if self.ready_seen && self.served.last() != Some(&latest) {
                    self.served.push(latest);
                }
                self.ready_seen = false;
            }
        }
        if r as usize == self.status_reg() {
            self.status_reads += 1;
            if v & 0x01 != 0 {
                self.ready_seen = true;
            }
        }
        // QMC5883L ROL_PNT (CONTROL2 bit 6): the pointer rolls over from 06H to 00H.
        self.ptr = if self.variant == QmcVariant::L && r == 0x06 && self.regs[0x0A] & 0x40 != 0 {
            0x00
        } else {
            (r + 1) % 0x30
        };
        v
    }

    fn write_byte(&mut self, now_ns: u64, v: u8) {
        let r = self.ptr;
        let ctrl2 = match self.variant {
            QmcVariant::L => 0x0A,
            QmcVariant::P => 0x0B,
        };
        if r == ctrl2 && v & 0x80 != 0 {
            self.regs = [0; 0x30];
            self.next_ns = None;
        } else if !self.data_regs().contains(&r) && r as usize != self.status_reg() {
            let was = self.continuous();
            self.regs[r as usize % 0x30] = v;
            if !was && self.continuous() {
                // The first measurement completes one period after the mode change.
                self.next_ns = Some(now_ns + self.period_ns());
            } else if was && !self.continuous() {
                self.next_ns = None;
            }
        }
        self.ptr = (r + 1) % 0x30;
    }

    /// Execute one I²C transaction addressed to this chip.
    pub fn transaction(&mut self, now_ns: u64, ops: &mut [Operation<'_>]) -> Result<(), SimError> {
        self.transactions += 1;
        if !self.present {
            return Err(SimError::Nack(NoAcknowledgeSource::Address));
        }
        // The address byte of each operation, then its bytes, each `byte_ns` on the bus.
        let mut t = now_ns;
        for op in ops {
            t += self.byte_ns;
            match op {
                Operation::Write(bytes) => {
                    if let Some((&r, data)) = bytes.split_first() {
                        t += self.byte_ns;
                        self.ptr = r % 0x30;
                        for &v in data {
                            t += self.byte_ns;
                            self.advance_to(t);
                            self.write_byte(t, v);
                        }
                    }
                }
                Operation::Read(buf) => {
                    for b in buf.iter_mut() {
                        t += self.byte_ns;
                        self.advance_to(t);
                        *b = self.read_byte();
                    }
                }
            }
        }
        Ok(())
    }
}
