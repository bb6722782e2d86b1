//! Helpers shared by the integration tests: a batch from generated parts, and batch equality
//! that sees NaN scales as equal to themselves.
#![allow(dead_code)] // each test crate uses its own subset

use imu_proto::{ImuSample, MagSample, SampleBatch, Scales, Vec};

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
