//! The words `imu-lab fit` prints around the session's numbers (the JSON object itself is
//! `noise_model::session::Session::json`).
use super::*;

/// A duration in the largest unit that keeps it readable (s, min, h, days).
pub(super) fn duration(s: f64) -> String {
    if s < 120.0 {
        format!("{} s", report::sig(s, 3))
    } else if s < 7200.0 {
        format!("{} min", report::sig(s / 60.0, 3))
    } else if s < 172_800.0 {
        format!("{} h", report::sig(s / 3600.0, 3))
    } else {
        format!("{} days", report::sig(s / 86400.0, 3))
    }
}
