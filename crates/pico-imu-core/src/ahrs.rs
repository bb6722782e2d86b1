//! Attitude and heading on the device (AHRS): Mahony's explicit complementary filter on the
//! calibrated samples — R. Mahony, T. Hamel, J.-M. Pflimlin, "Nonlinear Complementary Filters on
//! the Special Orthogonal Group", IEEE Transactions on Automatic Control 53(5), 2008 (the
//! explicit complementary filter with bias correction, in quaternion form).
//!
//! # What runs where
//! * the 1 kHz path only sums the corrected gyro and accelerometer counts ([`Accum::add`]: seven
//!   integer adds a sample);
//! * one filter update per magnetometer sample (200 Hz): the summed gyro is the rotation since
//!   the last update (`Σ g · T`, the IMU's measured period), the mean accelerometer and the
//!   magnetometer reading correct it; when no magnetometer sample comes for
//!   [`MAX_SUM`] IMU samples, the IMU path queues an update without it (the sums stay
//!   bounded). The updates are queued and run by the processing task (`crate::pipeline`).
//!
//! # Frames
//! The filter works in NED (x magnetic north, y east, z down) with a forward-right-down body.
//! The sensors' axes are forward-left-up (the accelerometer reads +g on z lying level), taken as
//! `(x, −y, −z)`; the MPU-6050's and the QMC5883L's axes are assumed parallel (the board's
//! layout; a board that turns one of them needs the calibration's matrix to turn it back).
//!
//! # Corrections
//! * gravity: the measured direction `â` of the mean accelerometer against the estimated
//!   `−R̂ᵀe_z`, error `â × (−R̂ᵀe_z)`;
//! * heading: the magnetometer reading turned to the world, `h = R̂ m`; its horizontal part
//!   should point north: the error is the angle between them about the vertical only,
//!   `−h_y / |h_xy|` times the body's vertical `R̂ᵀe_z`, so a magnetic disturbance can never tilt
//!   roll and pitch (the tilt-decoupled variant);
//! * `ω = Σg·T/Δt + k_P e + b̂`, `b̂ += k_I e Δt` (gyro bias left by the calibration).
//!
//! # Magnetic disturbance
//! Each update compares |B| and the dip (inclination, the angle of B below the horizontal:
//! `sin δ = m·R̂ᵀe_z / |m|`) with the expected field: |B| within ±[`FIELD_BAND`] of the expected
//! strength and the dip within ±[`DIP_BAND_DEG`] of the expected dip. Outside, the update skips
//! the magnetometer (heading from the gyro alone) and reports [`AhrsState::MagField`] or
//! [`AhrsState::MagDip`]. The expected values are the host's ([`Ahrs::set_reference`]) or, by
//! default, learnt: the mean |B| and dip of the first [`LEARN_UPDATES`] updates after the filter
//! converged. A calibration (the magnetometer's correction) changes what |B| reads: a new one
//! resets the filter and a learnt reference.
//!
//! # Integer arithmetic (the device's filter)
//! The Cortex-M0+ has no FPU: in `f32` (soft float, [`float::Ahrs`], the reference) an update
//! costs ≈ 30,000 cycles; [`Ahrs`] is the same filter in integers (docs/benchmarks.md has the
//! cycles). Formats (`Qn`: value · 2^n):
//! * the quaternion in Q30; the rotation's rows in Q29, from the quaternion rounded to Q15
//!   (16 × 16-bit products, entries within ≈ 6·10⁻⁵, the diagonal's also off by the norm's
//!   drift between renormalisations; with [`fixed::atan2`], the angles within
//!   0.004° + 0.014°/cos(pitch) of their exact values from the quaternion, tested);
//! * the half rotation `v` in Q30 rad: the gyro sums times the step per count (Q46, from the
//!   IMU's measured period), by [`fixed::mul_shr`], the sums clamped so that it stays below
//!   0.5 rad whatever they hold (a longer step is renormalised at once);
//! * the quaternion step `q + q ⊗ (0, v)` in block floating point: `v` shifted so its largest
//!   component fits 15 bits, times the quaternion in Q15 (every product one 32-bit multiply; the
//!   increments' relative error ≤ 6·10⁻⁵ of the largest component);
//! * the directions of the accelerometer, the magnetometer and `h`'s horizontal part: shifted to
//!   15 bits, scaled by [`fixed::rsqrt`] (≤ 2·10⁻⁴: only the correction's gain, the learnt
//!   field and the dip band's edges see it);
//! * the errors and the correction in Q30; the bias estimate in Q40 (its increments are
//!   `k_I Δt` times smaller than the correction's);
//! * roll, pitch, heading by [`fixed::atan2`] (a polynomial in the components' ratio, the ratio
//!   by a table-and-Newton reciprocal, ≤ 0.004°); pitch as `atan2(−d₁, √(d₂² + d₃²))`, the root
//!   by [`fixed::rsqrt`]; degrees in Q20.
//!
//! The output is `f32` for the wire ([`Attitude`]): seven integer-to-float conversions an
//! update, the scale put into the exponent ([`fixed::to_f32`]). `f32` and `libm` stay where they
//! run once and off the filter's path: the initial attitude, the host's field reference, the
//! declination (a learnt reference is made in integers, in the update that completes it). The
//! integer filter agrees with the `f32` one within 0.05° in roll, pitch and heading on random
//! trajectories, with the same states but where an error crossing a threshold slowly is decided
//! a few updates apart (`tests/ahrs.rs`).
pub use imu_proto::AhrsState;

