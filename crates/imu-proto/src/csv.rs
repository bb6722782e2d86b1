//! The CSV recording contract (host side, feature `std`): the one place that says which columns a
//! recording has, their units, how a file is read and written, and what its time column says.
//!
//! # Layout
//! * A header row, then one sample per row, comma-separated. Leading and trailing blanks of a
//!   field are ignored; a UTF-8 byte-order mark and CRLF line ends are accepted.
//! * `t` (s): the device's sample-clock stamp of the row.
//! * `gap_before` (samples, integer ≥ 0): samples the device lost immediately before this row
//!   (FIFO overflow, a dropped batch). Optional; absent means "none reported".
//! * `ax ay az` (m/s²), `gx gy gz` (deg/s), `mx my mz` (µT), `temp` (°C): the channels of
//!   [`Channel`], in that order. Any subset may be present; other columns are ignored.
//! * `q0 q1 q2 q3` (body → NED quaternion, `q0` the scalar), `roll pitch heading` (degrees),
//!   `ahrs` (the filter's state: 0 converging, 1 tracking, 2 |B| out of its band, 3 dip out of
//!   its band): the device's attitude estimate ([`ORIENTATION`]), optional.
//! * A missing value is an empty field. Only [`may_be_empty`] columns (`temp`, the orientation
//!   columns before the device's first estimate) may have one: a sensor that reports no
//!   temperature leaves the field empty. Anywhere else an empty field is
//!   an error naming the line and the column.
//! * A header naming a column twice is refused (which of the two would be meant?).
//!
//! The module's parts: the layout here (names, units, errors), reading ([`Reader`], `read.rs`),
//! writing ([`Writer`], `write.rs`) and the time column ([`timing`], `timing.rs`).
//!
//! Files in other layouts (metadata lines above the header, other column names) are read with
//! [`ReadOptions`]: `skip_lines` and `renames`. The units of such files are the caller's business
//! (a renamed or metadata-preceded column is not known to hold contract units).
//!
//! # Time
//! [`timing`] reads the `t` column as what it is, a list of stamps, and reports how regular it
//! is ([`Timing`]): the nominal period (median spacing), gaps (spacings of at least 2.5 periods or
//! of 2 ± ¼ periods, [`is_gap`], or reported by `gap_before`) which split the record into segments
//! no Allan difference may span, duplicated and jittered stamps, and bursty stamps (host read
//! times of buffered data, not a sample clock).
use std::fmt;

use crate::Channel;

mod read;
mod timing;
mod write;

pub use read::{parse_renames, HeaderColumn, ReadOptions, Reader};
pub use timing::{
    is_gap, read_clock, segments_between, timing, Clock, Gap, Regularity, Timing, TimingError,
    TimingScan, BURSTY_FRACTION, GAP_FACTOR, JITTER_TOLERANCE, ONE_SAMPLE_GAP_TOLERANCE,
};
pub use write::{WriteOptions, Writer};

/// Name of the time column (s).
pub const TIME: &str = "t";
/// Name of the column of samples lost before a row.
pub const GAP_BEFORE: &str = "gap_before";
/// The full header a recorder writes: `t`, `gap_before`, then every channel in [`Channel::ALL`]
/// order.
pub const HEADER: [&str; 12] = [
    "t",
    "gap_before",
    "ax",
    "ay",
    "az",
    "gx",
    "gy",
    "gz",
    "mx",
    "my",
    "mz",
    "temp",
];

/// The orientation columns a recorder may add after [`HEADER`]'s (the device's attitude
/// estimate, `imu_proto::Orientation`, held from the latest estimate at or before the row).
pub const ORIENTATION: [&str; 8] = ["q0", "q1", "q2", "q3", "roll", "pitch", "heading", "ahrs"];

/// The channel a contract column name stands for.
pub fn channel(name: &str) -> Option<Channel> {
    Channel::ALL.into_iter().find(|c| c.name() == name)
}

/// The contract unit of a column name: `s` for `t`, `samples` for `gap_before`, the channel's
/// unit otherwise; `None` for names outside the contract.
pub fn unit(name: &str) -> Option<&'static str> {
    match name {
        TIME => Some("s"),
        GAP_BEFORE => Some("samples"),
        "q0" | "q1" | "q2" | "q3" => Some("1"),
        "roll" | "pitch" | "heading" => Some("deg"),
        "ahrs" => Some("state"),
        _ => channel(name).map(Channel::unit),
    }
}

/// Whether a column may hold empty (missing) fields.
pub fn may_be_empty(name: &str) -> bool {
    name == Channel::Temp.name() || ORIENTATION.contains(&name)
}

/// A reading or writing error: what, where (file and line, when known).
#[derive(Debug, Clone, PartialEq)]
pub struct CsvError {
    /// The file (or stream) as shown to the user.
    pub source: String,
    /// 1-based line of the file, when the error is about one.
    pub line: Option<usize>,
    /// What is wrong, naming the field where there is one.
    pub message: String,
}

impl fmt::Display for CsvError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(l) => write!(f, "{}: line {l}: {}", self.source, self.message),
            None => write!(f, "{}: {}", self.source, self.message),
        }
    }
}

impl std::error::Error for CsvError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_matches_the_channels() {
        assert_eq!(&HEADER[..2], &[TIME, GAP_BEFORE]);
        for (h, c) in HEADER[2..].iter().zip(Channel::ALL) {
            assert_eq!(*h, c.name());
            assert_eq!(unit(h), Some(c.unit()));
        }
        assert_eq!(unit("t"), Some("s"));
        assert_eq!(unit("gyro_z"), None);
    }
}
