//! Helpers shared by the integration tests: a batch from generated parts, batch equality that
//! sees NaN scales as equal to themselves, one frame from an encoder call, and unsigned values
//! weighted towards the varint boundaries.
#![allow(dead_code)] // each test crate uses its own subset

use imu_proto::{
    EncodeError, FrameEncoder, ImuSample, MagSample, SampleBatch, Scales, Vec, MAX_FRAME,
};
use proptest::prelude::*;

/// The frame `encode` writes with a fresh encoder into a buffer of [`MAX_FRAME`] bytes.
pub fn frame_with(
    encode: impl FnOnce(&mut FrameEncoder, &mut [u8]) -> Result<usize, EncodeError>,
) -> Result<std::vec::Vec<u8>, EncodeError> {
    let mut out = std::vec![0u8; MAX_FRAME];
    let n = encode(&mut FrameEncoder::new(), &mut out)?;
    out.truncate(n);
    Ok(out)
}

/// Unsigned values of `bits` bits weighted towards the varint boundaries and the extremes.
pub fn arb_bits(bits: u32) -> impl Strategy<Value = u128> {
    let max = if bits == 128 {
        u128::MAX
    } else {
        (1u128 << bits) - 1
    };
    prop_oneof![
        any::<u128>().prop_map(move |v| v & max),
        Just(max),
        Just(0u128),
        (0..bits).prop_map(|k| 1u128 << k),
        (1..bits).prop_map(|k| (1u128 << k) - 1),
        (0..bits).prop_flat_map(move |k| (0u128..=(1 << 20)).prop_map(move |v| v << k & max)),
    ]
}

/// The IMU sample of generated parts (seq, t_us, accel, gyro, temp).
pub fn imu_sample(
    (seq, t_us, accel, gyro, temp): (u32, u64, [i32; 3], [i32; 3], Option<i32>),
) -> ImuSample {
    ImuSample {
        seq,
        t_us,
        accel,
        gyro,
        temp,
    }
}

/// The batch of the generated parts (`s` = accel, gyro, mag, temp, temp_offset scales); the
/// lengths must be within `MAX_BATCH_IMU` and `MAX_BATCH_MAG`.
pub fn batch_of(
    calibrated: bool,
    imu: &[ImuSample],
    mag: &[MagSample],
    s: [f32; 5],
) -> SampleBatch {
    SampleBatch {
        calibrated,
        scales: Scales {
            accel: s[0],
            gyro: s[1],
            mag: s[2],
            temp: s[3],
            temp_offset: s[4],
        },
        imu: Vec::from_slice(imu).expect("at most MAX_BATCH_IMU samples"),
        mag: Vec::from_slice(mag).expect("at most MAX_BATCH_MAG samples"),
    }
}

/// f32 NaN != NaN, so compare batches through their bit patterns.
pub fn same_batch(a: &SampleBatch, b: &SampleBatch) -> bool {
    let bits = |s: &Scales| [s.accel, s.gyro, s.mag, s.temp, s.temp_offset].map(f32::to_bits);
    a.calibrated == b.calibrated
        && a.imu == b.imu
        && a.mag == b.mag
        && bits(&a.scales) == bits(&b.scales)
}