pub mod fixed;
pub mod float;

use fixed::{atan2, mul_shr, norm15, rsqrt, to_f32, DEG_Q20};

/// Proportional gain while tracking, rad/s per unit error (time constant 1 s).
pub const KP: f32 = 1.0;
/// Integral gain (gyro bias), rad/s² per unit error: with [`KP`], a bias is learnt with a
/// time constant of ≈ KP/KI = 10 s.
pub const KI: f32 = 0.1;
/// |B| band around the expected strength: ±10 %.
pub const FIELD_BAND: f32 = 0.10;
/// Dip band around the expected dip: ±5°.
pub const DIP_BAND_DEG: f32 = 5.0;
/// Updates averaged to learn the expected field when the host has not set it (1 s at 200 Hz).
pub const LEARN_UPDATES: u32 = 200;
/// Converged: the correction's error (sines of the angles between measured and estimated
/// directions), smoothed over ≈ 16 updates and then squared, below sin²(2°), and at least this
/// many updates since the start. Smoothed before squaring, the sensors' noise is averaged down
/// (a noisy heading where the field is nearly vertical would otherwise never converge).
pub const CONVERGED_ERR2: f32 = 1.2e-3;
const MIN_CONVERGE_UPDATES: u32 = 50;
/// Updates with both sensors' readings averaged for the first attitude (40 ms): one
/// magnetometer reading's noise (0.2 µT against a horizontal field of 10 µT: ≈ 1° of heading)
/// would otherwise start the filter up to 3–4° off, a second of pulling in at k_P.
pub const START_UPDATES: u32 = 8;
/// Converging again: within [`SETTLE_UPDATES`] of converging or while the expected field is
/// being learnt, the smoothed error's tilt part (across the body's down axis) squared above
/// twice [`CONVERGED_ERR2`] (≈ 2.8°; the factor two keeps an error at the threshold from
/// flapping). The tilt, because it is what a learnt dip is made of and what a gyro bias's
/// horizontal part builds; the heading's error also grows with a magnetometer not calibrated
/// yet or a disturbance, which the field's bands report.
pub const REDIVERGED_ERR2: f32 = 2.0 * CONVERGED_ERR2;
/// Updates after converging that the tilt is still watched (3 s). From an exact start a gyro
/// bias's error builds over seconds: with k_P and k_I it peaks ≈ 2.7 s after the start, at
/// ≈ 0.83 bias/k_P. Later, a growing tilt is the vehicle's acceleration, not a filter still
/// pulling in.
pub const SETTLE_UPDATES: u32 = 600;
/// IMU samples summed at most before an update without the magnetometer (100 ms at 1 kHz;
/// full-scale counts × this stay far inside i32).
pub const MAX_SUM: u32 = 100;
/// The quaternion is renormalised every this many updates.
const RENORM_EVERY: u32 = 4;

/// The 1 kHz path's sums since the last update: corrected counts.
#[derive(Debug, Clone, Copy, Default)]
pub struct Accum {
    pub gyro: [i32; 3],
    pub accel: [i32; 3],
    pub n: u32,
}

impl Accum {
    /// One IMU sample (corrected counts).
    #[inline(always)]
    pub fn add(&mut self, accel: &[i32; 3], gyro: &[i32; 3]) {
        self.accel[0] += accel[0];
        self.accel[1] += accel[1];
        self.accel[2] += accel[2];
        self.gyro[0] += gyro[0];
        self.gyro[1] += gyro[1];
        self.gyro[2] += gyro[2];
        self.n += 1;
    }

    /// `n` IMU samples at once, their sums given.
    #[inline(always)]
    pub fn add_sums(&mut self, accel: &[i32; 3], gyro: &[i32; 3], n: u32) {
        for i in 0..3 {
            self.accel[i] += accel[i];
            self.gyro[i] += gyro[i];
        }
        self.n += n;
    }
}

/// One attitude estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Attitude {
    /// Body (forward-right-down) → NED, `[w, x, y, z]`, unit norm.
    pub q: [f32; 4],
    pub roll_deg: f32,
    pub pitch_deg: f32,
    /// Tilt-compensated heading, degrees in [0, 360): magnetic plus the declination.
    pub heading_deg: f32,
    pub state: AhrsState,
}

