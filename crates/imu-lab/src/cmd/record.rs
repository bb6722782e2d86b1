//! `imu-lab record --port PORT --out FILE.csv [--raw] [--seconds S]`: stream samples from the
//! device into a CSV in the contract every other subcommand reads.
//!
//! The CSV (docs/firmware.md, "The recording"): header `t,ax,ay,az,gx,gy,gz,mx,my,mz,temp,
//! gap_before,q0,q1,q2,q3,roll,pitch,heading,ahrs`, one row per IMU sample received (1 kHz):
//! * `t`: when the sensor took the sample, s since the device booted, on the sensor's own sample
//!   clock (the device's stamps: `t₀ + k·T̂`, docs/firmware.md "Timestamps");
//! * `ax … temp` in m/s², deg/s, µT, °C; the magnetometer columns hold the latest magnetometer
//!   sample taken at or before `t` (200 Hz, zero-order hold); rows start at the first IMU sample
//!   after the first magnetometer sample;
//! * `q0 … ahrs`: the device's attitude estimate (200 Hz, `imu_proto::Orientation`): the
//!   latest made at or before `t` (its instant is the last IMU sample it integrated), held;
//!   empty before the first. `ahrs` is the filter's state: 0 converging, 1 tracking, 2 |B| and
//!   3 dip out of their bands (a magnetic disturbance). A row is written once an estimate at or
//!   after its time has arrived (estimates and samples travel in separate frames), or 0.5 s of
//!   rows later (a device that sends none);
//! * `gap_before`: how many IMU samples of the device's sample grid are missing right before this
//!   row (0 normally): lost on the device (each comes with a `Gap` event and its cause) or on the
//!   link;
//! * a value the device did not have (a temperature the sample did not carry) is an empty field,
//!   never a number.
//!
//! `--raw` records the uncorrected counts (converted with the nominal sensitivities), as
//! calibration fitting needs; the default records the corrected values. The summary states the
//! samples the device took over the recording, those received, and those lost with their causes.
use std::collections::{BTreeMap, VecDeque};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use imu_proto::csv::{WriteOptions, Writer, GAP_BEFORE};
use imu_proto::{
    DeviceMsg, Event, GapCause, ImuSample, MagReference, MagSample, Orientation, Reply, Request,
    SampleBatch, Scales, Sensor, StreamMode,
};
use indicatif::{ProgressBar, ProgressStyle};

use crate::link::PortArgs;

#[derive(clap::Args, Debug)]
#[command(
    after_help = "CSV: t,ax,ay,az,gx,gy,gz,mx,my,mz,temp,gap_before,q0,q1,q2,q3,roll,pitch,heading,ahrs \
— t in s on the sensor's sample clock (the device's stamps), values in m/s², deg/s, µT, °C; \
gap_before = IMU samples lost right before the row (0 normally); q0…q3 the device's attitude \
(body → NED), roll, pitch, heading in degrees, ahrs its state (0 converging, 1 tracking, 2 |B| \
and 3 dip out of band); a value the device did not have is an empty field."
)]
pub struct Args {
    #[command(flatten)]
    pub port: PortArgs,
    /// Output CSV (columns t,ax,ay,az,gx,gy,gz,mx,my,mz,temp,gap_before).
    #[arg(long)]
    pub out: PathBuf,
    /// Record raw counts (nominal sensitivity, no corrections) instead of corrected values.
    #[arg(long)]
    pub raw: bool,
    /// Seconds of device time to record.
    #[arg(long, default_value_t = 60.0)]
    pub seconds: f64,
    /// Set the device's declination first (degrees, east positive; added to the heading; held
    /// in the device's RAM until a reset or the next setting).
    #[arg(long, allow_hyphen_values = true)]
    pub declination: Option<f64>,
}

/// The recording's columns, in order (names of the CSV contract, `imu_proto::csv`).
pub const COLUMNS: [&str; 20] = [
    "t", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp", GAP_BEFORE, "q0", "q1",
    "q2", "q3", "roll", "pitch", "heading", "ahrs",
];

/// How the recording prints numbers: `t` with µs resolution, the values at f32 precision
/// (shortest text that reads back; beyond the sensors' 16-bit resolution).
pub const PRINT: WriteOptions = WriteOptions {
    time_decimals: Some(6),
    f32_values: true,
};

