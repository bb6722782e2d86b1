//! The postcard bytes of `DeviceMsg::Table(table)`, written by hand: the same bytes as the serde
//! path (tested, `tests/table.rs`), at a fraction of its cycles on the M0+, where serde writes
//! each of a table's ≈ 150 varints, several of them 128-bit, through its own small copy.
//!
//! Layout (`crate::wire` has the rules): the variant (2), then [`AllanTable`]'s fields in
//! order — `channel` (its variant index), `snapshot`, `t_us`, `tau0_ns`, `scale` (f32), `pushed`,
//! `gaps`, and `levels` as a length and that many [`AllanLevel`]s (`m`, `stride`, `n2`, `sum2`,
//! `n3`, `sum3`).
use crate::wire::write_checked;
use crate::{AllanLevel, AllanTable, MAX_LEVELS};

/// Index of `DeviceMsg::Table` among `DeviceMsg`'s variants (tested against the serde path).
pub(crate) const TABLE_VARIANT: u8 = 2;

/// Most bytes of [`write_head`]: variant, channel, snapshot (5), `t_us` (10), `tau0_ns` (5),
/// scale (4), pushed (10), gaps (5), the number of levels (1: at most [`MAX_LEVELS`] < 128).
pub const HEAD_MAX: usize = 1 + 1 + 5 + 10 + 5 + 4 + 10 + 5 + 1;
/// Most bytes of [`write_level`]: `m` and `stride` (5 each), `n2` and `n3` (10 each), `sum2`
/// and `sum3` (19 each).
pub const LEVEL_MAX: usize = 5 + 5 + 10 + 19 + 10 + 19;
const _: () = assert!(MAX_LEVELS < 128);

/// Write the postcard encoding of `DeviceMsg::Table(table)` into `buf`; returns its length, or
/// `None` if `buf` is too small.
pub fn write(table: &AllanTable, buf: &mut [u8]) -> Option<usize> {
    let mut n = write_head(table, table.levels.len(), buf)?;
    for l in &table.levels {
        n += write_level(l, buf.get_mut(n..)?)?;
    }
    Some(n)
}

/// The bytes of `DeviceMsg::Table` that come before its levels: the variant, `table`'s fields
/// up to its levels, and the number of levels `levels` that follow (each then written by
/// [`write_level`]; `table.levels` itself is not read). Returns the length, `None` if `buf` is
/// too small ([`HEAD_MAX`] bytes always suffice). With the levels written one at a time, a
/// device can encode a table a few levels at a time.
pub fn write_head(table: &AllanTable, levels: usize, buf: &mut [u8]) -> Option<usize> {
    write_checked(buf, |c| {
        c.byte(TABLE_VARIANT);
        // A fieldless enum: its discriminant is its variant index (tested for every channel).
        c.varint(table.channel as u32);
        c.varint(table.snapshot);
        c.varint_u64(table.t_us);
        c.varint(table.tau0_ns);
        c.f32(table.scale);
        c.varint_u64(table.pushed);
        c.varint(table.gaps);
        c.varint(levels as u32);
    })
}

/// The bytes of one level of a table; the length, `None` if `buf` is too small ([`LEVEL_MAX`]
/// bytes always suffice).
pub fn write_level(l: &AllanLevel, buf: &mut [u8]) -> Option<usize> {
    write_checked(buf, |c| {
        c.varint(l.m);
        c.varint(l.stride);
        c.varint_u64(l.n2);
        c.varint_u128(l.sum2);
        c.varint_u64(l.n3);
        c.varint_u128(l.sum3);
    })
}