/// The first attitude, from one accelerometer and one magnetometer reading (body axes):
/// down = −â, east = down × m, north = east × down, as the rows of R; then the quaternion
/// of R, `[w, x, y, z]`, unit norm (exact functions: once per start). `None` when the readings
/// give no frame (a zero vector, or m parallel to a).
fn initial_quaternion(a: &[f32; 3], m: &[f32; 3]) -> Option<[f32; 4]> {
    let unit = |v: [f32; 3]| {
        let n = libm::sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        if n > 0.0 {
            Some(v.map(|c| c / n))
        } else {
            None
        }
    };
    let cross = |a: [f32; 3], b: [f32; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let down = unit(a.map(|c| -c))?;
    let east = unit(cross(down, *m))?;
    let north = cross(east, down);
    let r = [north, east, down];
    let tr = r[0][0] + r[1][1] + r[2][2];
    let q = if tr > 0.0 {
        let s = 2.0 * libm::sqrtf(1.0 + tr);
        [
            s / 4.0,
            (r[2][1] - r[1][2]) / s,
            (r[0][2] - r[2][0]) / s,
            (r[1][0] - r[0][1]) / s,
        ]
    } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
        let s = 2.0 * libm::sqrtf(1.0 + r[0][0] - r[1][1] - r[2][2]);
        [
            (r[2][1] - r[1][2]) / s,
            s / 4.0,
            (r[0][1] + r[1][0]) / s,
            (r[0][2] + r[2][0]) / s,
        ]
    } else if r[1][1] > r[2][2] {
        let s = 2.0 * libm::sqrtf(1.0 + r[1][1] - r[0][0] - r[2][2]);
        [
            (r[0][2] - r[2][0]) / s,
            (r[0][1] + r[1][0]) / s,
            s / 4.0,
            (r[1][2] + r[2][1]) / s,
        ]
    } else {
        let s = 2.0 * libm::sqrtf(1.0 + r[2][2] - r[0][0] - r[1][1]);
        [
            (r[1][0] - r[0][1]) / s,
            (r[0][2] + r[2][0]) / s,
            (r[1][2] + r[2][1]) / s,
            s / 4.0,
        ]
    };
    let n = libm::sqrtf(q.iter().map(|c| c * c).sum());
    if n.is_finite() && n > 0.0 {
        Some(q.map(|c| c / n))
    } else {
        None
    }
}

/// The gyro's step: half the rotation, rad, per count of a gyro sum, in Q46 (the half rotation
/// in Q30 is `sum · step >> 16`): the gyro's scale times the IMU's period, halved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GyroStep(pub i32);

impl GyroStep {
    /// From rad per count-sample (the gyro's scale in rad/s per count times the IMU's period in
    /// s); `f64` arithmetic (configuration and tests, not the sample path).
    pub fn from_rad(rad_per_count: f64) -> GyroStep {
        GyroStep(libm::round(rad_per_count * 0.5 * (1u64 << 46) as f64) as i32)
    }
}

/// One in Q30.
const ONE_Q30: i32 = 1 << 30;
/// [`CONVERGED_ERR2`] in Q30.
const CONVERGED_ERR2_Q30: u32 = (CONVERGED_ERR2 as f64 * (1u64 << 30) as f64) as u32;
/// [`REDIVERGED_ERR2`] in Q30.
const REDIVERGED_ERR2_Q30: u32 = (REDIVERGED_ERR2 as f64 * (1u64 << 30) as f64) as u32;
/// The bias estimate's bound, Q40 rad per half magnetometer period (2^30: 0.39 rad/s, 22°/s).
const BIAS_MAX_Q40: i32 = 1 << 30;

/// The gains of one update of `dt` (the correction's step).
#[derive(Debug, Clone, Copy)]
struct Gains {
    /// `k_P Δt / 2`, Q32.
    kph_q32: i32,
    /// `(k_I/k_P) Δt`, Q34: the bias's increment per unit of correction.
    kb_q34: i32,
    /// `Δt` over the magnetometer's period, Q16 (the bias is kept per magnetometer period).
    ratio_q16: i32,
}

impl Gains {
    /// `dt_us` is taken as at most 200 ms (the firmware's updates without the magnetometer
    /// come every [`MAX_SUM`] IMU samples, 100 ms): the half rotation, the correction and the
    /// bias term then stay below 2^30 in Q30 ([`Ahrs::rotate`]). The bias's increment takes it
    /// as at most 110 ms: `kI e Δt²/2` in Q40 stays below 9.4·10⁸ for |e_i| ≤ √2 (the sum
    /// saturates whatever absurd inputs make of the error).
    const fn new(dt_us: u32) -> Gains {
        let dt = (if dt_us > 200_000 { 200_000 } else { dt_us }) as f64 * 1e-6;
        let dt_b = if dt > 0.11 { 0.11 } else { dt };
        Gains {
            kph_q32: (0.5 * KP as f64 * dt * (1u64 << 32) as f64) as i32,
            kb_q34: ((KI / KP) as f64 * dt_b * (1u64 << 34) as f64) as i32,
            ratio_q16: (dt / (imu_proto::MAG_PERIOD_US as f64 * 1e-6) * 65536.0) as i32,
        }
    }
}

impl Gains {
    /// [`Gains::new`] at run time (`f64` in software: out of line, for the rare updates without
    /// the magnetometer).
    #[cold]
    #[inline(never)]
    fn at(dt_us: u32) -> Gains {
        Gains::new(dt_us)
    }
}

/// The gains of an update at a magnetometer sample (its period).
const MAG_GAINS: Gains = Gains::new(imu_proto::MAG_PERIOD_US as u32);

/// Expected field: bands on |B|² (input units squared) and on sin(dip) (Q30).
#[derive(Debug, Clone, Copy)]
struct Bands {
    field2: [u64; 2],
    sin_dip: [i32; 2],
}

/// 1 ∓ [`FIELD_BAND`], Q16.
const FIELD_EDGES_Q16: [u64; 2] = [
    ((1.0 - FIELD_BAND as f64) * 65536.0) as u64,
    ((1.0 + FIELD_BAND as f64) * 65536.0) as u64,
];
/// sin and cos of [`DIP_BAND_DEG`] (5°), Q30 (`tests`: equal to libm's).
const SIN_DIP_BAND_Q30: i64 = 93_582_766;
const COS_DIP_BAND_Q30: i64 = 1_069_655_912;

