//! `imu-lab simulate`: write simulated rate data in the CSV contract (`t` in s, then the chosen
//! columns in their contract units), with the exact theoretical Allan curve on request.
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};
use imu_proto::csv::{self as contract, unit as contract_unit};
use imu_sim::{SimConfig, SimEffect};
use serde::Serialize;

/// Arguments of `imu-lab simulate`. Parameters are in the canonical units of the noise model,
/// with u the columns' contract unit (deg/s for gx gy gz, m/s² for ax ay az).
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Sample rate [Hz].
    #[arg(long, default_value_t = 100.0)]
    pub rate: f64,
    /// Number of samples per column.
    #[arg(long, default_value_t = 1 << 18)]
    pub samples: usize,
    /// Random-number stream: the same number gives the same data (column k uses this + k).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Columns to generate, comma-separated contract names.
    #[arg(long, value_delimiter = ',', default_value = "gz")]
    pub columns: Vec<String>,
    /// Quantization Q [u·s].
    #[arg(long)]
    pub quantization: Option<f64>,
    /// White noise N [u·√s].
    #[arg(long)]
    pub white: Option<f64>,
    /// Flicker (bias instability) B [u].
    #[arg(long)]
    pub flicker: Option<f64>,
    /// Rate random walk K [u/√s].
    #[arg(long)]
    pub rrw: Option<f64>,
    /// Rate ramp R [u/s].
    #[arg(long)]
    pub ramp: Option<f64>,
    /// Gauss–Markov noise: SIGMA,TAU_C (u, s).
    #[arg(long, value_delimiter = ',')]
    pub markov: Vec<f64>,
    /// Sinusoid: AMPLITUDE,FREQ_HZ (u peak, Hz).
    #[arg(long, value_delimiter = ',')]
    pub sinusoid: Vec<f64>,
    /// A resonance (white noise driving a damped oscillator, a mount or structural mode):
    /// SIGMA,F0,ZETA (u standard deviation, Hz natural frequency, damping ratio 0 < ζ < 1).
    #[arg(long, value_delimiter = ',')]
    pub resonance: Vec<f64>,
    /// Pass the white noise through a low-pass filter with this corner [Hz] (the MPU-6050 DLPF;
    /// Jaime et al. configured 5 Hz).
    #[arg(long)]
    pub dlpf: Option<f64>,
    /// Order of that filter: 1 (one pole) or 2 (two cascaded poles).
    #[arg(long, default_value_t = 1)]
    pub dlpf_order: u8,
    /// Pass the white noise through a decimation filter of this many output samples (boxcar; a
    /// Bartlett filter with --bartlett) instead.
    #[arg(long)]
    pub decimation: Option<usize>,
    /// Make --decimation a Bartlett (two boxcars in cascade).
    #[arg(long, requires = "decimation")]
    pub bartlett: bool,
    /// A bias step: TIME_S,SIZE (s, u). Repeatable.
    #[arg(long, value_delimiter = ',')]
    pub step: Vec<f64>,
    /// A warm-up transient A·e^(−t/τ): AMPLITUDE,TAU_S (u, s).
    #[arg(long = "warm-up", value_delimiter = ',')]
    pub warm_up: Vec<f64>,
    /// A smooth drift of the bias (a logistic transition and a quadratic bow of a shape drawn
    /// from SHAPE_SEED): RMS[,SHAPE_SEED] (u about its mean over the record; default shape 1)
    #[arg(long = "drift", value_delimiter = ',')]
    pub drift: Vec<f64>,
    /// A bias following a warming temperature, written as a `temp` column:
    /// COEF,START_C,RISE_C,TAU_S (u/°C, °C, °C, s).
    #[arg(long, value_delimiter = ',')]
    pub temperature: Vec<f64>,
    /// Round every sample to this LSB (the part's resolution) [u].
    #[arg(long)]
    pub lsb: Option<f64>,
    /// Instead of noise: the board turned through a known trajectory (`standard`: 32 s: still,
    /// level turn, tilts to 60°, a tumble through the sphere; `imu_sim::trajectory`), every
    /// column of the contract at --rate for --samples rows (the trajectory repeated), plus the
    /// truth columns roll_true, pitch_true, heading_true (degrees, heading magnetic), for the
    /// emulator (`sim/src/cli.js run --stream`) and `imu-lab heading --truth`.
    /// `calibration` (80.5 s): eight poses held 5 s (every face of the accelerometer, two
    /// tilted) around the standard run's turns, for `imu-lab serve`'s calibration wizard.
    #[arg(long, value_parser = ["standard", "calibration"])]
    pub trajectory: Option<String>,
    /// With --trajectory: the accelerometer's offset, m/s² per axis (X,Y,Z), as the
    /// calibration's correction `s·(a − o)` names it.
    #[arg(long, requires = "trajectory", value_delimiter = ',')]
    pub accel_offset: Vec<f64>,
    /// With --trajectory: the accelerometer's scale per axis (X,Y,Z; 1 = exact): the part reads
    /// `f/s + o` for a specific force f.
    #[arg(long, requires = "trajectory", value_delimiter = ',')]
    pub accel_scale: Vec<f64>,
    /// With --trajectory: the part reading it — `ideal`, or `hard-iron` (25 µT of hard iron,
    /// soft iron, gyro bias 0.5 deg/s, the sensors' noise).
    #[arg(long, requires = "trajectory", value_parser = ["ideal", "hard-iron"], default_value = "hard-iron")]
    pub part: String,
    /// Output CSV (default: stdout).
    #[arg(long, short)]
    pub output: Option<PathBuf>,
    /// Also write the exact theoretical Allan deviation at octave τ as JSON to this file.
    #[arg(long)]
    pub theory: Option<PathBuf>,
}