/// One CSV row: `t` (s), the ten values in contract units (`None`: missing), and the IMU samples
/// missing right before it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    pub t: f64,
    pub values: [Option<f64>; 10],
    pub gap_before: u64,
    /// The device's attitude estimate held at `t` (see [`Held`]).
    pub orient: Option<Orientation>,
}

/// Turns sample batches into contract rows and keeps the accounts (pure: no I/O).
#[derive(Debug, Default)]
pub struct Rows {
    mag: Option<[f64; 3]>,
    last_seq: Option<u32>,
    last_mag_seq: Option<u32>,
    /// IMU samples dropped because no magnetometer sample had arrived yet.
    pub before_mag: u64,
    /// IMU samples missing between received ones (jumps of the sample-grid numbers).
    pub missing: u64,
    /// Magnetometer samples missing between received ones.
    pub mag_missing: u64,
    pub mag_received: u64,
    pub rows: u64,
    pub first_t: Option<f64>,
    pub last_t: Option<f64>,
}

impl Rows {
    /// Convert one batch; calls `row` for each complete row.
    pub fn batch(&mut self, b: &SampleBatch, mut row: impl FnMut(&Row)) {
        let s = b.scales;
        let mut mags = b.mag.iter().peekable();
        for imu in &b.imu {
            while let Some(m) = mags.next_if(|m| m.t_us <= imu.t_us) {
                self.take_mag(m, &s);
            }
            let gap = match self.last_seq {
                Some(prev) => u64::from(imu.seq.wrapping_sub(prev).wrapping_sub(1)),
                None => 0,
            };
            self.missing += gap;
            self.last_seq = Some(imu.seq);
            let Some(mag) = self.mag else {
                self.before_mag += 1;
                continue;
            };
            let r = imu_row(imu, mag, &s, gap);
            self.first_t.get_or_insert(r.t);
            self.last_t = Some(r.t);
            self.rows += 1;
            row(&r);
        }
        for m in mags {
            self.take_mag(m, &s);
        }
    }

    fn take_mag(&mut self, m: &MagSample, s: &Scales) {
        if let Some(prev) = self.last_mag_seq {
            self.mag_missing += u64::from(m.seq.wrapping_sub(prev).wrapping_sub(1));
        }
        self.last_mag_seq = Some(m.seq);
        self.mag_received += 1;
        self.mag = Some(mag_ut(m, s));
    }

    /// Device time covered so far, s.
    pub fn span(&self) -> f64 {
        match (self.first_t, self.last_t) {
            (Some(a), Some(b)) => b - a,
            _ => 0.0,
        }
    }
}

fn mag_ut(m: &MagSample, s: &Scales) -> [f64; 3] {
    m.mag.map(|v| f64::from(v) * f64::from(s.mag))
}

fn imu_row(i: &ImuSample, mag: [f64; 3], s: &Scales, gap_before: u64) -> Row {
    let a = i.accel.map(|v| f64::from(v) * f64::from(s.accel));
    let g = i.gyro.map(|v| f64::from(v) * f64::from(s.gyro));
    let temp = i
        .temp
        .map(|t| f64::from(t) * f64::from(s.temp) + f64::from(s.temp_offset));
    Row {
        t: i.t_us as f64 * 1e-6,
        values: [
            Some(a[0]),
            Some(a[1]),
            Some(a[2]),
            Some(g[0]),
            Some(g[1]),
            Some(g[2]),
            Some(mag[0]),
            Some(mag[1]),
            Some(mag[2]),
            temp,
        ],
        gap_before,
        orient: None,
    }
}

impl Row {
    /// The row's fields in [`COLUMNS`] order (`None`: an empty field).
    pub fn fields(&self) -> [Option<f64>; 20] {
        let mut f = [None; 20];
        f[0] = Some(self.t);
        f[1..11].copy_from_slice(&self.values);
        f[11] = Some(self.gap_before as f64);
        if let Some(o) = &self.orient {
            for (k, q) in o.q.iter().enumerate() {
                f[12 + k] = Some(f64::from(*q));
            }
            f[16] = Some(f64::from(o.roll_deg));
            f[17] = Some(f64::from(o.pitch_deg));
            f[18] = Some(f64::from(o.heading_deg));
            f[19] = Some(o.state as u8 as f64);
        }
        f
    }
}