impl Bands {
    /// The bands around a field of `field_q8` (input units, Q8) and a dip of sine `sin` and
    /// cosine `cos` (Q30, `cos` ≥ 0), in integers: a learnt reference is made on the
    /// filter's path, where `f64` and libm would cost ≈ 30,000 cycles in one update.
    /// `sin(δ ± 5°) = sin δ cos 5° ± cos δ sin 5°`, ±1 past the poles.
    fn new(field_q8: u64, sin: i32, cos: i32) -> Bands {
        let f2 = |k: u64| {
            let f = (field_q8 * k) >> 16;
            (f * f) >> 16
        };
        let (s, c) = (i64::from(sin), i64::from(cos));
        let lo = if s < -COS_DIP_BAND_Q30 {
            -ONE_Q30
        } else {
            ((s * COS_DIP_BAND_Q30 - c * SIN_DIP_BAND_Q30) >> 30) as i32
        };
        let hi = if s > COS_DIP_BAND_Q30 {
            ONE_Q30
        } else {
            ((s * COS_DIP_BAND_Q30 + c * SIN_DIP_BAND_Q30) >> 30) as i32
        };
        Bands {
            field2: FIELD_EDGES_Q16.map(f2),
            sin_dip: [lo, hi],
        }
    }

    /// The bands around the host's field (input units) and dip (degrees), by libm (once).
    fn set(field: f32, dip_deg: f32) -> Bands {
        let (s, c) = libm::sincosf(dip_deg.clamp(-90.0, 90.0).to_radians());
        let q30 = |x: f32| (x * ONE_Q30 as f32) as i32;
        Bands::new((field.max(0.0) * 256.0) as u64, q30(s), q30(c.max(0.0)))
    }
}

/// Where the expected field comes from.
#[derive(Debug, Clone, Copy)]
enum Reference {
    /// Learning: sums of |B| (input units, Q8) and sin(dip) (Q30) over `n` tracking updates.
    Learning { field: u64, sin_dip: i64, n: u32 },
    /// Known: the field in the input units and the dip in degrees, learnt or the host's.
    Known {
        field: f32,
        dip_deg: f32,
        bands: Bands,
        learnt: bool,
    },
}

const LEARNING: Reference = Reference::Learning {
    field: 0,
    sin_dip: 0,
    n: 0,
};

/// The filter, in integers (the device's).
#[derive(Debug, Clone)]
pub struct Ahrs {
    /// Body → NED, `[w, x, y, z]`, Q30.
    q: [i32; 4],
    /// Updates since the start, for the renormalisation's turn.
    steps: u32,
    /// The rotation's rows for `q` ([`rows`]), Q29.
    rows: [[i32; 3]; 3],
    /// Gyro bias estimate times half the magnetometer's period, rad (body), Q40.
    bias: [i32; 3],
    started: bool,
    /// Before the start: the accelerometer sums and the magnetometer readings of the updates
    /// so far (body axes), and how many.
    start_sums: ([i32; 3], [i32; 3], u32),
    converging: bool,
    /// Updates left of the watch after converging ([`SETTLE_UPDATES`]).
    settle: u32,
    updates: u32,
    /// The correction's error, smoothed over ≈ 16 updates, Q30.
    err: [i32; 3],
    /// The latest accelerometer sum (body), for updates with no new IMU sample.
    accel: [i32; 3],
    declination_deg: f32,
    declination_q20: i32,
    reference: Reference,
}

impl Default for Ahrs {
    fn default() -> Self {
        Self::new()
    }
}

/// The first three rows of the body → NED rotation of a unit quaternion (Q30), in Q29, from
/// the quaternion rounded to Q15: every product one 32-bit multiply. A Q15 product is Q30, and
/// a rotation entry is twice such products, which is the same number in Q29.
fn rows(q: &[i32; 4]) -> [[i32; 3]; 3] {
    let [w, x, y, z] = q.map(|c| (c + (1 << 14)) >> 15);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, xz, yz) = (x * y, x * z, y * z);
    let (wx, wy, wz) = (w * x, w * y, w * z);
    const ONE_Q29: i32 = 1 << 29;
    [
        [ONE_Q29 - yy - zz, xy - wz, xz + wy],
        [xy + wz, ONE_Q29 - xx - zz, yz - wx],
        [xz - wy, yz + wx, ONE_Q29 - xx - yy],
    ]
}

impl Ahrs {
    pub fn new() -> Self {
        Ahrs {
            q: [ONE_Q30, 0, 0, 0],
            steps: 0,
            rows: [[1 << 29, 0, 0], [0, 1 << 29, 0], [0, 0, 1 << 29]],
            bias: [0; 3],
            started: false,
            start_sums: ([0; 3], [0; 3], 0),
            converging: true,
            settle: 0,
            updates: 0,
            err: [0; 3],
            accel: [0; 3],
            declination_deg: 0.0,
            declination_q20: 0,
            reference: LEARNING,
        }
    }

    /// Start over (a new calibration): attitude from the next readings, a learnt reference
    /// learnt again; the declination and a host's reference stay.
    pub fn reset(&mut self) {
        let keep = (self.declination_deg, self.reference);
        *self = Ahrs::new();
        self.set_declination(keep.0);
        if let Reference::Known { learnt: false, .. } = keep.1 {
            self.reference = keep.1;
        }
    }

    /// Declination (true north = magnetic north + this), degrees, added to the heading.
    pub fn set_declination(&mut self, deg: f32) {
        let deg = if deg.is_finite() { deg } else { 0.0 };
        self.declination_deg = deg;
        // The same angle within [−180°, 180°] for the sum with the heading.
        let d = libm::remainderf(deg, 360.0);
        self.declination_q20 = libm::roundf(d * DEG_Q20 as f32) as i32;
    }