#[derive(Serialize)]
struct TheoryPoint {
    tau_s: f64,
    m: usize,
    dev: f64,
}

#[derive(Serialize)]
struct Theory<'a> {
    unit: &'a str,
    rate_hz: f64,
    samples: usize,
    effects: Vec<String>,
    adev: Vec<TheoryPoint>,
}

fn positive(v: Option<f64>, flag: &str) -> Result<Option<f64>> {
    match v {
        Some(x) if !(x >= 0.0 && x.is_finite()) => bail!("--{flag} {x}: must be ≥ 0"),
        other => Ok(other),
    }
}

/// `--trajectory`: the stream of a board turned through a known trajectory, with its truth.
fn trajectory(args: &Args) -> Result<()> {
    use imu_sim::trajectory::{write_stream, Part, Trajectory};
    let traj = if args.trajectory.as_deref() == Some("calibration") {
        Trajectory::calibration()
    } else {
        Trajectory::standard()
    };
    let mut part = if args.part == "ideal" {
        Part::ideal()
    } else {
        Part::hard_iron()
    };
    for (v, flag, lo, hi) in [
        (&args.accel_offset, "--accel-offset", -5.0, 5.0),
        (&args.accel_scale, "--accel-scale", 0.5, 2.0),
    ] {
        if !v.is_empty() && v.len() != 3 {
            bail!("{flag}: give three comma-separated numbers (X,Y,Z), got {v:?}");
        }
        if let Some(x) = v.iter().find(|x| !(lo..=hi).contains(*x)) {
            bail!("{flag} {x}: each axis must be between {lo} and {hi}");
        }
    }
    if let [x, y, z] = args.accel_offset[..] {
        part.accel_offset = [x, y, z];
    }
    if let [x, y, z] = args.accel_scale[..] {
        part.accel_scale = [x, y, z];
    }
    if args.rate > 1e6 {
        bail!(
            "--rate {} Hz with --trajectory: the stream's stamps are whole µs, so at most 1e6 Hz",
            args.rate
        );
    }
    let seconds = args.samples as f64 / args.rate;
    let result = match &args.output {
        Some(p) => {
            let f = std::fs::File::create(p)
                .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", p.display()))?;
            write_stream(
                std::io::BufWriter::new(f),
                &traj,
                &part,
                args.rate,
                seconds,
                args.seed,
            )
        }
        None => write_stream(
            std::io::stdout().lock(),
            &traj,
            &part,
            args.rate,
            seconds,
            args.seed,
        ),
    };
    result.map_err(|e| anyhow::anyhow!("writing the stream: {e}"))
}