/// Rows waiting for the attitude estimates that cover them (pure: no I/O). Estimates arrive in
/// time order, in frames of their own: once one at or after a row's time has arrived, every
/// estimate at or before it is known, and the row gets the latest of those.
#[derive(Debug, Default)]
pub struct Held {
    rows: VecDeque<Row>,
    estimates: VecDeque<Orientation>,
    held: Option<Orientation>,
    /// The newest estimate's time, s.
    newest: Option<f64>,
}

/// Rows held at most (0.5 s at 1 kHz) before they are written with what is known.
const HOLD_ROWS: usize = 500;

impl Held {
    pub fn row(&mut self, r: Row) {
        self.rows.push_back(r);
    }

    pub fn estimates(&mut self, o: &[Orientation]) {
        for e in o {
            self.newest = Some(e.t_us as f64 * 1e-6);
            self.estimates.push_back(*e);
        }
    }

    /// Hand over the rows that are complete (all of them with `all`).
    pub fn release(&mut self, all: bool, mut out: impl FnMut(&Row)) {
        while let Some(t) = self.rows.front().map(|r| r.t) {
            let covered = self.newest.is_some_and(|n| n >= t);
            if !(all || covered || self.rows.len() > HOLD_ROWS) {
                break;
            }
            let Some(mut r) = self.rows.pop_front() else {
                break;
            };
            while let Some(e) = self.estimates.front() {
                if e.t_us as f64 * 1e-6 > r.t {
                    break;
                }
                self.held = self.estimates.pop_front();
            }
            r.orient = self.held;
            out(&r);
        }
    }
}

/// Append the rows of one batch to the CSV (those whose estimates have arrived).
fn write_batch(
    b: &SampleBatch,
    rows: &mut Rows,
    held: &mut Held,
    w: &mut Writer<impl Write>,
) -> std::io::Result<()> {
    rows.batch(b, |r| held.row(*r));
    write_held(held, false, w)
}

fn write_held(held: &mut Held, all: bool, w: &mut Writer<impl Write>) -> std::io::Result<()> {
    let mut res = Ok(());
    held.release(all, |r| {
        if res.is_ok() {
            res = w.row(&r.fields());
        }
    });
    res
}

/// The device's own account of its losses during the recording: `Gap` events by sensor and
/// cause.
#[derive(Debug, Default)]
pub struct DeviceLosses {
    pub imu: BTreeMap<String, u64>,
    pub mag: BTreeMap<String, u64>,
}

impl DeviceLosses {
    pub fn event(&mut self, e: &Event) {
        if let Event::Gap {
            sensor,
            cause,
            lost,
            ..
        } = e
        {
            if *lost > 0 {
                let m = match sensor {
                    Sensor::Imu => &mut self.imu,
                    Sensor::Mag => &mut self.mag,
                };
                *m.entry(cause_name(*cause).to_string()).or_default() += u64::from(*lost);
            }
        }
    }

    fn total(m: &BTreeMap<String, u64>) -> u64 {
        m.values().sum()
    }
}

fn cause_name(c: GapCause) -> &'static str {
    match c {
        GapCause::FifoOverflow => "FIFO overflow",
        GapCause::SensorFault => "sensor fault",
        GapCause::BusFault => "bus fault",
        GapCause::Stalled => "sensor stalled",
        GapCause::Overwritten => "overwritten unread",
        GapCause::Paused => "paused for a flash write",
    }
}

/// "12 FIFO overflow, 3 bus fault" (the device's), plus what only the numbering shows (lost on
/// the link).
fn causes(device: &BTreeMap<String, u64>, missing: u64) -> String {
    let mut parts: Vec<String> = device.iter().map(|(c, n)| format!("{n} {c}")).collect();
    let on_device = DeviceLosses::total(device);
    if missing > on_device {
        parts.push(format!("{} not received (link)", missing - on_device));
    }
    if parts.is_empty() {
        "none".into()
    } else {
        parts.join(", ")
    }
}

/// The summary line's facts, every count with what it counts.
pub fn summary(rows: &Rows, losses: &DeviceLosses) -> String {
    let lost = rows.missing.max(DeviceLosses::total(&losses.imu));
    let mag_lost = rows.mag_missing.max(DeviceLosses::total(&losses.mag));
    format!(
        "{} rows over {:.3} s of device time; IMU: {} samples taken by the device, {} received, {} lost ({}); magnetometer: {} received, {} lost ({})",
        rows.rows,
        rows.span(),
        rows.rows + lost,
        rows.rows,
        lost,
        causes(&losses.imu, rows.missing),
        rows.mag_received,
        mag_lost,
        causes(&losses.mag, rows.mag_missing),
    )
}