    pub fn declination(&self) -> f32 {
        self.declination_deg
    }

    /// The expected field: strength in the magnetometer's input units and dip in degrees
    /// (positive down); `None` learns it again from the next converged second.
    pub fn set_reference(&mut self, field_dip: Option<(f32, f32)>) {
        self.reference = match field_dip {
            Some((field, dip_deg)) => Reference::Known {
                field,
                dip_deg,
                bands: Bands::set(field, dip_deg),
                learnt: false,
            },
            None => LEARNING,
        };
    }

    /// The expected field (strength, dip in degrees) in use, if known yet.
    pub fn reference(&self) -> Option<(f32, f32)> {
        match self.reference {
            Reference::Known { field, dip_deg, .. } => Some((field, dip_deg)),
            Reference::Learning { .. } => None,
        }
    }

    /// Whether the expected field is (or is being) learnt rather than the host's.
    pub fn reference_learnt(&self) -> bool {
        !matches!(self.reference, Reference::Known { learnt: false, .. })
    }

    /// The attitude now.
    pub fn quaternion(&self) -> [f32; 4] {
        self.q.map(|c| to_f32(c, 30))
    }

    /// The correction's error, smoothed, squared, and its tilt part squared (across the
    /// body's down axis): what `Converging` is decided on (against [`CONVERGED_ERR2`] and
    /// [`REDIVERGED_ERR2`]); updated while converging, settling or learning the expected field,
    /// held after. The tilt is taken about the down axis as it is after the update, which
    /// judged it about the axis before (one step apart: tests compare with a margin).
    pub fn convergence_errors2(&self) -> (f32, f32) {
        let e = self.err.map(|x| to_f32(x, 30));
        let d = self.rows[2].map(|x| to_f32(x, 29));
        let e2: f32 = e.iter().map(|x| x * x).sum();
        let along = e[0] * d[0] + e[1] * d[1] + e[2] * d[2];
        (e2, e2 - along * along)
    }