/// The samples as a recording in the contract: `t = i/rate`, then the columns.
fn write_rows<W: Write>(w: W, rate: f64, names: &[String], data: &[Vec<f64>]) -> Result<()> {
    let mut cols: Vec<&str> = vec![contract::TIME];
    cols.extend(names.iter().map(String::as_str));
    let mut out = contract::Writer::new(w, &cols, contract::WriteOptions::default())?;
    let n = data.iter().map(Vec::len).min().unwrap_or(0);
    let mut row = vec![None; cols.len()];
    for i in 0..n {
        row[0] = Some(i as f64 / rate);
        for (k, d) in data.iter().enumerate() {
            row[k + 1] = Some(d[i]);
        }
        out.row(&row)?;
    }
    out.finish()?;
    Ok(())
}

/// Most samples per column: every column is generated in memory (8 bytes a sample, and the
/// generators' own buffers) before it is written; 2²⁸ is 3.1 days at 1 kHz, 2 GiB a column.
const MAX_SAMPLES: usize = 1 << 28;

pub fn run(args: Args) -> Result<()> {
    crate::input::check_rate(args.rate, "--rate")?;
    if args.samples < 3 {
        bail!("--samples {}: at least 3 needed", args.samples);
    }
    if args.samples > MAX_SAMPLES {
        bail!(
            "--samples {}: at most {MAX_SAMPLES} ({} s at --rate {} Hz); each column is built in \
             memory, 8 bytes a sample: simulate a longer record in parts (--seed)",
            args.samples,
            MAX_SAMPLES as f64 / args.rate,
            args.rate
        );
    }
    if args.trajectory.is_some() {
        return trajectory(&args);
    }
    let mut effects = Vec::new();
    if let Some(q) = positive(args.quantization, "quantization")? {
        effects.push(SimEffect::Quantization { q });
    }
    if let Some(n) = positive(args.white, "white")? {
        match positive(args.dlpf, "dlpf")? {
            Some(fc) => {
                if !(fc > 0.0 && fc < args.rate / 2.0) {
                    bail!("--dlpf {fc}: the corner must be in (0, rate/2)");
                }
                if !(1..=2).contains(&args.dlpf_order) {
                    bail!("--dlpf-order {}: 1 or 2", args.dlpf_order);
                }
                effects.push(SimEffect::LowPassWhite {
                    n,
                    cutoff_hz: fc,
                    order: args.dlpf_order,
                })
            }
            None => match args.decimation {
                Some(length) if (1..=4096).contains(&length) => {
                    effects.push(SimEffect::Decimated {
                        n,
                        length,
                        bartlett: args.bartlett,
                    })
                }
                Some(length) => bail!("--decimation {length}: give 1 to 4096 samples"),
                None => effects.push(SimEffect::White { n }),
            },
        }
    } else if args.dlpf.is_some() || args.decimation.is_some() {
        bail!("--dlpf and --decimation filter the white noise: give --white too");
    }
    if args.dlpf.is_some() && args.decimation.is_some() {
        bail!("--dlpf and --decimation: give one filter");
    }
    if let Some(b) = positive(args.flicker, "flicker")? {
        effects.push(SimEffect::Flicker { b });
    }
    if let Some(k) = positive(args.rrw, "rrw")? {
        effects.push(SimEffect::RateRandomWalk { k });
    }
    if let Some(r) = args.ramp {
        if !r.is_finite() {
            bail!("--ramp {r}: not a number");
        }
        effects.push(SimEffect::RateRamp { r });
    }
    for (v, flag) in [(&args.markov, "markov"), (&args.sinusoid, "sinusoid")] {
        if !v.is_empty() && v.len() != 2 {
            bail!("--{flag}: expected two comma-separated numbers, got {v:?}");
        }
    }
    if let [sigma, tau_c] = args.markov[..] {
        if !(sigma >= 0.0 && tau_c > 0.0) {
            bail!("--markov {sigma},{tau_c}: need sigma ≥ 0 and tau_c > 0");
        }
        effects.push(SimEffect::Markov { sigma, tau_c });
    }
    if let [amplitude, freq_hz] = args.sinusoid[..] {
        if !(amplitude >= 0.0 && freq_hz > 0.0 && freq_hz < args.rate / 2.0) {
            bail!("--sinusoid {amplitude},{freq_hz}: need amplitude ≥ 0 and 0 < f < rate/2");
        }
        effects.push(SimEffect::Sinusoid { amplitude, freq_hz });
    }
    match args.resonance[..] {
        [] => {}
        [sigma, f0_hz, zeta]
            if sigma >= 0.0
                && sigma.is_finite()
                && f0_hz > 0.0
                && f0_hz < args.rate / 2.0
                && zeta > 0.0
                && zeta < 1.0 =>
        {
            effects.push(SimEffect::Resonance { sigma, f0_hz, zeta })
        }
        _ => bail!(
            "--resonance: expected SIGMA,F0,ZETA with sigma ≥ 0, 0 < f0 < rate/2 and 0 < ζ < 1 \
             (ζ ≥ 1 has no resonant peak), got {:?}",
            args.resonance
        ),
    }
    if !args.step.len().is_multiple_of(2) {
        bail!("--step: expected TIME_S,SIZE pairs, got {:?}", args.step);
    }
    let duration = args.samples as f64 / args.rate;
    for p in args.step.chunks(2) {
        let (at_s, size) = (p[0], p[1]);
        if !(at_s > 0.0 && at_s < duration && size.is_finite()) {
            bail!("--step {at_s},{size}: the instant must lie inside the record (0–{duration} s)");
        }
        effects.push(SimEffect::BiasStep { at_s, size });
    }
    match args.warm_up[..] {
        [] => {}
        [amplitude, tau_s] if amplitude.is_finite() && tau_s > 0.0 && tau_s.is_finite() => {
            effects.push(SimEffect::WarmUp { amplitude, tau_s })
        }
        _ => bail!(
            "--warm-up: expected AMPLITUDE,TAU_S with τ > 0, got {:?}",
            args.warm_up
        ),
    }
    match args.drift[..] {
        [] => {}
        [rms] if rms.is_finite() && rms >= 0.0 => {
            effects.push(SimEffect::Drift { rms, shape_seed: 1 })
        }
        [rms, seed]
            if rms.is_finite()
                && rms >= 0.0
                && seed >= 0.0
                && seed.fract() == 0.0
                && seed < 9.0e15 =>
        {
            effects.push(SimEffect::Drift {
                rms,
                shape_seed: seed as u64,
            })
        }
        _ => bail!(
            "--drift: expected RMS[,SHAPE_SEED] with rms ≥ 0 and a whole shape seed ≥ 0, got {:?}",
            args.drift
        ),
    }
    match args.temperature[..] {
        [] => {}
        [coef, start_c, rise_c, tau_s]
            if [coef, start_c, rise_c].iter().all(|v| v.is_finite())
                && tau_s > 0.0
                && tau_s.is_finite() =>
        {
            effects.push(SimEffect::Temperature {
                coef,
                start_c,
                rise_c,
                tau_s,
            })
        }
        _ => bail!(
            "--temperature: expected COEF,START_C,RISE_C,TAU_S with τ > 0, got {:?}",
            args.temperature
        ),
    }
    if let Some(q) = args.lsb {
        if !(q > 0.0 && q.is_finite()) {
            bail!("--lsb {q}: must be a positive number in the columns' unit");
        }
    }
    if effects.is_empty() {
        bail!("no effect given: use --white, --flicker, --rrw, --ramp, --quantization, --markov, --sinusoid or --resonance");
    }
    let mut units = Vec::new();
    for c in &args.columns {
        let u = contract_unit(c)
            .filter(|_| c != "t")
            .ok_or_else(|| anyhow!("--columns {c:?}: not a contract data column"))?;
        units.push(u);
    }
    // The theory's file is created before the samples are made, so that a path that cannot be
    // written fails before the record is written.
    let theory_file = match &args.theory {
        Some(p) => Some(File::create(p).with_context(|| format!("creating {}", p.display()))?),
        None => None,
    };
    let mut data = Vec::new();
    let mut cfg0 = None;
    let mut temp = None;
    for (i, _) in args.columns.iter().enumerate() {
        let cfg = SimConfig {
            rate_hz: args.rate,
            n_samples: args.samples,
            seed: args.seed.wrapping_add(i as u64),
            effects: effects.clone(),
            lsb: args.lsb,
        };
        let (y, t) = cfg.generate_with_temp();
        data.push(y);
        temp = temp.or(t);
        cfg0.get_or_insert(cfg);
    }
    let mut names = args.columns.clone();
    if let Some(t) = temp {
        names.push("temp".into());
        data.push(t);
    }
    match &args.output {
        Some(p) => {
            let f = File::create(p).with_context(|| format!("creating {}", p.display()))?;
            write_rows(BufWriter::new(f), args.rate, &names, &data)
                .with_context(|| format!("writing {}", p.display()))?;
        }
        None => {
            let out = std::io::stdout();
            write_rows(BufWriter::new(out.lock()), args.rate, &names, &data)
                .context("writing stdout")?;
        }
    }
    if let (Some(p), Some(mut f), Some(cfg)) = (&args.theory, theory_file, cfg0) {
        let mut ms = Vec::new();
        let mut m = 1usize;
        while 2 * m <= args.samples / 2 {
            ms.push(m);
            m *= 2;
        }
        let th = Theory {
            unit: units[0],
            rate_hz: args.rate,
            samples: args.samples,
            effects: effects.iter().map(|e| format!("{e:?}")).collect(),
            adev: ms
                .iter()
                .map(|&m| TheoryPoint {
                    tau_s: m as f64 / args.rate,
                    m,
                    dev: cfg.avar(m).sqrt(),
                })
                .collect(),
        };
        writeln!(f, "{}", serde_json::to_string_pretty(&th)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The contract writer gives byte for byte what the simulator's own writer gives (the
    /// emulator harness reads these files), and the reader reads it back exactly.
    #[test]
    fn rows_are_the_simulators_bytes_and_read_back() {
        let cfg = SimConfig {
            rate_hz: 1000.0,
            n_samples: 500,
            seed: 3,
            effects: vec![SimEffect::White { n: 0.01 }],
            lsb: None,
        };
        let data = vec![cfg.generate(), cfg.generate()];
        let names = vec!["gx".to_string(), "gy".to_string()];
        let mut ours = Vec::new();
        write_rows(&mut ours, 1000.0, &names, &data).unwrap();
        let mut theirs = Vec::new();
        imu_sim::write_csv(&mut theirs, 1000.0, &[("gx", &data[0]), ("gy", &data[1])]).unwrap();
        assert_eq!(
            String::from_utf8(ours.clone()).unwrap(),
            String::from_utf8(theirs).unwrap()
        );
        let mut r = contract::Reader::new(ours.as_slice(), "sim", &Default::default()).unwrap();
        let got = r.select(&["gx", "gy"], &[]).unwrap();
        assert_eq!(got, ["gx", "gy", "t"]);
        let mut row = [0.0; 3];
        for (i, (x, y)) in data[0].iter().zip(&data[1]).enumerate() {
            assert!(r.next_row(&mut row).unwrap());
            assert_eq!(row, [*x, *y, i as f64 / 1000.0]);
        }
        assert!(!r.next_row(&mut row).unwrap());
    }
}
