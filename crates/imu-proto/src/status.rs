//! The postcard bytes of `DeviceMsg::Status(status)`, written by hand: the same bytes as the
//! serde path (tested, `tests/status.rs`), for the device's once-a-second status frame, where
//! serde writes each of its u64 counters in a 64-bit varint loop (the M0+ has no 64-bit shifts;
//! docs/benchmarks.md has the cycles).
//!
//! Layout (`crate::wire` has the rules): the variant (3), then [`Status`]'s fields in order;
//! `u16` is a varint, `u8` one byte, an `Option` a 0/1 byte before its value, a fieldless enum
//! its variant index, an enum with data its variant index and then the data.
use crate::wire::{write_checked, Cursor};
use crate::{CalFault, CalProblem, CalStatus, Status};

/// Index of `DeviceMsg::Status` among `DeviceMsg`'s variants (tested against the serde path).
pub(crate) const STATUS_VARIANT: u8 = 3;

/// Write the postcard encoding of `DeviceMsg::Status(status)` into `buf`; returns its length,
/// or `None` if `buf` is too small.
pub fn write(s: &Status, buf: &mut [u8]) -> Option<usize> {
    write_checked(buf, |c| {
        c.byte(STATUS_VARIANT);
        for n in [
            s.uptime_us,
            s.samples_taken,
            s.samples_dropped,
            s.mag_samples,
            s.mag_dropped,
        ] {
            c.varint_u64(n);
        }
        for n in [
            s.fifo_overflows,
            s.i2c_errors,
            s.bus_faults,
            s.bus_recoveries,
            s.frames_rejected,
            s.frames_unsent,
            u32::from(s.cpu_load_permille),
        ] {
            c.varint(n);
        }
        c.option(s.temp_milli_c, Cursor::zigzag);
        // Fieldless enums: the discriminant is the variant index (tested for every variant).
        c.varint(s.imu as u32);
        c.varint(s.mag as u32);
        c.varint(s.imu_period_ns);
        c.varint(s.mag_period_ns);
        cal(c, &s.cal);
        c.varint(s.mode as u32);
    })
}

fn cal(c: &mut Cursor<'_, true>, cal: &CalStatus) {
    c.varint(cal.source as u32);
    c.option(cal.fault, |c, f| match f {
        CalFault::Flash => c.varint(0),
        CalFault::Rejected(p) => {
            c.varint(1);
            problem(c, p);
        }
    });
}

fn problem(c: &mut Cursor<'_, true>, p: CalProblem) {
    match p {
        CalProblem::Corrupt => c.varint(0),
        CalProblem::Version(v) => {
            c.varint(1);
            c.varint(u32::from(v));
        }
        CalProblem::OutOfRange => c.varint(2),
        CalProblem::Implausible {
            key,
            axis,
            value,
            lo,
            hi,
        } => {
            c.varint(3);
            c.byte(key);
            c.option(axis, |c, a| c.byte(a));
            c.f32(value);
            c.f32(lo);
            c.f32(hi);
        }
        CalProblem::OtherRanges => c.varint(4),
        CalProblem::OtherPart => c.varint(5),
    }
}
