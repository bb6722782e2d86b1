//! `imu-lab export kalibr`: Kalibr `imu.yaml` noise values from static recordings, with the unit
//! conversions written beside each number.
use std::path::PathBuf;

use allan::{deviation_segments, Stat, TauSet};
use anyhow::{anyhow, bail, Context, Result};
use noise_model::{practical, Effect, NoiseLab, Point, Record};

use crate::input::{self, InputArgs};
use crate::render::sig;

/// Arguments of `imu-lab export`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub target: Target,
}

/// Export formats.
#[derive(clap::Subcommand, Debug)]
pub enum Target {
    /// Kalibr imu.yaml (continuous-time noise densities and random walks, SI units).
    Kalibr(KalibrArgs),
}

/// Arguments of `imu-lab export kalibr`.
#[derive(clap::Args, Debug)]
pub struct KalibrArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// Gyroscope columns (deg/s or rad/s after scaling).
    #[arg(long, value_delimiter = ',', default_value = "gx,gy,gz")]
    pub gyro: Vec<String>,
    /// Accelerometer columns (m/s² after scaling).
    #[arg(long, value_delimiter = ',', default_value = "ax,ay,az")]
    pub accel: Vec<String>,
    /// Scale of the gyro columns to deg/s (overrides --scale for them), e.g. 0.0076336 = 1/131.
    #[arg(long)]
    pub gyro_scale: Option<f64>,
    /// Scale of the accel columns to m/s² (overrides --scale), e.g. 5.9855e-4 = 9.80665/16384.
    #[arg(long)]
    pub accel_scale: Option<f64>,
    /// ROS topic written into the file.
    #[arg(long, default_value = "/imu0")]
    pub rostopic: String,
    /// Output file (default: stdout).
    #[arg(long, short)]
    pub output: Option<PathBuf>,
}

/// N and K of one column (N = white, K = rate random walk; the 2σ upper bound when K is not
/// detected, so Kalibr is never told a drift is smaller than the data allow).
struct Axis {
    name: String,
    unit: String,
    n: f64,
    /// 1σ of `n`.
    n_sigma: f64,
    k: f64,
    /// 1σ of `k` (when detected).
    k_sigma: f64,
    k_is_bound: bool,
    adequate: bool,
}

fn analyse(input: &InputArgs, column: &str) -> Result<Axis> {
    let rec = input::load(input, &[column])?;
    let series = rec
        .column(column)
        .ok_or_else(|| anyhow!("column {column:?} missing"))?;
    let unit = series.unit.clone();
    let y = &series.values;
    let segments = rec.segments_of(column).unwrap_or_default();
    let rows = deviation_segments(&segments, 1.0 / rec.rate_hz, Stat::Oadev, &TauSet::Octave)
        .with_context(|| format!("{}: column {column:?}", input.file.display()))?;
    let (pts, _) = Point::from_rows(&rows);
    let lab = NoiseLab::new(Record {
        y,
        unit: &unit,
        tau0: 1.0 / rec.rate_hz,
        segments: vec![(0, y.len() as u64)],
        temp: None,
        timing: None,
        points: pts,
        user_effects: vec![],
    })
    .map_err(|e| anyhow!("{column}: {e}"))?;
    let m = lab
        .fit(&lab.default_specs())
        .map_err(|e| anyhow!("{column}: {e}"))?;
    let f = &m.fit;
    let (n, n_sigma) = f
        .term(&Effect::White)
        .filter(|t| t.detected)
        .map(|t| (t.amplitude(), t.amplitude_sigma()))
        .ok_or_else(|| anyhow!("{column}: no white noise detected; cannot give a noise density"))?;
    let kt = f.term(&Effect::RateRandomWalk).expect("default terms");
    let (k, k_is_bound) = if kt.detected {
        (kt.amplitude(), false)
    } else {
        (kt.amplitude_interval().1, true)
    };
    Ok(Axis {
        name: column.into(),
        unit,
        n,
        n_sigma,
        k,
        k_sigma: kt.amplitude_sigma(),
        k_is_bound,
        adequate: m.adequate,
    })
}

/// One sensor's conversion of (N, K) in the data's unit to Kalibr's units.
type ToKalibr = fn(f64, f64, &str) -> Result<(f64, f64), String>;

