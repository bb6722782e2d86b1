//! What a calibration run works on and what it produced, shared by the `calibrate` command
//! (`cmd::calibrate`) and its rendering (`render::calibration`).
use imu_cal::accel::AccelProblem;
use imu_cal::gyro::GyroProblem;
use imu_cal::gyro_rot::GyroRotProblem;
use imu_cal::lab::{Model, Problem, Report, Step};
use imu_cal::mag::MagProblem;
use imu_cal::sentinel::Sentinels;
use model_lab::Stop;

/// The prepared data of one run (kept for the report and the figures), with what was excluded
/// before fitting.
pub enum Data {
    /// Static poses.
    Accel(AccelProblem),
    /// Block means at rest.
    Gyro(GyroProblem),
    /// Moves between static poses.
    GyroRot(GyroRotProblem),
    /// Samples of the field.
    Mag(MagProblem),
}

impl Data {
    /// The problem behind it.
    pub fn problem(&self) -> &dyn Problem {
        match self {
            Data::Accel(p) => p,
            Data::Gyro(p) => p,
            Data::GyroRot(p) => p,
            Data::Mag(p) => p,
        }
    }
}

/// A loaded run: the data, the sentinels excluded, and notes about the input for the report.
pub struct Loaded {
    /// The problem's data.
    pub data: Data,
    /// Sentinels found (and excluded) in the sensor's columns.
    pub sentinels: Sentinels,
    /// Other notes on the input (gaps, missing temperature, …).
    pub notes: Vec<String>,
}
/// What a run produced: the report on the last model, and for `--auto` the walk that led to it.
pub struct Outcome {
    /// The model the run started from (`--model`).
    pub start: Model,
    /// The steps of the walk (`--auto`), in order.
    pub steps: Vec<Step>,
    /// Why the walk ended (`None` without `--auto`).
    pub stop: Option<Stop>,
    /// The last model's report: verdict, candidates, diagnosis, the next step.
    pub report: Report,
}
