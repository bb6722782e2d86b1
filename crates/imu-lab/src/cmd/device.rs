//! `imu-lab device …`: talk to the firmware (a Pico over USB CDC, or the emulator over TCP).
//!
//! * `status` — identity and counters;
//! * `tables [--fit] [--json F]` — the device's streaming Allan tables, each row checked against
//!   its own integer sums; `--fit` runs the noise-model lab on each channel;
//! * `calibrate --upload cal.toml|cal.bin` / `--download [--out cal.bin]` — the calibration in
//!   flash (`imu_cal::file` TOML → fixed-point blob);
//! * `orientation [--declination DEG] [--field-ut B --dip-deg D | --learn]` — the attitude
//!   filter's declination and expected field (RAM only on the device: lost at a reset);
//! * `reset-allan`, `mode off|calibrated|raw`.
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use imu_proto::{AllanTable, CalStatus, Channel, DeviceMsg, Reply, Request, Status, StreamMode};

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
            link.request_ok(Request::ResetAllan)?;
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
            link.request_ok(Request::SetMode(m))?;
            println!("streaming mode: {mode}");
            Ok(())
        }
    }
}

fn orientation(link: &mut Link, a: &OrientationArgs) -> Result<()> {
    let get = |link: &mut Link| match link.request(Request::GetOrientation)? {
        Reply::Orientation(c) => Ok(c),
        other => bail!("unexpected reply to GetOrientation: {other:?}"),
    };
    let mut cfg = get(link)?;
    if a.declination.is_some() || a.field_ut.is_some() || a.learn {
        let decl = a
            .declination
            .unwrap_or(f64::from(cfg.declination_cdeg) * 0.01);
        if !(-180.0..=180.0).contains(&decl) {
            bail!("--declination {decl}: degrees within ±180");
        }
        let reference = match (a.field_ut, a.dip_deg) {
            (Some(b), Some(d)) => {
                if !(1.0..=1000.0).contains(&b) {
                    bail!("--field-ut {b}: µT within 1 to 1000");
                }
                if !(-90.0..=90.0).contains(&d) {
                    bail!("--dip-deg {d}: degrees within ±90");
                }
                Some(imu_proto::MagReference {
                    field_nt: (b * 1000.0).round() as u32,
                    dip_cdeg: (d * 100.0).round() as i16,
                })
            }
            _ if a.learn => None,
            _ if cfg.learnt => None,
            _ => cfg.reference,
        };
        match link.request(Request::SetOrientation {
            declination_cdeg: (decl * 100.0).round() as i16,
            reference,
        })? {
            Reply::Ok => {}
            other => bail!("the device refused the orientation settings: {other:?}"),
        }
        cfg = get(link)?;
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
    if let Reply::Identity(id) = link.request(Request::Identify)? {
        println!(
            "device: {} on {}, protocol {}, IMU {} Hz, magnetometer {} Hz, Allan engines P = {}, {} octave levels ({} for the magnetometer)",
            id.firmware, id.board, id.protocol, id.imu_rate_hz, id.mag_rate_hz, id.allan_overlap, id.allan_levels, id.allan_levels_mag
        );
    }
    match link.request(Request::GetStatus)? {
        Reply::Status(s) => {
            print!("{}", format_status(&s));
            Ok(())
        }
        other => bail!("unexpected reply to GetStatus: {other:?}"),
    }
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
        format_cal(&s.cal),
        s.mode
    )
}

fn format_cal(c: &CalStatus) -> String {
    let src = match c.source {
        imu_proto::CalSource::Identity => "identity (none stored)",
        imu_proto::CalSource::Flash => "from flash",
        imu_proto::CalSource::Host => "set by the host, not persisted",
    };
    match c.fault {
        None => src.to_string(),
        Some(imu_proto::CalFault::Flash) => {
            format!("{src}; the flash could not be read or written")
        }
        Some(imu_proto::CalFault::Rejected(p)) => {
            format!("{src}; stored record refused: {}", cal_problem(&p))
        }
    }
}

