//! `imu-lab device …`: talk to the firmware (a Pico over USB CDC, or the emulator over TCP).
//!
//! * `status` — identity and counters;
//! * `tables [--fit] [--json F]` — the device's streaming Allan tables, each row checked against
//!   its own integer sums; `--fit` runs the noise-model lab on each channel;
//! * `calibrate --upload cal.toml|cal.bin` / `--download [--out cal.bin]` — the calibration in
//!   flash (`imu_cal::file` TOML → fixed-point blob);
//! * `orientation [--declination DEG] [--field-ut B --dip-deg D | --learn]` — the attitude
//!   filter's declination and expected field (kept in the device's flash: a change pauses
//!   sampling for the write);
//! * `reset-allan`, `mode off|calibrated|raw`.
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use imu_link::device::{self, TableRow};
use imu_proto::{AllanTable, Status, StreamMode};

use crate::link::{Link, PortArgs};

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub port: PortArgs,
    #[command(subcommand)]
    pub cmd: Cmd,
}

#[derive(clap::Subcommand, Debug)]
pub enum Cmd {
    /// Identity, sample counters, faults, CPU load and temperature.
    Status,
    /// The device's Allan tables (overlapping ADEV on octave τ, 68.3 % bounds).
    Tables(TablesArgs),
    /// Upload or download the calibration stored in flash.
    Calibrate(CalArgs),
    /// Forget the Allan state on the device.
    ResetAllan,
    /// Choose what the device streams: off, calibrated or raw samples.
    Mode {
        #[arg(value_parser = ["off", "calibrated", "raw"])]
        mode: String,
    },
    /// The attitude filter's declination and expected field: set them (any given) and show
    /// them. Held in the device's RAM until a reset.
    Orientation(OrientationArgs),
}

#[derive(clap::Args, Debug)]
pub struct OrientationArgs {
    /// Declination, degrees east positive, added to the magnetic heading (true heading).
    #[arg(long, allow_hyphen_values = true)]
    pub declination: Option<f64>,
    /// Expected field strength, µT (with --dip-deg): |B| outside ±10 % of it is reported as a
    /// magnetic disturbance.
    #[arg(long, requires = "dip_deg", conflicts_with = "learn")]
    pub field_ut: Option<f64>,
    /// Expected dip (inclination), degrees, positive down (with --field-ut): outside ±5° of it
    /// is reported as a magnetic disturbance.
    #[arg(long, requires = "field_ut", allow_hyphen_values = true)]
    pub dip_deg: Option<f64>,
    /// Let the device learn the expected field (its first converged second after the start or
    /// a new calibration).
    #[arg(long)]
    pub learn: bool,
}

#[derive(clap::Args, Debug)]
pub struct TablesArgs {
    /// Fit the noise model (noise-model crate, default five terms) to each channel's table.
    #[arg(long)]
    pub fit: bool,
    /// Only these channels (ax … mz, temp; comma-separated).
    #[arg(long, value_delimiter = ',')]
    pub channel: Vec<String>,
    /// Also write the tables (with the integer sums) as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Seconds to wait for all ten tables.
    #[arg(long, default_value_t = 30.0)]
    pub timeout: f64,
}

#[derive(clap::Args, Debug)]
#[group(skip)]
#[command(group(
    clap::ArgGroup::new("action")
        .required(true)
        .multiple(false)
        .args(["upload", "download"])
))]
pub struct CalArgs {
    /// Calibration to store: a TOML calibration file (imu_cal::file) or a `.bin` blob.
    #[arg(long)]
    pub upload: Option<PathBuf>,
    /// Read the calibration in use and print it (`--out` saves the blob).
    #[arg(long)]
    pub download: bool,
    /// With --download: write the blob here (re-uploadable with --upload FILE.bin).
    #[arg(long, requires = "download", conflicts_with = "upload")]
    pub out: Option<PathBuf>,
    /// With --upload: apply without writing flash (in RAM only, lost at reset).
    #[arg(long, requires = "upload", conflicts_with = "download")]
    pub no_persist: bool,
}