pub fn run(a: Args) -> Result<()> {
    if !(a.seconds > 0.0 && a.seconds.is_finite()) {
        bail!(
            "--seconds must be a positive number of seconds, got {}",
            a.seconds
        );
    }
    if let Some(d) = a.declination {
        if !(-180.0..=180.0).contains(&d) {
            bail!("--declination {d}: degrees within ±180");
        }
    }
    let mut link = a.port.open()?;
    if let Some(d) = a.declination {
        set_declination(&mut link, d)?;
    }
    if let Reply::Identity(id) = link.request(Request::Identify)? {
        eprintln!(
            "device: {} on {} (IMU {} Hz, magnetometer {} Hz)",
            id.firmware, id.board, id.imu_rate_hz, id.mag_rate_hz
        );
    }
    let file = File::create(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut w = Writer::new(BufWriter::new(file), &COLUMNS, PRINT)
        .with_context(|| format!("writing {}", a.out.display()))?;

    let mode = if a.raw {
        StreamMode::Raw
    } else {
        StreamMode::Calibrated
    };
    let mut rows = Rows::default();
    // Batches that arrive before the reply are from the previous mode: not recorded.
    match link.request_with(Request::SetMode(mode), crate::link::REPLY_TIMEOUT, |_| {})? {
        Reply::Ok => {}
        other => bail!("the device did not accept streaming mode {mode:?}: {other:?}"),
    }

    let pb = ProgressBar::new((a.seconds * 1000.0) as u64);
    pb.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} ms of device time  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    // Ctrl-C ends the recording like the end of --seconds: the rows so far are flushed, streaming
    // is switched off and the summary printed. (A second handler cannot be installed in one
    // process; then Ctrl-C keeps its default meaning, and the BufWriter still flushes on exit.)
    let stop = Arc::new(AtomicBool::new(false));
    let stopped = stop.clone();
    if let Err(e) = ctrlc::set_handler(move || stopped.store(true, Ordering::Relaxed)) {
        pb.println(format!("Ctrl-C will not end the recording cleanly: {e}"));
    }
    let mut events = Vec::new();
    let mut losses = DeviceLosses::default();
    let mut held = Held::default();
    let mut idle = 0;
    while rows.span() < a.seconds && !stop.load(Ordering::Relaxed) {
        match link.recv(Duration::from_millis(500))? {
            Some(DeviceMsg::Samples(b)) => {
                idle = 0;
                if b.calibrated != a.raw {
                    write_batch(&b, &mut rows, &mut held, &mut w)
                        .with_context(|| format!("writing {}", a.out.display()))?;
                }
                pb.set_position((rows.span() * 1000.0) as u64);
                pb.set_message(format!("{} rows, {} samples lost", rows.rows, rows.missing));
            }
            Some(DeviceMsg::Event(e)) => {
                // suspend + eprintln: shown even when the bar is hidden (stderr not a terminal).
                pb.suspend(|| eprintln!("device event: {e:?}"));
                losses.event(&e);
                events.push(e);
            }
            Some(DeviceMsg::Orientation(o)) => {
                held.estimates(&o);
                write_held(&mut held, false, &mut w)
                    .with_context(|| format!("writing {}", a.out.display()))?;
            }
            Some(_) => {}
            None => {
                idle += 1;
                if idle >= 20 {
                    bail!(
                        "no samples from {} for 10 s ({} rows written to {})",
                        link.name(),
                        rows.rows,
                        a.out.display()
                    );
                }
            }
        }
    }
    pb.finish_and_clear();
    write_held(&mut held, true, &mut w).with_context(|| format!("writing {}", a.out.display()))?;
    if stop.load(Ordering::Relaxed) {
        eprintln!(
            "stopped by Ctrl-C after {:.3} s of device time",
            rows.span()
        );
    }
    w.finish()
        .with_context(|| format!("writing {}", a.out.display()))?;
    // Stop streaming; a failure here does not lose the recording.
    let status = link
        .request_with(
            Request::SetMode(StreamMode::Off),
            crate::link::REPLY_TIMEOUT,
            |_| {},
        )
        .and_then(|_| link.request(Request::GetStatus));
    println!(
        "{}: {}; {} samples before the first magnetometer reading not recorded, {} device events",
        a.out.display(),
        summary(&rows, &losses),
        rows.before_mag,
        events.len()
    );
    if let Ok(Reply::Status(s)) = status {
        println!(
            "device counters since boot: IMU {} samples taken, {} lost; magnetometer {} taken, {} lost; {} FIFO overflows, {} I2C errors, {} frames not sent",
            s.samples_taken, s.samples_dropped, s.mag_samples, s.mag_dropped, s.fifo_overflows, s.i2c_errors, s.frames_unsent
        );
    }
    let st = link.rx_stats();
    if st.rejected() > 0 {
        println!(
            "link: {} corrupt frames from the device were skipped",
            st.rejected()
        );
    }
    Ok(())
}

