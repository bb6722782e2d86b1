//! What the sensor tasks do on each tick, generic over the I2C bus and the delay so the same
//! code runs on the device (embassy-rp async I2C) and in the host tests (the register-level
//! chip models on a simulated bus). The tasks in `main.rs` only wait for the tick, run bus
//! recovery when [`ImuService::wants_recovery`] says so, and forward the messages.
use embedded_hal_async::delay::DelayNs;
use embedded_hal_async::i2c::I2c;
use imu_drivers::asynch::{Mpu6050, Qmc5883};
use imu_drivers::mpu6050::{self as mpu, FifoFrame, RawSample};
use imu_drivers::qmc5883 as qmc;
use imu_proto::{Event, Scales, Sensor, SensorState, Vec};

use crate::device::{Fault, SensorMsg, IMU_PERIOD_US, MAG_PERIOD_US};
use crate::health::Health;
use crate::stage::{self, Stage};

/// FIFO frames read per I2C burst (and per [`SensorMsg::Imu`]); a tick drains up to four
/// bursts, more than the FIFO gathers between two ticks.
pub const BURST_FRAMES: usize = crate::device::BURST_MAX;
/// Frames the 1024-byte FIFO holds with accel + temp + gyro (14 bytes each).
pub const FIFO_FRAMES: u64 = 1024 / 14;

/// Whether the FIFO may have overflowed since `count` was read, `dt_us` ago (the task was held
/// up between the count transfer and the data transfer, e.g. by a stall). The count cannot
/// show such an overflow, and the frames read after it would be misaligned; the tick then
/// treats it as an overflow (found by the end-to-end test's 120 ms stall falling between the
/// two transfers). The FIFO gains at most one 14-byte frame per 512 µs (the sensor's 1 kHz
/// with a 95 % margin for its clock) plus one in progress; normally `dt_us` is well below 1 ms
/// and this fires only within two frames of the capacity.
pub fn count_may_be_stale<I: I2c>(count: u16, dt_us: u64, imu: &Mpu6050<I>) -> bool {
    let capacity = imu.fifo_capacity().unwrap_or(0) as u64;
    u64::from(count) + 14 * ((dt_us >> 9) + 1) >= capacity
}

/// MPU-6050: 1 kHz (DLPF 184 Hz, SMPLRT_DIV 0), ±4 g, ±250 deg/s (the seed's ranges, which the
/// calibration file assumes), FIFO with temperature, no interrupt pin (timer-driven).
pub fn imu_config() -> mpu::Config {
    mpu::Config {
        gyro_range: mpu::GyroRange::Dps250,
        accel_range: mpu::AccelRange::G4,
        dlpf: mpu::Dlpf::Hz184,
        sample_rate_divider: 0,
        fifo: Some(FifoFrame::AccelTempGyro),
        interrupt: mpu::InterruptConfig {
            data_ready: false,
            ..Default::default()
        },
    }
}

/// QMC5883L: continuous, 200 Hz, ±2 G, OSR 512 (the driver's defaults).
///
/// Pointer roll-over (`roll_over`, status and data in one 7-byte transfer) is left off: it saved
/// 1,262 of 16,785 cycles per sample set in the emulator, but a read whose status byte shows
/// DRDY clear still reads the data bytes, and a sample that lands during them is lost (its DRDY
/// cleared by the discarded bytes). The e2e run saw one such loss in 60 s (split as `Late`, so
/// no bias); the status-then-data pair loses none (docs/firmware.md).
pub fn mag_config() -> qmc::Config {
    qmc::Config::default()
}

/// Contract-unit scales of the configured ranges (corrected counts keep the nominal LSB, see
/// `imu_cal::device`): m/s² = LSB·g₀/(LSB/g), deg/s = LSB/(LSB/(deg/s)), µT = LSB·100/(LSB/G).
pub fn scales() -> Scales {
    let s = imu_config().scale(mpu::ChipId::Mpu6050);
    Scales {
        accel: mpu::STANDARD_GRAVITY / s.accel_lsb_per_g,
        gyro: 1.0 / s.gyro_lsb_per_dps,
        mag: 100.0
            / mag_config()
                .range
                .lsb_per_gauss(qmc::Variant::L)
                .unwrap_or(12000.0),
        temp: 1.0 / s.temperature.lsb_per_c,
        temp_offset: s.temperature.offset_c,
    }
}