    /// One update. `acc`: the IMU sums since the last update (emptied); `step`: the gyro's
    /// half rotation per count; `mag`: corrected magnetometer counts (sensor axes), `None` for
    /// an update without it; `dt_us`: the time since the last update, µs (the correction's
    /// step). Returns the attitude once the filter has started (it starts at the first update
    /// with both an accelerometer and a magnetometer reading).
    #[inline(never)]
    pub fn update(
        &mut self,
        acc: &mut Accum,
        step: GyroStep,
        mag: Option<&[i32; 3]>,
        dt_us: u32,
    ) -> Option<Attitude> {
        // Half the rotation since the last update, body axes (sensor forward-left-up →
        // forward-right-down: the sign flips are free), Q30.
        // The sums clamped so that |sum · step| < 2^45: the half rotation stays below 2^29
        // (0.5 rad) in Q30, whatever the sums and the gyro's range.
        let bits = 32 - fixed::leading_zeros(step.0.unsigned_abs());
        let max = 1i32 << (45u32.saturating_sub(bits)).min(30);
        let g = acc.gyro.map(|s| mul_shr(s.clamp(-max, max), step.0, 16));
        let mut v = [g[0], -g[1], -g[2]];
        if acc.n > 0 {
            // The sum's scale does not matter: the direction is normalised below.
            self.accel = [
                acc.accel[0],
                acc.accel[1].wrapping_neg(),
                acc.accel[2].wrapping_neg(),
            ];
        }
        *acc = Accum::default();
        let m = mag.map(|m| [m[0], m[1].wrapping_neg(), m[2].wrapping_neg()]);
        if !self.started {
            if let (Some(m), true) = (m, self.accel != [0; 3]) {
                let (a_sum, m_sum, n) = &mut self.start_sums;
                for i in 0..3 {
                    a_sum[i] = a_sum[i].saturating_add(self.accel[i]);
                    m_sum[i] = m_sum[i].saturating_add(m[i]);
                }
                *n += 1;
                if *n >= START_UPDATES {
                    let (a, m, _) = self.start_sums;
                    self.start_sums = ([0; 3], [0; 3], 0);
                    self.start(&a, &m);
                }
            }
            return None;
        }
        let gains = if u64::from(dt_us) == imu_proto::MAG_PERIOD_US {
            MAG_GAINS
        } else {
            Gains::at(dt_us)
        };
        let [r1, r2, d] = self.rows;
        let d15 = d.map(|c| c >> 14);
        // Gravity: â × (−d) = d × â, Q30 (Q15 times Q15).
        let mut e = [0; 3];
        if let Some((a, _)) = norm15(self.accel) {
            // |a|² < 3·2^30 (each component below 2^15) and ≥ 2^28: 1/|a| = m·2^-s, s 30 or 31.
            let (im, is) = rsqrt(sum_sq(&a));
            let im = im as i32;
            // â in Q15: a · m · 2^-s · 2^15 (|a · m| < 2^31: |a_i| < 2^15, m < 2^16).
            let ah = a.map(|c| (c * im) >> (is - 15));
            e = [
                d15[1] * ah[2] - d15[2] * ah[1],
                d15[2] * ah[0] - d15[0] * ah[2],
                d15[0] * ah[1] - d15[1] * ah[0],
            ];
        }
        let mut state = AhrsState::Tracking;
        if let Some((m, sh)) = m.and_then(norm15) {
            // |m|² in [2^28, 3·2^30): 1/|m| = im·2^-is, is 30 or 31.
            let m2 = sum_sq(&m);
            let (im, is) = rsqrt(m2);
            // m·d in Q15 · m's units (< √3·2^30); sin δ = m·d/(|m| 2^15), Q30:
            // (m·d >> 16) · im · 2^(31 − is) (< 2^31 by the bound on m·d for each `is`).
            let md = m[0] * d15[0] + m[1] * d15[1] + m[2] * d15[2];
            let sin_dip = ((md >> 16) * im as i32) << (31 - is);
            state = self.check_field(m2, sh, im, is, sin_dip);
            if state == AhrsState::Tracking {
                // h = R̂ m, north and east: the heading error about the vertical, sin of the
                // angle of h's horizontal part from north.
                let hx = dot15(&r1, &m) >> 16;
                let hy = dot15(&r2, &m) >> 16;
                let h2 = (hx * hx + hy * hy) as u32;
                if h2 != 0 {
                    let (ih, js) = rsqrt(h2);
                    // −h_y/|h_xy| in Q30: h_y · ih · 2^(30 − js) (|h_y · ih| ≤ 2^js·(1 + 2·10⁻⁴)).
                    let p = -(hy * ih as i32);
                    let eh = if js >= 30 {
                        p >> (js - 30)
                    } else {
                        p << (30 - js)
                    };
                    let eh15 = eh >> 15;
                    for i in 0..3 {
                        e[i] += eh15 * d15[i];
                    }
                }
            }
        }
        // The correction, k_P e Δt/2, per axis, Q30.
        let c = e.map(|x| mul_shr(x, gains.kph_q32, 32));
        let learning = matches!(self.reference, Reference::Learning { .. });
        if self.converging || self.settle > 0 || learning {
            // The error smoothed (from the first update's on), then squared: the systematic
            // error, with the sensors' noise averaged down (|e|² ≤ 2: < 2^31 in Q30).
            if self.updates == 0 {
                self.err = e;
            }
            for (s, x) in self.err.iter_mut().zip(e) {
                *s = *s - (*s >> 4) + (x >> 4);
            }
            let e15 = self.err.map(|x| x >> 15);
            let [a, b, c] = e15.map(i32::unsigned_abs);
            let err2 = a * a + b * b + c * c;
            self.updates = self.updates.saturating_add(1);
            if self.converging {
                if self.updates >= MIN_CONVERGE_UPDATES && err2 < CONVERGED_ERR2_Q30 {
                    self.converging = false;
                    self.settle = SETTLE_UPDATES;
                }
            } else {
                // Settling: the tilt (the error across the body's down axis; |err·d| ≤ |err|).
                let along =
                    ((e15[0] * d15[0] + e15[1] * d15[1] + e15[2] * d15[2]) >> 15).unsigned_abs();
                if err2.saturating_sub(along * along) > REDIVERGED_ERR2_Q30 {
                    // Tilted again (a gyro bias's error building): converging again, and a
                    // learnt reference learnt afresh once converged, not from a tilted estimate.
                    self.converging = true;
                    self.settle = 0;
                    if self.reference_learnt() {
                        self.reference = LEARNING;
                    }
                } else {
                    self.settle = self.settle.saturating_sub(1);
                }
            }
        }
        // b̂ Δt/2 += kI e Δt · Δt/2 = (kI/kP) Δt · (kP e Δt/2); Q30 · Q34 >> 24 is Q40. Also
        // while converging: a bias leaves a steady error of b/kP that only the bias estimate
        // takes out, so a part with more than ≈ 2°/s left would otherwise never converge.
        for (b, c) in self.bias.iter_mut().zip(c) {
            *b = b
                .saturating_add(mul_shr(c, gains.kb_q34, 24))
                .clamp(-BIAS_MAX_Q40, BIAS_MAX_Q40);
        }
        // The bias is kept per magnetometer period: scaled only for an update without it.
        for i in 0..3 {
            let b = if mag.is_some() {
                self.bias[i] >> 10
            } else {
                mul_shr(self.bias[i], gains.ratio_q16, 26)
            };
            v[i] += c[i] + b;
        }
        let long = self.rotate(&v);
        // Back to unit norm by a Newton step from 1: every fourth update (each step grows |q|²
        // by |v|² ≲ 1e-5 at the rates the part measures), and after every update without the
        // magnetometer or with a long step.
        self.steps = self.steps.wrapping_add(1);
        if mag.is_none() || long || self.steps.is_multiple_of(RENORM_EVERY) {
            let n2: i64 = self.q.iter().map(|&c| mul_shr(c, c, 30) as i64).sum();
            let s = if long {
                // |q|² up to ≈ 1.4: 1/|q| by rsqrt (≤ 1.2·10⁻⁴), refined by the next steps.
                let (m, e) = rsqrt(n2.clamp(1, u32::MAX as i64) as u32);
                (m << (45 - e)) as i32
            } else {
                ((3 * ONE_Q30 as i64 - n2) / 2).clamp(0, i32::MAX as i64) as i32
            };
            self.q = self.q.map(|c| mul_shr(c, s, 30));
        }
        self.rows = rows(&self.q);
        if self.converging {
            state = AhrsState::Converging;
        }
        Some(self.attitude(state))
    }