/// Why the device refused a calibration, in words: an implausible parameter in the calibration
/// file's words (`imu_cal::device::Refusal`), key, index, value and bound.
pub fn cal_problem(p: &imu_proto::CalProblem) -> String {
    use imu_proto::CalProblem;
    match *p {
        CalProblem::Corrupt => {
            "not a valid calibration blob (length, magic, CRC or payload)".into()
        }
        CalProblem::Version(v) => format!("blob format version {v}, not one the firmware reads"),
        CalProblem::OutOfRange => "a coefficient outside the fixed-point range".into(),
        CalProblem::Implausible {
            key,
            axis,
            value,
            lo,
            hi,
        } => match imu_cal::device::Key::from_u8(key) {
            Some(key) => imu_cal::device::Refusal {
                key,
                axis,
                value: value.into(),
                lo: lo.into(),
                hi: hi.into(),
            }
            .to_string(),
            None => format!(
                "parameter {key} (unknown to this host) index {axis:?} = {value} is outside {lo}–{hi}"
            ),
        },
        CalProblem::OtherRanges => "fitted for other full-scale ranges than the firmware's".into(),
        CalProblem::OtherPart => {
            "fitted for other sensor parts than the firmware's, or recording none".into()
        }
    }
}

/// Collect one table per wanted channel after a `GetTables` request: all from the round that
/// answers it (one snapshot of the device, `Reply::Tables`); tables of another round are not
/// mixed in.
pub fn fetch_tables(
    link: &mut Link,
    wanted: &[Channel],
    timeout: Duration,
) -> Result<BTreeMap<usize, AllanTable>> {
    let mut got = BTreeMap::new();
    let mut early = Vec::new();
    let round = match link.request_with(Request::GetTables, crate::link::REPLY_TIMEOUT, |m| {
        if let DeviceMsg::Table(t) = m {
            early.push(t);
        }
    })? {
        Reply::Tables { snapshot } => snapshot,
        other => bail!("unexpected reply to GetTables: {other:?}"),
    };
    let keep = |t: AllanTable, got: &mut BTreeMap<usize, AllanTable>| {
        if t.snapshot == round {
            got.insert(t.channel.index(), t);
        }
    };
    for t in early {
        keep(t, &mut got);
    }
    let until = Instant::now() + timeout;
    while wanted.iter().any(|c| !got.contains_key(&c.index())) {
        let left = until.saturating_duration_since(Instant::now());
        match link.recv(left)? {
            Some(DeviceMsg::Table(t)) => keep(t, &mut got),
            Some(_) => {}
            None => {
                let missing: Vec<&str> = wanted
                    .iter()
                    .filter(|c| !got.contains_key(&c.index()))
                    .map(|c| c.name())
                    .collect();
                bail!(
                    "tables for {} of round {round} did not arrive within {:.0} s",
                    missing.join(", "),
                    timeout.as_secs_f64()
                );
            }
        }
    }
    got.retain(|k, _| wanted.iter().any(|c| c.index() == *k));
    Ok(got)
}

/// One row of a table as the host derives it from the device's sums.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    /// τ = m·τ0, s (τ0 the sensor's measured period).
    pub tau: f64,
    /// Overlapping ADEV, contract unit: `σ² = Σ D2² / (2 n m²)` × scale² (NIST SP 1065 eq. 11).
    pub dev: f64,
    /// Equivalent degrees of freedom (`allan::ci`).
    pub edf: f64,
    /// 68.3 % bounds of `dev` (`allan::ci::chi2_bounds`).
    pub lo: f64,
    pub hi: f64,
}

/// The rows of a table from its sums: deviation, Greenhall's EDF for the level's estimator
/// (stride `s`, `m/s` differences per cluster; Greenhall & Riley 2003) with the noise exponent
/// from the local slope of the Allan variance (`allan::ci::alpha_from_slope`), and exact χ²
/// bounds (NIST SP 1065 eq. 45). Where Greenhall's algorithm is undefined, the simple EDF of
/// NIST SP 1065 Table 5 for white FM (`allan::ci::edf_simple`).
pub fn rows(t: &AllanTable) -> Vec<Row> {
    use allan::ci;
    let tau0 = f64::from(t.tau0_ns) * 1e-9;
    let devs: Vec<f64> = t
        .levels
        .iter()
        .map(|l| l.oadev(f64::from(t.scale)).unwrap_or(0.0))
        .collect();
    let n = t.levels.len();
    (0..n)
        .map(|k| {
            let l = &t.levels[k];
            let (a, b) = if k + 1 < n {
                (k, k + 1)
            } else {
                (k.saturating_sub(1), k)
            };
            let alpha = if a == b {
                0
            } else {
                ci::alpha_from_slope(devs[a] * devs[a], devs[b] * devs[b], 2.0, 2)
            };
            let sums = *l;
            let s_factor = f64::from(l.m) / f64::from(l.stride.max(1));
            let edf = ci::edf_greenhall(
                alpha,
                f64::from(l.m),
                sums.phase_points(),
                ci::Variance::Unmodified { d: 2, s_factor },
            )
            .filter(|e| e.is_finite() && *e > 0.0)
            .unwrap_or_else(|| ci::edf_simple(0, f64::from(l.m), sums.phase_points()).max(1.0));
            let (lo, hi) = ci::chi2_bounds(devs[k], edf, ci::ONE_SIGMA);
            Row {
                tau: f64::from(l.m) * tau0,
                dev: devs[k],
                edf,
                lo,
                hi,
            }
        })
        .collect()
}

