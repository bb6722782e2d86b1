//! The postcard bytes of `DeviceMsg::Table(table)`, written by hand: the same bytes as the serde
//! path (tested, `tests/table.rs`), at a fraction of its cycles on the M0+, where serde writes
//! each of a table's ≈ 150 varints, several of them 128-bit, through its own small copy.
//!
//! Layout (`crate::wire` has the rules): the variant (2), then [`AllanTable`]'s fields in
//! order — `channel` (its variant index), `snapshot`, `t_us`, `tau0_ns`, `scale` (f32), `pushed`,
//! `gaps`, and `levels` as a length and that many [`AllanLevel`]s (`m`, `stride`, `n2`, `sum2`,
//! `n3`, `sum3`).
use crate::wire::Cursor;
use crate::AllanTable;

/// Index of `DeviceMsg::Table` among `DeviceMsg`'s variants (tested against the serde path).
pub(crate) const TABLE_VARIANT: u8 = 2;

/// Write the postcard encoding of `DeviceMsg::Table(table)` into `buf`; returns its length, or
/// `None` if `buf` is too small.
pub fn write(table: &AllanTable, buf: &mut [u8]) -> Option<usize> {
    let len = buf.len();
    let mut c = Cursor::<true> { buf, pos: 0 };
    c.byte(TABLE_VARIANT);
    // A fieldless enum: its discriminant is its variant index (tested for every channel).
    c.varint(table.channel as u32);
    c.varint(table.snapshot);
    c.varint_u64(table.t_us);
    c.varint(table.tau0_ns);
    c.f32(table.scale);
    c.varint_u64(table.pushed);
    c.varint(table.gaps);
    c.varint(table.levels.len() as u32);
    for l in &table.levels {
        c.varint(l.m);
        c.varint(l.stride);
        c.varint_u64(l.n2);
        c.varint_u128(l.sum2);
        c.varint_u64(l.n3);
        c.varint_u128(l.sum3);
    }
    Some(c.pos).filter(|&n| n <= len)
}