pub fn run(a: Args) -> Result<()> {
    // A calibration to upload is read and checked before the port is opened: a file the host
    // refuses never reaches the device.
    let upload = match &a.cmd {
        Cmd::Calibrate(CalArgs {
            upload: Some(path), ..
        }) => Some(upload_blob(path)?),
        _ => None,
    };
    let mut link = a.port.open()?;
    match a.cmd {
        Cmd::Status => status(&mut link),
        Cmd::Tables(t) => tables(&mut link, &t),
        Cmd::Calibrate(c) => calibrate(&mut link, &c, upload),
        Cmd::ResetAllan => {
            device::reset_allan(&mut link)?;
            println!("Allan state reset");
            Ok(())
        }
        Cmd::Orientation(o) => orientation(&mut link, &o),
        Cmd::Mode { mode } => {
            let m = match mode.as_str() {
                "off" => StreamMode::Off,
                "raw" => StreamMode::Raw,
                _ => StreamMode::Calibrated,
            };
            device::set_mode(&mut link, m)?;
            println!("streaming mode: {mode}");
            Ok(())
        }
    }
}

fn orientation(link: &mut Link, a: &OrientationArgs) -> Result<()> {
    let mut cfg = device::orientation(link)?;
    if a.declination.is_some() || a.field_ut.is_some() || a.learn {
        let field = a.field_ut.zip(a.dip_deg);
        let req = device::orientation_request(&cfg, a.declination, field, a.learn)
            .map_err(|e| anyhow::anyhow!("orientation settings refused, nothing sent: {e}"))?;
        cfg = device::set_orientation(link, req)?;
    }
    println!(
        "declination {:.2}° (added to the magnetic heading); expected field: {}",
        f64::from(cfg.declination_cdeg) * 0.01,
        match cfg.reference {
            Some(r) => format!(
                "{:.2} µT, dip {:.2}° ({}); a disturbance outside ±10 % of it or ±5° of dip",
                f64::from(r.field_nt) * 1e-3,
                f64::from(r.dip_cdeg) * 0.01,
                if cfg.learnt {
                    "learnt by the device"
                } else {
                    "set by the host"
                }
            ),
            None => "being learnt (the device's first converged second)".into(),
        }
    );
    println!("held in the device's RAM: a reset forgets these settings");
    Ok(())
}

fn status(link: &mut Link) -> Result<()> {
    let id = device::identify(link)?;
    println!(
        "device: {} on {}, protocol {}, IMU {} Hz, magnetometer {} Hz, Allan engines P = {}, {} octave levels ({} for the magnetometer)",
        id.firmware, id.board, id.protocol, id.imu_rate_hz, id.mag_rate_hz, id.allan_overlap, id.allan_levels, id.allan_levels_mag
    );
    print!("{}", format_status(&device::status(link)?));
    Ok(())
}

/// Human-readable status, every number with its unit.
pub fn format_status(s: &Status) -> String {
    let temp = match s.temp_milli_c {
        None => "n/a (no IMU sample with a temperature yet)".to_string(),
        Some(t) => format!("{:.2} °C", f64::from(t) / 1000.0),
    };
    let period = |ns: u32, nominal_us: u64| {
        if ns == 0 {
            "sample clock not measured yet".to_string()
        } else {
            format!(
                "sample period {:.3} µs ({:+.2} % from nominal)",
                f64::from(ns) * 1e-3,
                (f64::from(ns) * 1e-3 / nominal_us as f64 - 1.0) * 100.0
            )
        }
    };
    format!(
        "uptime:            {:.3} s\n\
         IMU:               {:?}, {} samples taken, {} lost, {} FIFO overflows; {}\n\
         magnetometer:      {:?}, {} samples taken, {} lost; {}\n\
         I2C:               {} errors ({} bus faults), {} bus recoveries\n\
         host frames:       {} rejected; device frames not sent: {}\n\
         CPU load:          {:.1} %\n\
         temperature:       {temp}\n\
         calibration:       {}\n\
         streaming:         {:?}\n",
        s.uptime_us as f64 * 1e-6,
        s.imu,
        s.samples_taken,
        s.samples_dropped,
        s.fifo_overflows,
        period(s.imu_period_ns, imu_proto::IMU_PERIOD_US),
        s.mag,
        s.mag_samples,
        s.mag_dropped,
        period(s.mag_period_ns, imu_proto::MAG_PERIOD_US),
        s.i2c_errors,
        s.bus_faults,
        s.bus_recoveries,
        s.frames_rejected,
        s.frames_unsent,
        f64::from(s.cpu_load_permille) / 10.0,
        device::format_cal(&s.cal),
        s.mode
    )
}