fn parse_channels(names: &[String]) -> Result<Vec<Channel>> {
    if names.is_empty() {
        return Ok(Channel::ALL.to_vec());
    }
    names
        .iter()
        .map(|n| {
            Channel::ALL
                .into_iter()
                .find(|c| c.name() == n.trim())
                .with_context(|| format!("unknown channel `{n}` (ax ay az gx gy gz mx my mz temp)"))
        })
        .collect()
}

fn tables(link: &mut Link, a: &TablesArgs) -> Result<()> {
    let wanted = parse_channels(&a.channel)?;
    if !(a.timeout > 0.0 && a.timeout.is_finite()) {
        bail!("--timeout must be positive seconds");
    }
    let got = fetch_tables(link, &wanted, Duration::from_secs_f64(a.timeout))?;
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
        let rows = rows(t);
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
    println!("\ndeviation, EDF and bounds computed on the host from the device's integer sums (allan::ci)");
    if let Some(p) = &a.json {
        let v: Vec<&AllanTable> = got.values().collect();
        std::fs::write(p, serde_json::to_string_pretty(&v)?)
            .with_context(|| format!("writing {}", p.display()))?;
        println!("tables written to {}", p.display());
    }
    Ok(())
}

/// The noise-model fit of one device table (default five terms), with the host's bounds.
fn fit_table(t: &AllanTable, rows: &[Row]) {
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

/// The blob to upload from `path`: a `.bin` blob, decoded and checked as the device will, or a
/// TOML calibration file converted and checked (`CalFile::to_device`: the datasheet bounds
/// on the file's own numbers, named by key, index, value and bound).
fn upload_blob(path: &std::path::Path) -> Result<imu_proto::Vec<u8, { imu_proto::MAX_CAL_BLOB }>> {
    let blob = if path.extension().is_some_and(|e| e == "bin") {
        let b = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        imu_cal::device::decode_blob(&b)
            .map_err(|e| anyhow::anyhow!("{}: refused, nothing uploaded: {e}", path.display()))?;
        b
    } else {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let file = imu_cal::file::CalFile::from_toml(&text)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        let cal = file
            .to_device()
            .map_err(|e| anyhow::anyhow!("{}: refused, nothing uploaded: {e}", path.display()))?;
        let mut buf = [0u8; imu_cal::device::MAX_BLOB_LEN];
        imu_cal::device::encode_blob(&cal, &mut buf)
            .map_err(|e| anyhow::anyhow!("encoding the blob: {e}"))?
            .to_vec()
    };
    imu_proto::Vec::from_slice(&blob).map_err(|_| {
        anyhow::anyhow!(
            "calibration blob of {} B exceeds {} B",
            blob.len(),
            imu_proto::MAX_CAL_BLOB
        )
    })
}

fn calibrate(
    link: &mut Link,
    a: &CalArgs,
    upload: Option<imu_proto::Vec<u8, { imu_proto::MAX_CAL_BLOB }>>,
) -> Result<()> {
    if let (Some(path), Some(blob)) = (&a.upload, upload) {
        let persist = !a.no_persist;
        // A flash write pauses sampling and can take a few hundred ms (sector erase).
        match link.request_with(
            Request::SetCalibration { blob, persist },
            Duration::from_secs(10),
            |_| {},
        )? {
            Reply::Ok => println!(
                "calibration from {} {} (the Allan state was reset: new corrections, new data)",
                path.display(),
                if persist {
                    "applied and written to flash"
                } else {
                    "applied (not persisted)"
                }
            ),
            Reply::Error(imu_proto::ErrorCode::BadCalibration(p)) => {
                bail!("the device refused the calibration: {}", cal_problem(&p))
            }
            Reply::Error(e) => bail!("the device refused the calibration: {e:?}"),
            other => bail!("unexpected reply: {other:?}"),
        }
        return Ok(());
    }
    match link.request(Request::GetCalibration)? {
        Reply::Calibration { blob, status } => {
            println!("calibration in use: {}", format_cal(&status));
            let cal = imu_cal::device::decode_blob(&blob)
                .map_err(|e| anyhow::anyhow!("the device sent an invalid blob: {e}"))?;
            print_cal(&cal);
            if let Some(out) = &a.out {
                std::fs::write(out, &blob).with_context(|| format!("writing {}", out.display()))?;
                println!("blob ({} B) written to {}", blob.len(), out.display());
            }
            Ok(())
        }
        Reply::Error(e) => bail!("the device could not report its calibration: {e:?}"),
        other => bail!("unexpected reply: {other:?}"),
    }
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
            f.ranges.mag_gauss,
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
    use imu_proto::AllanLevel;

    #[derive(clap::Parser, Debug)]
    struct Cal {
        #[command(flatten)]
        c: CalArgs,
    }

    /// The device's refusal (four numbers on the wire) reads as the host's own refusal of the
    /// file; a key this host does not know is still shown with its numbers.
    #[test]
    fn a_device_refusal_reads_in_the_files_words() {
        let p = imu_proto::CalProblem::Implausible {
            key: imu_cal::device::Key::AccelScale as u8,
            axis: Some(0),
            value: 1.9,
            lo: 0.91,
            hi: 1.09,
        };
        assert_eq!(cal_problem(&p), "accel.scale[0] = 1.9 is outside 0.91–1.09");
        let p = imu_proto::CalProblem::Implausible {
            key: imu_cal::device::Key::MagSoftIronCondition as u8,
            axis: None,
            value: f32::INFINITY,
            lo: 1.0,
            hi: 3.0,
        };
        assert_eq!(
            cal_problem(&p),
            "mag.soft_iron condition number = ∞ is outside 1–3"
        );
        let p = imu_proto::CalProblem::Implausible {
            key: 200,
            axis: Some(1),
            value: 5.0,
            lo: -1.0,
            hi: 1.0,
        };
        let s = cal_problem(&p);
        assert!(
            s.contains("200") && s.contains('5') && s.contains("unknown"),
            "{s}"
        );
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

    /// A white-FM table (σ ∝ τ^−½, 60000 samples, strided above m = 8) built from its sums.
    fn white_fm_table() -> AllanTable {
        let mut levels = imu_proto::Vec::new();
        for k in 0..10u32 {
            let m = 1u32 << k;
            let stride = if m <= 8 { 1 } else { m / 8 };
            let dev = 0.1 / f64::from(m).sqrt();
            let n2 = (60_000 - 2 * u64::from(m)) / u64::from(stride);
            let sum2 = (dev / 0.01).powi(2) * 2.0 * n2 as f64 * f64::from(m).powi(2);
            levels
                .push(AllanLevel {
                    m,
                    stride,
                    n2,
                    sum2: sum2 as u128,
                    n3: 0,
                    sum3: 0,
                })
                .unwrap();
        }
        AllanTable {
            channel: Channel::Gz,
            snapshot: 1,
            t_us: 60_000_000,
            tau0_ns: 1_013_171,
            scale: 0.01,
            pushed: 60_000,
            gaps: 0,
            levels,
        }
    }

    #[test]
    fn rows_come_from_the_sums_and_follow_greenhall() {
        // The slope gives alpha = 0, so every EDF must equal allan::ci's Greenhall value for
        // alpha 0 exactly, and the bounds must bracket the deviation.
        let t = white_fm_table();
        let rows = rows(&t);
        for (l, r) in t.levels.iter().zip(&rows) {
            // The deviation is the sums' (to the f64 rounding of the sums built above).
            let want = 0.1 / f64::from(l.m).sqrt();
            assert!((r.dev - want).abs() < 1e-6 * want, "m = {}: {}", l.m, r.dev);
            // τ from the measured period, not the nominal 1 ms.
            assert!((r.tau - f64::from(l.m) * 1.013171e-3).abs() < 1e-12);
            assert!(r.lo < r.dev && r.dev < r.hi, "m = {}", l.m);
            let sums = *l;
            let g = allan::ci::edf_greenhall(
                0,
                f64::from(l.m),
                sums.phase_points(),
                allan::ci::Variance::Unmodified {
                    d: 2,
                    s_factor: f64::from(l.m) / f64::from(l.stride),
                },
            )
            .unwrap();
            assert!(
                (r.edf - g).abs() <= 1e-9 * g,
                "m = {}: {} vs {g}",
                l.m,
                r.edf
            );
        }
        // More clusters, tighter bounds: the relative width grows with τ.
        let w = |i: usize| (rows[i].hi - rows[i].lo) / rows[i].dev;
        assert!(w(0) < w(5) && w(5) < w(9));
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