const EMPTY_FRAME: RawSample = RawSample {
    accel: [0; 3],
    temp: None,
    gyro: [0; 3],
};

/// Messages produced by one tick (at most one burst and one fault report, or a few bursts).
pub type Out = Vec<SensorMsg, 4>;

fn fault(
    sensor: Sensor,
    h: &Health,
    i2c_errors: u32,
    recoveries: u32,
    event: Option<Event>,
    lost: u32,
) -> SensorMsg {
    SensorMsg::Fault(Fault {
        sensor,
        i2c_errors,
        recoveries,
        state: h.state(),
        event,
        lost,
    })
}

/// The IMU side: initialisation, FIFO draining, overflow and loss handling.
pub struct ImuService {
    health: Health,
    ready: bool,
    last_read_us: u64,
}

impl Default for ImuService {
    fn default() -> Self {
        Self::new()
    }
}

impl ImuService {
    pub const fn new() -> Self {
        Self {
            health: Health::new(Sensor::Imu),
            ready: false,
            last_read_us: 0,
        }
    }

    pub fn state(&self) -> SensorState {
        self.health.state()
    }

    /// Missing and a retry is due: the caller recovers the bus before the next [`Self::tick`].
    pub fn wants_recovery(&self, t_us: u64) -> bool {
        !self.ready && self.health.retry_due(t_us)
    }

    /// After a pause (flash write): empty the FIFO and report the gap.
    pub async fn resume<I: I2c>(&mut self, imu: &mut Mpu6050<I>, now_us: u64, out: &mut Out) {
        if self.ready {
            if imu.reset_fifo().await.is_err() {
                self.ready = false;
            }
            self.last_read_us = now_us;
            let _ = out.push(SensorMsg::Resumed { t_us: now_us });
        }
    }

