//! `imu-lab record --port PORT --out FILE.csv [--raw] [--seconds S]`: stream samples from the
//! device into a CSV in the contract every other subcommand reads.
//!
//! Rows are the IMU samples (1 kHz): `t` is the device timestamp in s since boot, the
//! magnetometer columns hold the latest magnetometer sample taken at or before `t` (200 Hz,
//! zero-order hold), and rows start at the first IMU sample after the first magnetometer sample,
//! so every row is complete. `--raw` records the uncorrected counts (converted with the nominal
//! sensitivities), as calibration fitting needs; the default records the corrected values.
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use imu_proto::{DeviceMsg, ImuSample, MagSample, Reply, Request, SampleBatch, Scales, StreamMode};
use indicatif::{ProgressBar, ProgressStyle};

use crate::link::PortArgs;

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub port: PortArgs,
    /// Output CSV (columns t,ax,ay,az,gx,gy,gz,mx,my,mz,temp).
    #[arg(long)]
    pub out: PathBuf,
    /// Record raw counts (nominal sensitivity, no corrections) instead of corrected values.
    #[arg(long)]
    pub raw: bool,
    /// Seconds of device time to record.
    #[arg(long, default_value_t = 60.0)]
    pub seconds: f64,
}

/// The CSV header of the contract.
pub const HEADER: &str = "t,ax,ay,az,gx,gy,gz,mx,my,mz,temp";

/// Turns sample batches into contract rows (pure: no I/O, unit-tested below).
#[derive(Debug, Default)]
pub struct Rows {
    mag: Option<[f64; 3]>,
    last_seq: Option<u32>,
    /// IMU samples dropped because no magnetometer sample had arrived yet.
    pub before_mag: u64,
    /// Jumps in the IMU sequence numbers, and the samples missing in them.
    pub gaps: u64,
    pub missing: u64,
    pub rows: u64,
    pub first_t: Option<f64>,
    pub last_t: Option<f64>,
}

