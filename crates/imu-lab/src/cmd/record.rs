//! `imu-lab record --port PORT --out FILE.csv [--raw] [--seconds S]`: stream samples from the
//! device into a CSV in the contract every other subcommand reads.
//!
//! The rows, their columns and the accounts of what was lost are `imu_link::record`'s (shared
//! with `pico_imu.Device.record`): header `t,ax,ay,az,gx,gy,gz,mx,my,mz,temp,gap_before,q0,q1,
//! q2,q3,roll,pitch,heading,ahrs`, one row per IMU sample received (1 kHz), `t` on the sensor's
//! own sample clock (the device's stamps), values in m/s², deg/s, µT, °C, `gap_before` the IMU
//! samples missing right before the row, an empty field for a value the device did not have.
//!
//! `--raw` records the uncorrected counts (converted with the nominal sensitivities), as
//! calibration fitting needs; the default records the corrected values. The summary states the
//! samples the device took over the recording, those received, and those lost with their causes.
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use imu_link::device;
use imu_link::record::{self, Recorder, Row};
use imu_proto::{Reply, Request};
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
        device::set_declination(&mut link, d)?;
    }
    if let Reply::Identity(id) = link.request(Request::Identify)? {
        eprintln!(
            "device: {} on {} (IMU {} Hz, magnetometer {} Hz)",
            id.firmware, id.board, id.imu_rate_hz, id.mag_rate_hz
        );
    }
    let file = File::create(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut w = record::csv_writer(BufWriter::new(file))
        .with_context(|| format!("writing {}", a.out.display()))?;
    let mut rec = Recorder::start(&mut link, a.raw)?;

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
    // The first write error, if any: rows after it are not written.
    let mut written: std::io::Result<()> = Ok(());
    let mut write = |r: &Row| {
        if written.is_ok() {
            written = w.row(&r.fields());
        }
    };
    while rec.span() < a.seconds && !stop.load(Ordering::Relaxed) {
        rec.poll(&mut link, Duration::from_millis(500), &mut write, |e| {
            // suspend + eprintln: shown even when the bar is hidden (stderr not a terminal).
            pb.suspend(|| eprintln!("device event: {e:?}"));
        })
        .with_context(|| format!("recording into {}", a.out.display()))?;
        pb.set_position((rec.span() * 1000.0) as u64);
        pb.set_message(format!(
            "{} rows, {} samples lost",
            rec.rows.rows, rec.rows.missing
        ));
    }
    pb.finish_and_clear();
    if stop.load(Ordering::Relaxed) {
        eprintln!("stopped by Ctrl-C after {:.3} s of device time", rec.span());
    }
    // The rows still held are written, streaming is switched off (a failure there does not
    // lose the recording) and the device's counters asked for.
    let done = rec.finish(&mut link, &mut write);
    written.with_context(|| format!("writing {}", a.out.display()))?;
    w.finish()
        .with_context(|| format!("writing {}", a.out.display()))?;
    println!(
        "{}: {}; {} samples before the first magnetometer reading not recorded, {} device events",
        a.out.display(),
        record::summary(&done.rows, &done.losses),
        done.rows.before_mag,
        done.events.len()
    );
    if let Some(s) = done.status {
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