fn tables(link: &mut Link, a: &TablesArgs) -> Result<()> {
    let wanted = device::channels(&a.channel).map_err(anyhow::Error::msg)?;
    if !(a.timeout > 0.0 && a.timeout.is_finite()) {
        bail!("--timeout must be positive seconds");
    }
    let got = device::fetch_tables(link, &wanted, Duration::from_secs_f64(a.timeout))?;
    let Some(first) = got.values().next() else {
        bail!("no tables received");
    };
    println!(
        "tables of round {} (one snapshot of every channel, device time {:.3} s)",
        first.snapshot,
        first.t_us as f64 * 1e-6
    );
    for t in got.values() {
        let unit = t.channel.unit();
        println!(
            "\n{} [{unit}]: τ0 = {:.3} µs (the sensor's measured period), {} samples, {} gaps",
            t.channel.name(),
            f64::from(t.tau0_ns) * 1e-3,
            t.pushed,
            t.gaps
        );
        println!(
            "{:>12} {:>9} {:>10} {:>14} {:>14} {:>14} {:>9}",
            "τ [s]", "m", "n", "ADEV", "lo (68.3 %)", "hi", "EDF"
        );
        let rows = device::table_rows(t);
        for (l, r) in t.levels.iter().zip(&rows) {
            println!(
                "{:>12.4e} {:>9} {:>10} {:>14.6e} {:>14.6e} {:>14.6e} {:>9.1}",
                r.tau, l.m, l.n2, r.dev, r.lo, r.hi, r.edf
            );
        }
        if a.fit {
            fit_table(t, &rows);
        }
    }
    println!("\ndeviation, EDF and bounds computed on the host from the device's integer sums (allan::confidence)");
    if let Some(p) = &a.json {
        let v: Vec<&AllanTable> = got.values().collect();
        std::fs::write(p, serde_json::to_string_pretty(&v)?)
            .with_context(|| format!("writing {}", p.display()))?;
        println!("tables written to {}", p.display());
    }
    Ok(())
}

/// The noise-model fit of one device table (default five terms), with the host's bounds.
fn fit_table(t: &AllanTable, rows: &[TableRow]) {
    let pts: Vec<noise_model::Point> = rows
        .iter()
        .filter(|r| r.dev > 0.0 && r.lo > 0.0 && r.hi > r.lo && r.edf > 0.0)
        .map(|r| noise_model::Point {
            tau: r.tau,
            dev: r.dev,
            edf: r.edf,
            lo: r.lo,
            hi: r.hi,
            m: 0,
        })
        .collect();
    let tau0 = f64::from(t.tau0_ns) * 1e-9;
    match noise_model::fit(
        &pts,
        tau0,
        &noise_model::DEFAULT_TERMS,
        &noise_model::FitOptions::default(),
    ) {
        Ok(f) => {
            let a = noise_model::assess(&f);
            println!(
                "  fit ({} points): χ²/dof = {:.2}, {}",
                pts.len(),
                f.chi2_dof(),
                if a.adequate {
                    "adequate"
                } else {
                    "NOT adequate"
                }
            );
            for term in &f.terms {
                let amp = term.amplitude();
                match term.upper_bound() {
                    None => println!(
                        "    {:<14} {:.4e} ± {:.1e} ({} in canonical units of {})",
                        term.effect.name(),
                        amp,
                        term.amplitude_sigma(),
                        term.effect.amp_name(),
                        t.channel.unit()
                    ),
                    Some(ub) => {
                        println!("    {:<14} not detected (< {:.2e})", term.effect.name(), ub)
                    }
                }
            }
            for r in &a.failing {
                println!(
                    "    misfit for τ {:.3e}…{:.3e} s: a missing effect (try `imu-lab fit`)",
                    r.lo, r.hi
                );
            }
        }
        Err(e) => println!("  fit: {e}"),
    }
}