/// Set the device's declination, keeping its expected field (a host's, or learnt).
pub fn set_declination(link: &mut crate::link::Link, deg: f64) -> Result<()> {
    let reference: Option<MagReference> = match link.request(Request::GetOrientation)? {
        Reply::Orientation(c) if !c.learnt => c.reference,
        Reply::Orientation(_) => None,
        other => bail!("unexpected reply to GetOrientation: {other:?}"),
    };
    match link.request(Request::SetOrientation {
        declination_cdeg: (deg * 100.0).round() as i16,
        reference,
    })? {
        Reply::Ok => Ok(()),
        other => bail!("the device refused declination {deg}°: {other:?}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use imu_proto::Vec as HVec;

    /// The CSV line the recording writes for `r`.
    fn csv_line(r: &Row) -> String {
        let mut w = Writer::new(Vec::new(), &COLUMNS, PRINT).unwrap();
        w.row(&r.fields()).unwrap();
        let text = String::from_utf8(w.finish().unwrap()).unwrap();
        text.lines().nth(1).unwrap().to_string()
    }

    fn scales() -> Scales {
        Scales {
            accel: 0.5,
            gyro: 0.25,
            mag: 0.1,
            temp: 1.0 / 340.0,
            temp_offset: 36.53,
        }
    }

    fn imu(seq: u32, t_ms: u64) -> ImuSample {
        ImuSample {
            seq,
            t_us: t_ms * 1000,
            accel: [2, 4, 6],
            gyro: [4, 8, -12],
            temp: Some(340),
        }
    }

    fn batch() -> SampleBatch {
        SampleBatch {
            calibrated: true,
            scales: scales(),
            imu: HVec::new(),
            mag: HVec::new(),
        }
    }

    /// A batch opening with one magnetometer sample `mag` at t = 0.
    fn batch_with_mag(mag: [i32; 3]) -> SampleBatch {
        let mut b = batch();
        b.mag
            .push(MagSample {
                seq: 0,
                t_us: 0,
                mag,
            })
            .unwrap();
        b
    }

    /// The rows of `b` and the accounts after it.
    fn rows_of(b: &SampleBatch) -> (Rows, Vec<Row>) {
        let mut r = Rows::default();
        let mut out = Vec::new();
        r.batch(b, |row| out.push(*row));
        (r, out)
    }

    #[test]
    fn rows_hold_the_latest_magnetometer_sample_and_scale_to_contract_units() {
        let mut b = batch();
        for k in 0..10 {
            b.imu.push(imu(k, 100 + u64::from(k))).unwrap();
        }
        // Magnetometer readings at 102 ms and 107 ms.
        b.mag
            .push(MagSample {
                seq: 0,
                t_us: 102_000,
                mag: [10, 20, 30],
            })
            .unwrap();
        b.mag
            .push(MagSample {
                seq: 1,
                t_us: 107_000,
                mag: [40, 50, 60],
            })
            .unwrap();
        let (r, out) = rows_of(&b);
        // Samples at 100 and 101 ms precede the first magnetometer reading.
        assert_eq!(r.before_mag, 2);
        assert_eq!(out.len(), 8);
        // Scales are f32 on the wire: 0.1 µT/LSB is 0.1 within 1.5e-9; compare to 1e-6.
        let v = |row: &Row, i: usize| row.values[i].unwrap();
        let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
        assert_eq!(out[0].t, 0.102);
        assert!(
            close(v(&out[0], 0), 1.0) && close(v(&out[0], 5), -3.0),
            "{:?}",
            out[0]
        );
        assert!(close(v(&out[0], 6), 1.0) && close(v(&out[0], 8), 3.0));
        assert!(close(v(&out[4], 6), 1.0)); // 106 ms: still the 102 ms reading
        assert!(close(v(&out[5], 6), 4.0)); // 107 ms: the new one
        assert_eq!(csv_line(&out[5]).split(',').nth(7), Some("4"));
        // 340 LSB = 1 °C above 36.53 °C.
        assert!((v(&out[0], 9) - 37.53).abs() < 1e-5); // f32 offset: ±2e-6 °C
        assert_eq!(r.missing, 0);
        assert!(out.iter().all(|row| row.gap_before == 0));
        assert!((r.span() - 0.007).abs() < 1e-12);
    }

    #[test]
    fn a_sequence_jump_is_marked_on_the_row_after_it() {
        let mut b = batch_with_mag([0, 0, 0]);
        for (seq, t) in [(0, 1), (1, 2), (5, 6), (6, 7)] {
            b.imu.push(imu(seq, t)).unwrap();
        }
        let (r, out) = rows_of(&b);
        assert_eq!((r.missing, r.rows), (3, 4));
        let gaps: Vec<u64> = out.iter().map(|r| r.gap_before).collect();
        assert_eq!(gaps, [0, 0, 3, 0]);
        assert!(csv_line(&out[2]).ends_with(",3,,,,,,,,"));
    }

    #[test]
    fn a_missing_temperature_is_an_empty_field() {
        let mut b = batch_with_mag([1, 2, 3]);
        let mut s = imu(0, 1);
        s.temp = None;
        b.imu.push(s).unwrap();
        let (_, out) = rows_of(&b);
        let line = csv_line(&out[0]);
        let fields: Vec<&str> = line.split(',').collect();
        assert_eq!(fields.len(), COLUMNS.len());
        assert_eq!(fields[10], "", "{line}");
        assert_eq!(fields[11], "0");
    }

    #[test]
    fn the_summary_splits_losses_by_the_device_causes_and_the_link() {
        let mut r = Rows::default();
        let mut b = batch_with_mag([0, 0, 0]);
        for (seq, t) in [(0, 1), (1, 2), (20, 21), (21, 22)] {
            b.imu.push(imu(seq, t)).unwrap();
        }
        r.batch(&b, |_| {});
        let mut l = DeviceLosses::default();
        l.event(&Event::Gap {
            sensor: Sensor::Imu,
            at: 2,
            cause: GapCause::FifoOverflow,
            lost: 15,
            t_us: 21_000,
        });
        let s = summary(&r, &l);
        assert!(
            s.contains("22 samples taken by the device, 4 received, 18 lost"),
            "{s}"
        );
        assert!(s.contains("15 FIFO overflow, 3 not received (link)"), "{s}");
    }

    /// Rows wait for the estimates that cover them, then carry the latest at or before their
    /// time; the columns are the estimate's, empty before the first.
    #[test]
    fn rows_hold_the_latest_attitude_estimate_at_or_before_them() {
        let est = |t_us: u64, heading: f32| Orientation {
            seq: 0,
            t_us,
            q: [1.0, 0.0, 0.0, 0.0],
            roll_deg: 1.5,
            pitch_deg: -2.5,
            heading_deg: heading,
            state: imu_proto::AhrsState::MagDip,
        };
        let mut h = Held::default();
        let mut b = batch_with_mag([0, 0, 0]);
        for k in 0..10 {
            b.imu.push(imu(k, 1 + u64::from(k))).unwrap();
        }
        let mut r = Rows::default();
        r.batch(&b, |row| h.row(*row));
        let mut out = Vec::new();
        h.release(false, |r| out.push(*r));
        assert!(out.is_empty(), "no estimate yet: rows wait");
        h.estimates(&[est(2_000, 10.0), est(5_000, 20.0)]);
        h.release(false, |r| out.push(*r));
        // Rows at 1 … 5 ms are covered (an estimate at 5 ms arrived); 6 … 10 ms wait.
        assert_eq!(out.len(), 5);
        assert_eq!(out[0].orient, None);
        assert_eq!(out[1].orient.map(|o| o.heading_deg), Some(10.0));
        assert_eq!(out[4].orient.map(|o| o.heading_deg), Some(20.0));
        h.release(true, |r| out.push(*r));
        assert_eq!(out.len(), 10);
        assert_eq!(out[9].orient.map(|o| o.heading_deg), Some(20.0));
        let line = csv_line(&out[9]);
        assert!(line.ends_with(",1,0,0,0,1.5,-2.5,20,3"), "{line}");
        let first = csv_line(&out[0]);
        assert!(first.ends_with(",0,,,,,,,,"), "{first}");
    }
}