impl Rows {
    /// Convert one batch; calls `row` with `[t, ax … temp]` for each complete row.
    pub fn batch(&mut self, b: &SampleBatch, mut row: impl FnMut(&[f64; 11])) {
        let s = b.scales;
        let mut mags = b.mag.iter().peekable();
        for imu in &b.imu {
            while let Some(m) = mags.next_if(|m| m.t_us <= imu.t_us) {
                self.mag = Some(mag_ut(m, &s));
            }
            if let Some(prev) = self.last_seq {
                let step = imu.seq.wrapping_sub(prev);
                if step != 1 {
                    self.gaps += 1;
                    self.missing += u64::from(step.wrapping_sub(1));
                }
            }
            self.last_seq = Some(imu.seq);
            let Some(mag) = self.mag else {
                self.before_mag += 1;
                continue;
            };
            let r = imu_row(imu, mag, &s);
            self.first_t.get_or_insert(r[0]);
            self.last_t = Some(r[0]);
            self.rows += 1;
            row(&r);
        }
        for m in mags {
            self.mag = Some(mag_ut(m, &s));
        }
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

fn imu_row(i: &ImuSample, mag: [f64; 3], s: &Scales) -> [f64; 11] {
    let a = i.accel.map(|v| f64::from(v) * f64::from(s.accel));
    let g = i.gyro.map(|v| f64::from(v) * f64::from(s.gyro));
    let temp = f64::from(i.temp) * f64::from(s.temp) + f64::from(s.temp_offset);
    [
        i.t_us as f64 * 1e-6,
        a[0],
        a[1],
        a[2],
        g[0],
        g[1],
        g[2],
        mag[0],
        mag[1],
        mag[2],
        temp,
    ]
}

/// One CSV line: `t` with µs resolution, the values at f32 precision (shortest
/// representation), which exceeds the sensors' 16-bit resolution.
pub fn csv_line(r: &[f64; 11]) -> String {
    let mut s = format!("{:.6}", r[0]);
    for v in &r[1..] {
        s.push(',');
        s.push_str(&(*v as f32).to_string());
    }
    s
}

/// Append the rows of one batch to the CSV.
fn write_batch(b: &SampleBatch, rows: &mut Rows, w: &mut impl Write) -> std::io::Result<()> {
    let mut res = Ok(());
    rows.batch(b, |r| {
        if res.is_ok() {
            res = writeln!(w, "{}", csv_line(r));
        }
    });
    res
}

pub fn run(a: Args) -> Result<()> {
    if !(a.seconds > 0.0 && a.seconds.is_finite()) {
        bail!(
            "--seconds must be a positive number of seconds, got {}",
            a.seconds
        );
    }
    let mut link = a.port.open()?;
    if let Reply::Identity(id) = link.request(Request::Identify)? {
        eprintln!(
            "device: {} on {} (IMU {} Hz, magnetometer {} Hz)",
            id.firmware, id.board, id.imu_rate_hz, id.mag_rate_hz
        );
    }
    let file = File::create(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut w = BufWriter::new(file);
    writeln!(w, "{HEADER}")?;

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
    let mut idle = 0;
    while rows.span() < a.seconds && !stop.load(Ordering::Relaxed) {
        match link.recv(Duration::from_millis(500))? {
            Some(DeviceMsg::Samples(b)) => {
                idle = 0;
                if b.calibrated != a.raw {
                    write_batch(&b, &mut rows, &mut w)
                        .with_context(|| format!("writing {}", a.out.display()))?;
                }
                pb.set_position((rows.span() * 1000.0) as u64);
                pb.set_message(format!("{} rows, {} gaps", rows.rows, rows.gaps));
            }
            Some(DeviceMsg::Event(e)) => {
                // suspend + eprintln: shown even when the bar is hidden (stderr not a terminal).
                pb.suspend(|| eprintln!("device event: {e:?}"));
                events.push(e);
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
    if stop.load(Ordering::Relaxed) {
        eprintln!(
            "stopped by Ctrl-C after {:.3} s of device time",
            rows.span()
        );
    }
    w.flush()
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
        "{}: {} rows, {:.3} s of device time, {} gaps ({} samples missing), {} samples before the first magnetometer reading skipped, {} device events",
        a.out.display(),
        rows.rows,
        rows.span(),
        rows.gaps,
        rows.missing,
        rows.before_mag,
        events.len()
    );
    if let Ok(Reply::Status(s)) = status {
        println!(
            "device: {} samples taken, {} dropped, {} FIFO overflows, {} I2C errors, {} frames not sent",
            s.samples_taken, s.samples_dropped, s.fifo_overflows, s.i2c_errors, s.frames_unsent
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

#[cfg(test)]
mod tests {
    use super::*;
    use imu_proto::Vec as HVec;

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
            temp: 340,
        }
    }

    #[test]
    fn rows_hold_the_latest_magnetometer_sample_and_scale_to_contract_units() {
        let mut b = SampleBatch {
            calibrated: true,
            scales: scales(),
            imu: HVec::new(),
            mag: HVec::new(),
        };
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
        let mut r = Rows::default();
        let mut out = Vec::new();
        r.batch(&b, |row| out.push(*row));
        // Samples at 100 and 101 ms precede the first magnetometer reading.
        assert_eq!(r.before_mag, 2);
        assert_eq!(out.len(), 8);
        // Scales are f32 on the wire: 0.1 µT/LSB is 0.1 within 1.5e-9; compare to 1e-6.
        let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6);
        assert_eq!(out[0][0], 0.102);
        assert!(
            close(&out[0][1..7], &[1.0, 2.0, 3.0, 1.0, 2.0, -3.0]),
            "{:?}",
            out[0]
        );
        assert!(close(&out[0][7..10], &[1.0, 2.0, 3.0]), "{:?}", out[0]);
        assert!(close(&out[4][7..10], &[1.0, 2.0, 3.0])); // 106 ms: still the 102 ms reading
        assert!(close(&out[5][7..10], &[4.0, 5.0, 6.0])); // 107 ms: the new one
        assert_eq!(csv_line(&out[5]).split(',').nth(7), Some("4"));
        // 340 LSB = 1 °C above 36.53 °C.
        assert!((out[0][10] - 37.53).abs() < 1e-5, "{}", out[0][10]); // f32 offset: ±2e-6 °C
        assert_eq!(r.gaps, 0);
        assert!((r.span() - 0.007).abs() < 1e-12);
    }

    #[test]
    fn a_sequence_jump_is_counted_as_a_gap() {
        let mut b = SampleBatch {
            calibrated: true,
            scales: scales(),
            imu: HVec::new(),
            mag: HVec::new(),
        };
        b.mag
            .push(MagSample {
                seq: 0,
                t_us: 0,
                mag: [0, 0, 0],
            })
            .unwrap();
        for (seq, t) in [(0, 1), (1, 2), (5, 6), (6, 7)] {
            b.imu.push(imu(seq, t)).unwrap();
        }
        let mut r = Rows::default();
        r.batch(&b, |_| {});
        assert_eq!((r.gaps, r.missing, r.rows), (1, 3, 4));
    }
}