    /// `q ← q + q ⊗ (0, v)`, `v` in Q30 (|v_i| < 2^30), in block floating point: `v` shifted
    /// right by `b` until its largest component fits 15 bits, the quaternion taken in Q15; each
    /// sum of three products is below 2^31 (Cauchy–Schwarz: |q| ≤ 2^15, |v| < √3·2^15) and is
    /// Q(45 − b), shifted to Q30.
    /// Returns whether the step was long (a component of `v` at or above 2^25, 0.03 rad: beyond
    /// the gyro's full scale over a magnetometer period), so that the caller renormalises at
    /// once and |q| stays near one whatever the sums.
    fn rotate(&mut self, v: &[i32; 3]) -> bool {
        let big = v[0].unsigned_abs() | v[1].unsigned_abs() | v[2].unsigned_abs();
        let b = 17u32.saturating_sub(fixed::leading_zeros(big));
        let s = 15 - b;
        let [v0, v1, v2] = v.map(|c| c >> b);
        let [w, x, y, z] = self.q;
        let [qw, qx, qy, qz] = self.q.map(|c| c >> 15);
        self.q = [
            w - ((qx * v0 + qy * v1 + qz * v2) >> s),
            x + ((qw * v0 + qy * v2 - qz * v1) >> s),
            y + ((qw * v1 - qx * v2 + qz * v0) >> s),
            z + ((qw * v2 + qx * v1 - qy * v0) >> s),
        ];
        b > 10
    }

    /// The field checks: `m2` is |m|² of the magnetometer reading shifted by `sh` bits
    /// ([`norm15`]), `1/|m| = im·2^-is` in those units, `sin_dip` in Q30; while learning, learn
    /// from tracking updates.
    fn check_field(&mut self, m2: u32, sh: i32, im: u32, is: u32, sin_dip: i32) -> AhrsState {
        let bands = match &mut self.reference {
            Reference::Known { bands, .. } => *bands,
            Reference::Learning { .. } => {
                if !self.converging {
                    self.learn(m2, sh, im, is, sin_dip);
                }
                return AhrsState::Tracking;
            }
        };
        // |m|² in input units squared.
        let m2 = if sh >= 0 {
            u64::from(m2 >> (2 * sh))
        } else {
            u64::from(m2) << (-2 * sh)
        };
        if m2 < bands.field2[0] || m2 > bands.field2[1] {
            AhrsState::MagField
        } else if sin_dip < bands.sin_dip[0] || sin_dip > bands.sin_dip[1] {
            AhrsState::MagDip
        } else {
            AhrsState::Tracking
        }
    }

    /// One tracking update's field for the learnt reference (arguments as for
    /// [`Ahrs::check_field`]); after [`LEARN_UPDATES`], the reference (once: `f64` and libm).
    #[inline(never)]
    fn learn(&mut self, m2: u32, sh: i32, im: u32, is: u32, sin_dip: i32) {
        let Reference::Learning {
            field,
            sin_dip: s,
            n,
        } = &mut self.reference
        else {
            return;
        };
        // |m| in input units, Q8: √m2 · 2^(8 − sh) = m2 · im · 2^(8 − sh − is).
        let r = is as i32 + sh - 8;
        let f = u64::from(m2) * u64::from(im);
        *field += if r >= 0 { f >> r } else { f << -r };
        *s += i64::from(sin_dip);
        *n += 1;
        if *n >= LEARN_UPDATES {
            // The means, the dip's cosine from its sine, the dip by atan2: integers only.
            let field_q8 = *field / u64::from(*n);
            let sin = (*s / i64::from(*n)).clamp(-(ONE_Q30 as i64), ONE_Q30 as i64) as i32;
            let c2 = (ONE_Q30 as i64 - ((i64::from(sin) * i64::from(sin)) >> 30)) as u64;
            let cos = (c2 << 30).isqrt() as i32;
            self.reference = Reference::Known {
                field: to_f32(field_q8.min(i32::MAX as u64) as i32, 8),
                dip_deg: to_f32(atan2(sin, cos), 20),
                bands: Bands::new(field_q8, sin, cos),
                learnt: true,
            };
        }
    }

    /// Roll, pitch, heading from the rotation's rows.
    #[inline(never)]
    fn attitude(&self, state: AhrsState) -> Attitude {
        let [r1, r2, d] = self.rows;
        let roll = atan2(d[1], d[2]);
        // cos θ = √(d₂² + d₃²) from the Q15 components (< 2^30 summed), back in Q29.
        let (d2, d3) = (d[1] >> 14, d[2] >> 14);
        let c2 = (d2 * d2 + d3 * d3) as u32;
        let cos = if c2 == 0 {
            0
        } else {
            let (m, s) = rsqrt(c2);
            mul_shr(c2 as i32, m as i32, s) << 14
        };
        let pitch = atan2(-d[0], cos);
        // h and the declination are within ±180°: one turn added or taken puts the sum in
        // [0°, 360°) (not a loop: the compiler makes a loop of these a division).
        let mut heading = atan2(r2[0], r1[0]) + self.declination_q20;
        if heading < 0 {
            heading += 360 * DEG_Q20;
        } else if heading >= 360 * DEG_Q20 {
            heading -= 360 * DEG_Q20;
        }
        Attitude {
            q: self.q.map(|c| to_f32(c, 30)),
            roll_deg: to_f32(roll, 20),
            pitch_deg: to_f32(pitch, 20),
            heading_deg: to_f32(heading, 20),
            state,
        }
    }