/// The largest noise density and random walk over the axes, each in Kalibr's units by `kalibr`
/// (one sensor has one entry in Kalibr's file, so its noisiest axis stands for it).
fn worst(axes: &[Axis], kalibr: ToKalibr) -> Result<(f64, f64)> {
    let (mut n_max, mut k_max): (f64, f64) = (0.0, 0.0);
    for x in axes {
        let (n, k) = kalibr(x.n, x.k, &x.unit).map_err(|e| anyhow!("{}: {e}", x.name))?;
        n_max = n_max.max(n);
        k_max = k_max.max(k);
    }
    Ok((n_max, k_max))
}

fn group(input: &InputArgs, cols: &[String], scale: Option<f64>, unit: &str) -> Result<Vec<Axis>> {
    let mut args = input.clone();
    if let Some(s) = scale {
        args.scale = Some(s);
        args.unit = Some(unit.into());
    }
    cols.iter().map(|c| analyse(&args, c)).collect()
}

pub fn run(args: Args) -> Result<()> {
    let Target::Kalibr(a) = args.target;
    if a.gyro.is_empty() || a.accel.is_empty() {
        bail!("give at least one --gyro and one --accel column");
    }
    let rate = {
        let rec = input::load(&a.input, &[a.gyro[0].as_str()])?;
        rec.rate_hz
    };
    let gyro = group(&a.input, &a.gyro, a.gyro_scale, "deg/s")?;
    let accel = group(&a.input, &a.accel, a.accel_scale, "m/s²")?;
    let (gn, gk) = worst(&gyro, practical::kalibr_gyro)?;
    let (an, ak) = worst(&accel, practical::kalibr_accel)?;
    let imu = noise_model::KalibrImu {
        gyroscope_noise_density: gn,
        gyroscope_random_walk: gk,
        accelerometer_noise_density: an,
        accelerometer_random_walk: ak,
        update_rate: rate,
    };
    let describe = |v: &[Axis]| {
        v.iter()
            .map(|x| {
                let k = if x.k_is_bound {
                    format!("K < {}", sig(x.k, 3))
                } else {
                    format!("K = {} ± {}", sig(x.k, 3), sig(x.k_sigma, 2))
                };
                format!(
                    "#   {}: N = {} ± {} {u}·√s, {k} {u}/√s{}",
                    x.name,
                    sig(x.n, 4),
                    sig(x.n_sigma, 2),
                    if x.adequate {
                        ""
                    } else {
                        " (five-term model NOT adequate for this axis: see `imu-lab fit`)"
                    },
                    u = x.unit
                )
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let yaml = format!(
        "# Kalibr IMU noise model, written by `imu-lab export kalibr` from {file}\n\
         # Values are the largest over the axes (conservative), from a weighted fit of Jaime et al.'s\n\
         # five Allan terms. Kalibr wants CONTINUOUS-time densities (not per-sample σ):\n\
         #   gyroscope_noise_density [rad/s/√Hz]   = N [deg/s·√s] × π/180   (1/√Hz = √s)\n\
         #   gyroscope_random_walk   [rad/s²/√Hz]  = K [deg/s/√s] × π/180\n\
         #   accelerometer_noise_density [m/s²/√Hz] = N [m/s²·√s]  (same number)\n\
         #   accelerometer_random_walk   [m/s³/√Hz] = K [m/s²/√s]  (same number)\n\
         # The discrete per-sample σ would be density × √update_rate. ± is 1σ; K given as \"<\" is a 2σ upper\n\
         # bound (not detected in this record). Many users inflate these values (×2–10) for\n\
         # unmodelled effects; that choice is left to you.\n\
         # Per axis:\n{g}\n{acc}\n\
         accelerometer_noise_density: {an:.6e}\n\
         accelerometer_random_walk: {ak:.6e}\n\
         gyroscope_noise_density: {gn:.6e}\n\
         gyroscope_random_walk: {gk:.6e}\n\
         rostopic: {topic}\n\
         update_rate: {rate}  # Hz\n",
        file = a.input.file.display(),
        g = describe(&gyro),
        acc = describe(&accel),
        an = imu.accelerometer_noise_density,
        ak = imu.accelerometer_random_walk,
        gn = imu.gyroscope_noise_density,
        gk = imu.gyroscope_random_walk,
        topic = a.rostopic,
        // The rate read from the stamps to 9 significant digits (not 100.0000000000199).
        rate = sig(imu.update_rate, 9),
    );
    match &a.output {
        Some(p) => std::fs::write(p, yaml).with_context(|| format!("writing {}", p.display()))?,
        None => print!("{yaml}"),
    }
    Ok(())
}