/// The blob to upload from `path` (`imu_cal::file::upload_blob`: a `.bin` blob or a TOML
/// calibration file, checked before anything is sent).
fn upload_blob(path: &std::path::Path) -> Result<Vec<u8>> {
    let content = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let is_blob = path.extension().is_some_and(|e| e == "bin");
    imu_cal::file::upload_blob(&content, is_blob)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

fn calibrate(link: &mut Link, a: &CalArgs, upload: Option<Vec<u8>>) -> Result<()> {
    if let (Some(path), Some(blob)) = (&a.upload, upload) {
        let persist = !a.no_persist;
        device::upload_calibration(link, &blob, persist)?;
        println!(
            "calibration from {} {} (the Allan state was reset: new corrections, new data)",
            path.display(),
            if persist {
                "applied and written to flash"
            } else {
                "applied (not persisted)"
            }
        );
        return Ok(());
    }
    let (blob, status) = device::calibration(link)?;
    println!("calibration in use: {}", device::format_cal(&status));
    let cal = imu_cal::device::decode_blob(&blob)
        .map_err(|e| anyhow::anyhow!("the device sent an invalid blob: {e}"))?;
    print_cal(&cal);
    if let Some(out) = &a.out {
        std::fs::write(out, &blob).with_context(|| format!("writing {}", out.display()))?;
        println!("blob ({} B) written to {}", blob.len(), out.display());
    }
    Ok(())
}

/// The fixed-point corrections as numbers: out = M·raw − c (− κ·ΔT for the gyro), in nominal
/// LSB, and what they were fitted for.
fn print_cal(cal: &imu_cal::device::Calibration) {
    match cal.fitted_for() {
        None => println!("fitted for: nothing recorded (identity)"),
        Some(f) => println!(
            "fitted for: {} at ±{} g and ±{} deg/s, {} at ±{} G{}",
            f.imu.name(),
            f.ranges.accel_g,
            f.ranges.gyro_dps,
            f.mag.name(),
            imu_cal::device::plausible::Num(f.ranges.mag_gauss()),
            if f.parts_assumed {
                " (parts not recorded in this version-2 blob: taken to be the firmware's)"
            } else {
                ""
            }
        ),
    }
    let show = |name: &str, a: &imu_cal::device::Affine| {
        let m = a.matrix();
        let c = a.folded_offset();
        println!("{name}: out = M·raw − c  [nominal LSB]");
        for i in 0..3 {
            println!(
                "    [{:>10.6} {:>10.6} {:>10.6}]   c = {:>10.3}",
                m[i][0], m[i][1], m[i][2], c[i]
            );
        }
    };
    show("accel", cal.accel());
    show("gyro", cal.gyro().affine());
    let k = cal.gyro().kappa();
    println!(
        "    temperature term κ = [{:.6}, {:.6}, {:.6}] LSB per temperature LSB, T_ref = {} LSB",
        k[0],
        k[1],
        k[2],
        cal.gyro().t_ref()
    );
    show("mag", cal.mag());
}

#[cfg(test)]
mod tests {
    use super::*;
    use imu_proto::CalStatus;

    #[derive(clap::Parser, Debug)]
    struct Cal {
        #[command(flatten)]
        c: CalArgs,
    }

    #[test]
    fn every_documented_calibrate_flag_combination_parses_and_no_other() {
        use clap::Parser;
        let p = |args: &[&str]| {
            Cal::try_parse_from(std::iter::once("calibrate").chain(args.iter().copied()))
        };
        let c = p(&["--upload", "cal.toml", "--no-persist"]).unwrap().c;
        assert!(c.no_persist && c.upload.is_some());
        let c = p(&["--upload", "cal.bin"]).unwrap().c;
        assert!(!c.no_persist);
        let c = p(&["--download", "--out", "cal.bin"]).unwrap().c;
        assert!(c.download && c.out.is_some());
        assert!(p(&["--download"]).unwrap().c.download);
        for bad in [
            &[][..],
            &["--no-persist"][..],
            &["--upload", "a", "--download"][..],
            &["--out", "x.bin"][..],
            &["--upload", "a", "--out", "x.bin"][..],
            &["--download", "--no-persist"][..],
        ] {
            assert!(p(bad).is_err(), "{bad:?} accepted");
        }
    }

    #[test]
    fn status_prints_units_the_missing_temperature_and_the_measured_period() {
        let s = Status {
            uptime_us: 2_500_000,
            samples_taken: 10,
            samples_dropped: 3,
            mag_samples: 2,
            mag_dropped: 1,
            fifo_overflows: 0,
            i2c_errors: 1,
            bus_faults: 0,
            bus_recoveries: 0,
            frames_rejected: 0,
            frames_unsent: 0,
            cpu_load_permille: 37,
            temp_milli_c: None,
            imu: imu_proto::SensorState::Ok,
            mag: imu_proto::SensorState::Stalled,
            imu_period_ns: 1_013_171,
            mag_period_ns: 0,
            cal: CalStatus {
                source: imu_proto::CalSource::Identity,
                fault: Some(imu_proto::CalFault::Rejected(
                    imu_proto::CalProblem::OtherRanges,
                )),
            },
            mode: StreamMode::Off,
        };
        let t = format_status(&s);
        assert!(t.contains("2.500 s"), "{t}");
        assert!(t.contains("3.7 %"), "{t}");
        assert!(t.contains("n/a"), "{t}");
        assert!(t.contains("10 samples taken, 3 lost"), "{t}");
        assert!(t.contains("1013.171 µs (+1.32 % from nominal)"), "{t}");
        assert!(t.contains("Stalled"), "{t}");
        assert!(t.contains("other full-scale ranges"), "{t}");
    }
}