    /// The first attitude, from the accelerometer and magnetometer readings (body axes), in
    /// `f32` and libm once ([`initial_quaternion`]).
    #[inline(never)]
    fn start(&mut self, a: &[i32; 3], m: &[i32; 3]) {
        if let Some(q) = initial_quaternion(&a.map(|c| c as f32), &m.map(|c| c as f32)) {
            self.q = q.map(|c| libm::roundf(c * ONE_Q30 as f32) as i32);
            self.rows = rows(&self.q);
            self.started = true;
        }
    }
}

/// `|v|²` of a vector whose components are below 2^15 (< 3·2^30).
#[inline(always)]
fn sum_sq(v: &[i32; 3]) -> u32 {
    (v[0] * v[0]) as u32 + (v[1] * v[1]) as u32 + (v[2] * v[2]) as u32
}

/// A Q29 row (taken to Q15) dotted with a vector of components below 2^15: Q15 in the vector's
/// units, below √3·2^30 for a unit row.
#[inline(always)]
fn dot15(r: &[i32; 3], v: &[i32; 3]) -> i32 {
    (r[0] >> 14) * v[0] + (r[1] >> 14) * v[1] + (r[2] >> 14) * v[2]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::clock_keyed;

    #[test]
    fn the_dip_band_constants_are_its_sine_and_cosine() {
        let r = f64::from(DIP_BAND_DEG).to_radians();
        let q30 = |x: f64| libm::round(x * f64::from(ONE_Q30)) as i64;
        assert_eq!(SIN_DIP_BAND_Q30, q30(libm::sin(r)));
        assert_eq!(COS_DIP_BAND_Q30, q30(libm::cos(r)));
    }

    /// A learnt reference from its means in integers (square root, atan2, the bands) against
    /// libm: random |m|² and sines of the dip (drawn anew every run), the poles included.
    #[test]
    fn a_learnt_reference_is_libms() {
        let mut next = clock_keyed();
        for k in 0..2_000 {
            // |m|² as the update has it: [2^28, 3·2^30), shifted by `sh` from the input units.
            let m2 = (1u32 << 28) + (next() % (3 * (1u64 << 30) - (1 << 28))) as u32;
            let sh = (next() % 5) as i32 - 2;
            let sin = match k {
                0 => ONE_Q30,
                1 => -ONE_Q30,
                _ => (next() % (2 * ONE_Q30 as u64 + 1)) as i32 - ONE_Q30,
            };
            let (im, is) = fixed::rsqrt(m2);
            let mut a = Ahrs::new();
            a.converging = false;
            for _ in 0..LEARN_UPDATES {
                a.learn(m2, sh, im, is, sin);
            }
            let (field, dip) = a.reference().expect("learnt");
            let want_field = f64::from(m2).sqrt() * 2f64.powi(-sh);
            let want_dip = libm::asin(f64::from(sin) / f64::from(ONE_Q30)).to_degrees();
            assert!(
                (f64::from(field) / want_field - 1.0).abs() < 3e-4,
                "m2 {m2}, sh {sh}: {field} against {want_field}"
            );
            assert!(
                (f64::from(dip) - want_dip).abs() < 0.005,
                "sin {sin}: {dip}° against {want_dip}°"
            );
            let Reference::Known { bands, .. } = a.reference else {
                panic!("not learnt");
            };
            let edges = [1.0 - FIELD_BAND as f64, 1.0 + FIELD_BAND as f64];
            for (i, d) in [-1.0, 1.0].into_iter().enumerate() {
                let want = libm::sin((want_dip + d * 5.0).clamp(-90.0, 90.0).to_radians());
                let got = f64::from(bands.sin_dip[i]) / f64::from(ONE_Q30);
                assert!((got - want).abs() < 5e-7, "sin {sin}: {got} against {want}");
                let want = (want_field * edges[i]).powi(2);
                let r = bands.field2[i] as f64 / want;
                assert!((r - 1.0).abs() < 6e-4, "m2 {m2}, sh {sh}: {r}");
            }
        }
    }

    /// The integer bands against the same bands from libm, for random fields and dips (drawn
    /// anew every run), the poles included.
    #[test]
    fn the_integer_bands_are_libms() {
        let mut draw = clock_keyed();
        let mut next = || (draw() >> 11) as f64 / (1u64 << 53) as f64;
        for _ in 0..10_000 {
            let field = 100.0 + 20_000.0 * next();
            let dip = -90.0 + 180.0 * next();
            let b = Bands::set(field as f32, dip as f32);
            let f = field as f32 as f64;
            for (k, edge) in [(0, 1.0 - FIELD_BAND as f64), (1, 1.0 + FIELD_BAND as f64)] {
                let want = (f * edge) * (f * edge);
                assert!(
                    (b.field2[k] as f64 - want).abs() <= 1e-4 * want + 2.0,
                    "field {field}, edge {k}: {} against {want}",
                    b.field2[k]
                );
            }
            let dip = dip as f32 as f64;
            for (k, d) in [(0, dip - 5.0), (1, dip + 5.0)] {
                let want = libm::sin(d.clamp(-90.0, 90.0).to_radians());
                let got = f64::from(b.sin_dip[k]) / f64::from(ONE_Q30);
                assert!(
                    (got - want).abs() < 2e-7,
                    "dip {dip}, edge {k}: {got} against {want}"
                );
            }
        }
    }
}
