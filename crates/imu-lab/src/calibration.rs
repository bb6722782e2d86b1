//! What a calibration run works on and what it produced (`imu_cal::session`), shared by the
//! `calibrate` command (`cmd::calibrate`) and its rendering (`render::calibration`).
pub use imu_cal::session::{Data, Loaded, Outcome};
