//! The postcard bytes of `DeviceMsg::Orientation(list)`, written by hand: the same bytes as the
//! serde path (tested, `tests/orientation.rs`), for the device's attitude frames (fifty a
//! second), where serde's generic writer cost ≈ 360 cycles per ms on the M0+
//! (docs/benchmarks.md).
//!
//! Layout (`crate::wire` has the rules): the variant (5), the list's length, then each
//! [`Orientation`]'s fields in order: `seq` and `t_us` varints, the quaternion's and the three
//! angles' `f32`s, the state's variant index.
use crate::wire::{write_checked, Cursor};
use crate::{Orientation, Vec, MAX_ORIENTATIONS};

/// The longest encoding of one [`Orientation`]: `seq` 5, `t_us` 10, seven `f32`s 28, the state 1.
const MAX_ONE: usize = 5 + 10 + 28 + 1;

/// Index of `DeviceMsg::Orientation` among `DeviceMsg`'s variants (tested against the serde
/// path).
pub(crate) const ORIENTATION_VARIANT: u8 = 5;

/// Write the postcard encoding of `DeviceMsg::Orientation(list)` into `buf`; returns its
/// length, or `None` if `buf` is too small.
pub fn write(list: &Vec<Orientation, MAX_ORIENTATIONS>, buf: &mut [u8]) -> Option<usize> {
    if buf.len() >= 2 + list.len() * MAX_ONE {
        // Room for the longest encoding: no byte can fall past the end, none is compared.
        let mut c = Cursor::<false> { buf, pos: 0 };
        write_to(&mut c, list);
        return Some(c.pos);
    }
    write_checked(buf, |c| write_to(c, list))
}

/// The bytes, through either cursor.
#[inline(always)]
fn write_to<const CHECKED: bool>(
    c: &mut Cursor<'_, CHECKED>,
    list: &Vec<Orientation, MAX_ORIENTATIONS>,
) {
    c.byte(ORIENTATION_VARIANT);
    c.varint(list.len() as u32);
    for o in list {
        c.varint(o.seq);
        c.varint_u64(o.t_us);
        for x in o.q {
            c.f32(x);
        }
        c.f32(o.roll_deg);
        c.f32(o.pitch_deg);
        c.f32(o.heading_deg);
        // A fieldless enum: the discriminant is the variant index (tested for every
        // variant).
        c.varint(o.state as u32);
    }
}