    /// One service tick at `now()` µs. `recoveries` is the number of bus recoveries the caller
    /// ran just before (reported with the next fault message).
    pub async fn tick<I: I2c, D: DelayNs>(
        &mut self,
        imu: &mut Mpu6050<I>,
        delay: &mut D,
        now: &impl Fn() -> u64,
        recoveries: u32,
        out: &mut Out,
    ) {
        let t = now();
        if !self.ready {
            if self.health.state() == SensorState::Missing && !self.health.retry_due(t) {
                return;
            }
            match imu.init(delay, &imu_config()).await {
                Ok(_) => {
                    let t = now();
                    let event = self.health.ok(t);
                    let lost = match event {
                        Some(Event::SensorBack { down_us, .. }) => (down_us / IMU_PERIOD_US) as u32,
                        _ => 0,
                    };
                    self.ready = true;
                    self.last_read_us = t;
                    let _ = out.push(fault(Sensor::Imu, &self.health, 0, recoveries, event, lost));
                }
                Err(_) => {
                    let event = self.health.error(now());
                    let _ = out.push(fault(Sensor::Imu, &self.health, 1, recoveries, event, 0));
                }
            }
            return;
        }
        // Drain the FIFO: BURST_FRAMES a read, again while reads come back full.
        let first = out.len();
        let mut t_last = None;
        // Frames are read straight into the message (no copy): a full-length `Imu` message is
        // pushed first and cut to what the read returned, or taken back if it returned none.
        // (A local burst pushed after the read measured 10,210 instead of 9,711 cycles per
        // sample set: the burst lives in the task's future across the await, then is copied.)
        while out.len() + 1 < out.capacity() {
            let slot = out.len();
            let _ = out.push(SensorMsg::Imu {
                t_us: 0,
                samples: Vec::from_array([EMPTY_FRAME; BURST_FRAMES]),
            });
            let r = match out.last_mut() {
                Some(SensorMsg::Imu { samples, .. }) => {
                    stage::enter(Stage::I2c);
                    let t0 = now();
                    let r = match imu.fifo_count().await {
                        Ok(count) if count_may_be_stale(count, now() - t0, imu) => {
                            Err(mpu::Error::FifoOverflow)
                        }
                        Ok(count) => imu.read_fifo_counted(count, samples).await,
                        Err(e) => Err(e),
                    };
                    stage::leave();
                    samples.truncate(*r.as_ref().unwrap_or(&0));
                    r
                }
                _ => Ok(0),
            };
            let t = now();
            if !matches!(r, Ok(n) if n > 0) {
                out.truncate(slot);
            }
            match r {
                Ok(0) => break,
                Ok(n) => {
                    if let Some(SensorMsg::Imu { t_us, .. }) = out.last_mut() {
                        *t_us = t;
                    }
                    if let Some(e) = self.health.ok(t) {
                        // The report goes before the frames it precedes.
                        let f = fault(Sensor::Imu, &self.health, 0, 0, Some(e), 0);
                        let _ = out.insert(slot, f);
                    }
                    self.last_read_us = t;
                    t_last = Some(t);
                    if n < BURST_FRAMES {
                        break;
                    }
                }
                Err(mpu::Error::FifoOverflow) => {
                    // The FIFO held FIFO_FRAMES frames; the rest of the time since the last
                    // read is lost (at least one frame, or the chip would not have overflowed).
                    let elapsed = t.saturating_sub(self.last_read_us) / IMU_PERIOD_US;
                    let lost = elapsed.saturating_sub(FIFO_FRAMES).max(1) as u32;
                    if imu.reset_fifo().await.is_err() {
                        self.ready = false;
                    }
                    self.last_read_us = now();
                    let _ = out.push(SensorMsg::ImuOverflow { t_us: t, lost });
                    break;
                }
                Err(_) => {
                    let event = self.health.error(t);
                    if event.is_some() {
                        self.ready = false;
                    }
                    let _ = out.push(fault(Sensor::Imu, &self.health, 1, 0, event, 0));
                    break;
                }
            }
        }
        // Only the last read of the tick emptied the FIFO, so only its newest frame is "now":
        // stamp every burst of the tick backwards from it, 1 ms a frame (a burst's `t_us` is the
        // time of its last frame).
        if let Some(t_last) = t_last {
            let mut later = 0u64;
            for m in out[first..].iter_mut().rev() {
                if let SensorMsg::Imu { t_us, samples } = m {
                    *t_us = t_last.saturating_sub(later * IMU_PERIOD_US);
                    later += samples.len() as u64;
                }
            }
        }
    }
}

/// The magnetometer side.
///
/// The QMC5883L runs on its own clock, so its samples land at a phase of their own. The service
/// follows that phase: each tick's first poll comes one period after the previous tick's first
/// poll, moved later by the re-polls that tick needed (the sample landed between the last two),
/// or [`MAG_CREEP_US`] earlier when the first poll found data, so the loop keeps re-finding
/// the moment a sample lands and reads it within [`MAG_REPOLL_US`] of it. Measured in the
/// emulator before this loop (fixed slots): three status polls found DRDY clear for every
/// sample read, each a bus transaction and a timer wait.
pub struct MagService {
    health: Health,
    ready: bool,
    next_poll_us: Option<u64>,
}

impl Default for MagService {
    fn default() -> Self {
        Self::new()
    }
}

/// Re-polls of DRDY within one tick, [`MAG_REPOLL_US`] apart.
pub const MAG_DRDY_POLLS: u32 = 4;
/// Time between DRDY polls within a tick, µs.
pub const MAG_REPOLL_US: u64 = 500;
/// How much earlier the next tick polls when this tick's first poll found data, µs: one extra
/// status poll every `MAG_REPOLL_US / MAG_CREEP_US` = 25 samples keeps the read within
/// `MAG_REPOLL_US` of the sample's landing even if the sensor's clock runs fast.
pub const MAG_CREEP_US: u64 = 20;

impl MagService {
    pub const fn new() -> Self {
        Self {
            health: Health::new(Sensor::Mag),
            ready: false,
            next_poll_us: None,
        }
    }

    /// When the next tick should start, µs since boot (`None`: no phase known yet, use the
    /// caller's own schedule).
    pub fn next_poll_us(&self) -> Option<u64> {
        self.next_poll_us
    }

