//! The processing task's state machine: sensor messages through the sample path
//! ([`crate::pipeline`]), the table rounds ([`crate::tables`]), host requests
//! ([`crate::requests`]), counters and the status report.
use imu_cal::device::Calibration;
use imu_proto::{CalSource, CalStatus, DeviceMsg, Event, Scales, Sensor, SensorState, Status};

use crate::clock::Fine;
use crate::msg::{Report, SensorMsg};
use crate::outbox::{FrameSink, Outbox, Sent};
use crate::pipeline::Pipeline;
use crate::tables::{Tables, TABLE_SPACING_US};

/// Counters reported in [`Status`] besides the sample path's.
#[derive(Debug, Clone, Copy, Default)]
pub struct Counters {
    pub fifo_overflows: u32,
    pub i2c_errors: u32,
    pub bus_faults: u32,
    pub bus_recoveries: u32,
    pub frames_rejected: u32,
}

/// The device state machine.
pub struct Device {
    pub(crate) pipeline: Pipeline,
    pub(crate) tables: Tables,
    pub(crate) outbox: Outbox,
    pub(crate) cal_status: CalStatus,
    pub(crate) status_ms: u32,
    pub(crate) tables_ms: u32,
    pub counters: Counters,
    state: [SensorState; 2],
    /// The sensors' sample periods from their clocks, [`Fine`] (0: not known yet): as the
    /// latest samples carry them, or the latest report gives them. Converted to ns only for a
    /// report, so the per-message path does no 64-bit multiply.
    period: [Fine; 2],
    pub(crate) firmware: &'static str,
    /// When the last periodic status frame went out, µs.
    last_status_us: Option<u64>,
    /// The attitude filter's settings in flash (the defaults while none are stored).
    pub(crate) stored_orientation: crate::settings::OrientationSetting,
}

impl Device {
    /// A device with identity corrections, streaming calibrated samples, status every 1 s and
    /// tables every 10 s. `scales` converts corrected counts to contract units.
    pub fn new(scales: Scales, firmware: &'static str) -> Self {
        Self {
            pipeline: Pipeline::new(scales),
            tables: Tables::new(),
            outbox: Outbox::new(),
            cal_status: CalStatus {
                source: CalSource::Identity,
                fault: None,
            },
            status_ms: 1000,
            tables_ms: 10_000,
            counters: Counters::default(),
            state: [SensorState::Unknown; 2],
            period: [Fine::ZERO; 2],
            firmware,
            last_status_us: None,
            stored_orientation: crate::settings::DEFAULT_ORIENTATION,
        }
    }

    pub fn cal_status(&self) -> CalStatus {
        self.cal_status
    }

    /// The corrections in use.
    pub fn calibration(&self) -> &Calibration {
        &self.pipeline.cal
    }

    pub fn mode(&self) -> imu_proto::StreamMode {
        self.pipeline.mode
    }

    /// Status frame interval, ms (0 = off).
    pub fn status_interval_ms(&self) -> u32 {
        self.status_ms
    }

    /// Table round interval, ms (0 = off).
    pub fn tables_interval_ms(&self) -> u32 {
        self.tables_ms
    }

    /// Frames dropped because the host was not reading.
    pub fn frames_unsent(&self) -> u32 {
        self.outbox.unsent
    }

    /// Feed one sensor message through the pipeline.
    pub fn on_sensor(&mut self, msg: &SensorMsg, sink: &mut impl FrameSink) {
        match msg {
            SensorMsg::Imu {
                stamps,
                frames,
                after,
            } => {
                self.period[0] = stamps.period;
                self.pipeline
                    .imu_burst(frames, stamps, *after, &mut self.outbox, sink)
            }
            SensorMsg::Mag { stamps, xyz, after } => {
                self.period[1] = stamps.period;
                self.pipeline.mag_sample(
                    stamps.k0,
                    stamps.us(0),
                    *xyz,
                    *after,
                    &mut self.outbox,
                    sink,
                )
            }
            SensorMsg::Report(r) => self.report(r, sink),
            SensorMsg::BusRecovered {
                t_us,
                pulses,
                sda_released,
            } => {
                self.counters.bus_recoveries = self.counters.bus_recoveries.saturating_add(1);
                self.send(
                    &DeviceMsg::Event(Event::BusRecovered {
                        t_us: *t_us,
                        pulses: *pulses,
                        sda_released: *sda_released,
                    }),
                    sink,
                );
            }
        }
    }

    fn report(&mut self, r: &Report, sink: &mut impl FrameSink) {
        let c = &mut self.counters;
        c.i2c_errors = c.i2c_errors.saturating_add(r.i2c_errors);
        c.bus_faults = c.bus_faults.saturating_add(r.bus_faults);
        c.fifo_overflows = c.fifo_overflows.saturating_add(r.fifo_overflows);
        let i = r.sensor as usize;
        self.state[i] = r.state;
        if r.period_ns != 0 {
            // Exact back through `period_ns` (the ns → Fine rounding loses less than 1/1000 of
            // a Fine unit per ns).
            self.period[i] = u64::from(r.period_ns) * crate::clock::US / 1000;
        }
        if let Some(e) = r.event {
            self.send(&DeviceMsg::Event(e), sink);
        }
    }

    /// Whether attitude updates wait to run ([`Device::attitude_step`]).
    pub fn attitude_pending(&self) -> bool {
        self.pipeline.attitude_pending()
    }

    /// Whether the attitude queue is full (its updates are not being run: no IMU bursts).
    pub fn attitude_backlog(&self) -> bool {
        self.pipeline.attitude_backlog()
    }

    /// Run one queued attitude update (≈ 20 µs on the M0+: the processing task runs them
    /// where that delay does not disturb the sensor tasks, in line with an IMU burst's
    /// processing). Returns whether more wait.
    pub fn attitude_step(&mut self, sink: &mut impl FrameSink) -> bool {
        self.pipeline.attitude_step(&mut self.outbox, sink)
    }

    /// Send the batch assembled so far (if any).
    pub fn flush(&mut self, sink: &mut impl FrameSink) {
        self.pipeline.flush(&mut self.outbox, sink);
    }

    pub(crate) fn send(&mut self, msg: &DeviceMsg, sink: &mut impl FrameSink) -> Sent {
        self.outbox.send(msg, sink)
    }

    /// A sensor's state as last reported.
    pub fn sensor_state(&self, sensor: Sensor) -> SensorState {
        self.state[sensor as usize]
    }

    /// Counters and health now.
    pub fn status(&self, uptime_us: u64, cpu_load_permille: u16) -> Status {
        let p = &self.pipeline;
        let periods = self.periods_ns();
        let s = p.scales;
        let n = &p.counts;
        Status {
            uptime_us,
            samples_taken: n.imu_taken,
            samples_dropped: n.imu_lost,
            mag_samples: n.mag_taken,
            mag_dropped: n.mag_lost,
            fifo_overflows: self.counters.fifo_overflows,
            i2c_errors: self.counters.i2c_errors,
            bus_faults: self.counters.bus_faults,
            bus_recoveries: self.counters.bus_recoveries,
            frames_rejected: self.counters.frames_rejected,
            frames_unsent: self.outbox.unsent,
            cpu_load_permille,
            temp_milli_c: p
                .last_temp
                .map(|t| ((f32::from(t) * s.temp + s.temp_offset) * 1000.0) as i32),
            imu: self.state[0],
            mag: self.state[1],
            imu_period_ns: periods[0],
            mag_period_ns: periods[1],
            cal: self.cal_status,
            mode: p.mode,
        }
    }

    /// Send a status frame; returns the status sent.
    pub fn send_status(
        &mut self,
        uptime_us: u64,
        cpu_load_permille: u16,
        sink: &mut impl FrameSink,
    ) -> Status {
        let st = self.status(uptime_us, cpu_load_permille);
        self.outbox.send_status(&st, sink);
        self.last_status_us = Some(uptime_us);
        st
    }

    /// Each sensor's period, ns (0: not known yet).
    fn periods_ns(&self) -> [u32; 2] {
        self.period.map(period_ns)
    }

    /// Whether the magnetometer is delivering samples (table work is then scheduled right
    /// after its reads; see `process_task`).
    pub fn mag_ok(&self) -> bool {
        self.state[1] == SensorState::Ok
    }

    /// Start a table round now (one snapshot of every engine; a round in progress is
    /// abandoned). Returns its number.
    pub fn start_tables(&mut self, t_us: u64) -> u32 {
        self.tables
            .start(&self.pipeline.engines, t_us, self.periods_ns())
    }

    /// Whether a table round is in progress.
    pub fn tables_pending(&self) -> bool {
        self.tables.pending()
    }

    /// Run the table round's next step when it is time; returns the channel whose table was
    /// queued. No step runs within [`TABLE_SPACING_US`] of a periodic status frame, before or
    /// after it ([`Device::send_status`] at its interval), so the two never share 100 ms of
    /// CPU, unless status frames come so often (under 4 spacings apart) that steps would
    /// hardly ever run.
    pub fn tables_step(
        &mut self,
        now_us: u64,
        sink: &mut impl FrameSink,
    ) -> Option<imu_proto::Channel> {
        let interval = u64::from(self.status_ms) * 1000;
        if let Some(last) = self
            .last_status_us
            .filter(|_| interval >= 4 * TABLE_SPACING_US)
        {
            let next = last + interval;
            if now_us < last + TABLE_SPACING_US || now_us + TABLE_SPACING_US > next {
                return None;
            }
        }
        self.tables
            .step(now_us, &self.pipeline.scales, &mut self.outbox, sink)
    }

    /// The table of a channel now (tests): an immediate snapshot.
    pub fn table(&mut self, ch: imu_proto::Channel, t_us: u64) -> imu_proto::AllanTable {
        let round = self.start_tables(t_us);
        let _ = round;
        let t = self.tables.table(ch.index(), &self.pipeline.scales);
        self.tables.abandon();
        t
    }

    /// A host frame was rejected by the decoder.
    pub fn rejected_frame(&mut self) {
        self.counters.frames_rejected = self.counters.frames_rejected.saturating_add(1);
    }
}

/// A [`Fine`] period in ns.
fn period_ns(p: Fine) -> u32 {
    p.ns() as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reported period stored in Fine units reads back as the same ns.
    #[test]
    fn reported_periods_round_trip_through_fine_units() {
        for ns in (1..=20_000_000u32).step_by(997) {
            assert_eq!(
                period_ns(u64::from(ns) * crate::clock::US / 1000),
                ns,
                "{ns}"
            );
        }
    }
}