    pub fn state(&self) -> SensorState {
        self.health.state()
    }

    pub fn wants_recovery(&self, t_us: u64) -> bool {
        !self.ready && self.health.retry_due(t_us)
    }

    /// One 200 Hz tick. DRDY may trail the tick a little (the sensor runs on its own clock):
    /// it is polled again after 0.5 ms rather than a whole period, so no sample is overwritten.
    pub async fn tick<I: I2c, D: DelayNs>(
        &mut self,
        mag: &mut Qmc5883<I>,
        delay: &mut D,
        now: &impl Fn() -> u64,
        recoveries: u32,
        out: &mut Out,
    ) {
        let t = now();
        // Until a sample shows where the phase is, one period on from this tick.
        self.next_poll_us = Some(t + MAG_PERIOD_US);
        if !self.ready {
            if self.health.state() == SensorState::Missing && !self.health.retry_due(t) {
                return;
            }
            match mag.init(delay, &mag_config()).await {
                Ok(()) => {
                    let event = self.health.ok(now());
                    self.ready = true;
                    let _ = out.push(fault(Sensor::Mag, &self.health, 0, recoveries, event, 0));
                }
                Err(_) => {
                    let event = self.health.error(now());
                    let _ = out.push(fault(Sensor::Mag, &self.health, 1, recoveries, event, 0));
                }
            }
            return;
        }
        let mut r = mag.read().await;
        let mut repolls = 0;
        while repolls < MAG_DRDY_POLLS && matches!(r, Err(qmc::Error::NotReady)) {
            delay.delay_us(MAG_REPOLL_US as u32).await;
            repolls += 1;
            r = mag.read().await;
        }
        match r {
            Ok(s) => {
                // The sample landed in the last re-poll interval (or before the first poll):
                // the next one lands a period later.
                self.next_poll_us = Some(match repolls {
                    0 => t + MAG_PERIOD_US - MAG_CREEP_US,
                    n => t + MAG_PERIOD_US + u64::from(n) * MAG_REPOLL_US,
                });
                if let Some(e) = self.health.ok(t) {
                    let _ = out.push(fault(Sensor::Mag, &self.health, 0, 0, Some(e), 0));
                }
                let _ = out.push(SensorMsg::Mag {
                    t_us: now(),
                    xyz: s.xyz,
                    skipped: s.skipped,
                });
            }
            Err(qmc::Error::NotReady) => {
                // Nothing for the whole tick: the sample lands later than the last poll.
                let polls = u64::from(MAG_DRDY_POLLS) + 1;
                self.next_poll_us = Some(t + MAG_PERIOD_US + polls * MAG_REPOLL_US);
            }
            Err(_) => {
                let event = self.health.error(t);
                if event.is_some() {
                    self.ready = false;
                }
                let _ = out.push(fault(Sensor::Mag, &self.health, 1, 0, event, 0));
            }
        }
    }
}

/// A task's fixed slots: `offset_us` past each multiple of `period_us` since boot, so the
/// sensor tasks' bus use interleaves the same way every period. A slot that has already passed
/// is skipped, not caught up.
#[derive(Debug, Clone, Copy)]
pub struct Slots {
    period_us: u64,
    offset_us: u64,
    /// The slot returned last (0: none yet).
    last_us: u64,
}

impl Slots {
    pub const fn new(period_us: u64, offset_us: u64) -> Self {
        Self {
            period_us,
            offset_us,
            last_us: 0,
        }
    }

    /// The first slot after `now_us`. When the previous slot has passed and the one after it
    /// has not (a task that kept up), that is one addition; otherwise a 64-bit division
    /// (≈ 280 cycles on the Cortex-M0+, which has no divide instruction).
    pub fn next_after(&mut self, now_us: u64) -> u64 {
        let following = self.last_us + self.period_us;
        self.last_us = if self.last_us != 0 && self.last_us <= now_us && now_us < following {
            following
        } else {
            let k = now_us.saturating_sub(self.offset_us) / self.period_us + 1;
            k * self.period_us + self.offset_us
        };
        self.last_us
    }
}
