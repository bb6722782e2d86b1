//! Attitude and heading on the device (AHRS): Mahony's explicit complementary filter on the
//! calibrated samples — R. Mahony, T. Hamel, J.-M. Pflimlin, "Nonlinear Complementary Filters on
//! the Special Orthogonal Group", IEEE Transactions on Automatic Control 53(5), 2008 (the
//! "explicit complementary filter with bias correction", its eq. (32) in quaternion form).
//!
//! # What runs where
//! * the 1 kHz path only sums the corrected gyro and accelerometer counts ([`Accum::add`]: seven
//!   integer adds a sample);
//! * one filter update per magnetometer sample (200 Hz): the summed gyro is the rotation since
//!   the last update (`Σ g · T`, the IMU's measured period), the mean accelerometer and the
//!   magnetometer reading correct it; when no magnetometer sample comes for
//!   [`MAX_SUM`] IMU samples, the IMU path runs an update without it (the sums stay bounded).
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
//! # micromath and libm
//! The update uses micromath's f32 approximations where their error is far below what the
//! result needs, and the exact (libm) functions only off the hot path (configuration, the
//! initial attitude). The measured errors are in docs/firmware.md ("Orientation") and held by
//! the test `micromath_error_on_the_values_that_matter`:
//! * `invsqrt` (a bit trick, ≤ 3.5 % error) scales the accelerometer to unit length: its error
//!   only scales the correction gain;
//! * `invsqrt` + one Newton step for `cos θ` in the pitch and for |h_xy| and |m| (≤ 0.2 %);
//! * `atan2` (≤ 0.16°) for roll, pitch and heading;
//! * the quaternion (micromath's `Quaternion`: the product and the scaling) is renormalised by a
//!   Newton step from 1 (`q (3 − |q|²)/2`, error O((|q|² − 1)²), ≈ 1e-7 at 200 Hz).
//!   micromath's `asin` (atan of x/√(1−x²) with the raw `invsqrt`) errs by up to 0.8° at 60°
//!   of pitch, so pitch is `atan2(−r₃₁, √(r₃₂² + r₃₃²))` instead.
use micromath::{Quaternion, F32};

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
/// Converged: the smoothed squared error (sine of the angle between measured and estimated
/// directions, squared) below sin²(2°), and at least this many updates since the start.
const CONVERGED_ERR2: f32 = 1.2e-3;
const MIN_CONVERGE_UPDATES: u32 = 50;
/// IMU samples summed at most before an update without the magnetometer (100 ms at 1 kHz;
/// full-scale counts × this stay far inside i32).
pub const MAX_SUM: u32 = 100;

/// What the filter reports with each attitude.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AhrsState {
    /// Since the start (or a new calibration): the estimate is still pulling in.
    Converging,
    /// Tracking, the magnetometer within its expected band.
    Tracking,
    /// |B| outside its band: heading from the gyro alone.
    MagField,
    /// The dip outside its band: heading from the gyro alone.
    MagDip,
}

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

/// Expected field: bands on |B|² (input units squared) and on sin(dip).
#[derive(Debug, Clone, Copy)]
struct Bands {
    field2: [f32; 2],
    sin_dip: [f32; 2],
}

impl Bands {
    fn new(field: f32, dip_deg: f32) -> Bands {
        let lo = field * (1.0 - FIELD_BAND);
        let hi = field * (1.0 + FIELD_BAND);
        let d = |x: f32| libm::sinf(x.clamp(-90.0, 90.0).to_radians());
        Bands {
            field2: [lo * lo, hi * hi],
            sin_dip: [d(dip_deg - DIP_BAND_DEG), d(dip_deg + DIP_BAND_DEG)],
        }
    }
}

/// Where the expected field comes from.
#[derive(Debug, Clone, Copy)]
enum Reference {
    /// Learning: sums of |B| and sin(dip) over `n` tracking updates.
    Learning {
        field: f32,
        sin_dip: f32,
        n: u32,
    },
    Learnt(Bands),
    /// Set by the host (field in the input units, dip in degrees).
    Set {
        field: f32,
        dip_deg: f32,
        bands: Bands,
    },
}

/// The filter.
#[derive(Debug, Clone)]
pub struct Ahrs {
    q: Quaternion,
    /// Gyro bias estimate, rad/s (body).
    bias: [f32; 3],
    started: bool,
    converging: bool,
    updates: u32,
    err2: f32,
    /// Mean accelerometer of the latest update (body), for updates with no new IMU sample.
    accel: [f32; 3],
    have_accel: bool,
    declination_deg: f32,
    reference: Reference,
}

impl Default for Ahrs {
    fn default() -> Self {
        Self::new()
    }
}

/// `1/√x` to ≈ 0.2 %: micromath's bit-trick guess and one Newton step.
#[inline(always)]
fn inv_sqrt(x: f32) -> f32 {
    let y = F32(x).invsqrt().0;
    y * (1.5 - 0.5 * x * y * y)
}

#[inline(always)]
fn atan2_deg(y: f32, x: f32) -> f32 {
    F32(y).atan2(F32(x)).0 * (180.0 / core::f32::consts::PI)
}

impl Ahrs {
    pub fn new() -> Self {
        Ahrs {
            q: Quaternion::IDENTITY,
            bias: [0.0; 3],
            started: false,
            converging: true,
            updates: 0,
            err2: 1.0,
            accel: [0.0; 3],
            have_accel: false,
            declination_deg: 0.0,
            reference: Reference::Learning {
                field: 0.0,
                sin_dip: 0.0,
                n: 0,
            },
        }
    }

    /// Start over (a new calibration): attitude from the next readings, a learnt reference
    /// learnt again; the declination and a host's reference stay.
    pub fn reset(&mut self) {
        let keep = (self.declination_deg, self.reference);
        *self = Ahrs::new();
        self.declination_deg = keep.0;
        if let Reference::Set { .. } = keep.1 {
            self.reference = keep.1;
        }
    }

    /// Declination (true north = magnetic north + this), degrees, added to the heading.
    pub fn set_declination(&mut self, deg: f32) {
        self.declination_deg = deg;
    }

    pub fn declination(&self) -> f32 {
        self.declination_deg
    }

    /// The expected field: strength in the magnetometer's input units and dip in degrees
    /// (positive down); `None` learns it again from the next converged second.
    pub fn set_reference(&mut self, field_dip: Option<(f32, f32)>) {
        self.reference = match field_dip {
            Some((field, dip_deg)) => Reference::Set {
                field,
                dip_deg,
                bands: Bands::new(field, dip_deg),
            },
            None => Reference::Learning {
                field: 0.0,
                sin_dip: 0.0,
                n: 0,
            },
        };
    }

    /// The expected field (strength, dip in degrees) in use, if known yet.
    pub fn reference(&self) -> Option<(f32, f32)> {
        match self.reference {
            Reference::Set { field, dip_deg, .. } => Some((field, dip_deg)),
            Reference::Learnt(b) => {
                let field = libm::sqrtf(b.field2[0]) / (1.0 - FIELD_BAND);
                let dip = libm::asinf(b.sin_dip[0]).to_degrees() + DIP_BAND_DEG;
                Some((field, dip))
            }
            Reference::Learning { .. } => None,
        }
    }

    /// The attitude now.
    pub fn quaternion(&self) -> [f32; 4] {
        self.q.to_array()
    }

    /// One update. `acc`: the IMU sums since the last update (emptied); `rad_per_count`: gyro
    /// count × sample period → rad; `mag`: corrected magnetometer counts (sensor axes), `None`
    /// for an update without it; `dt`: the time since the last update, s (the correction's
    /// step). Returns the attitude once the filter has started (it starts at the first update
    /// with both an accelerometer and a magnetometer reading).
    pub fn update(
        &mut self,
        acc: &mut Accum,
        rad_per_count: f32,
        mag: Option<&[i32; 3]>,
        dt: f32,
    ) -> Option<Attitude> {
        // Sensor (forward-left-up) → body (forward-right-down).
        let dtheta = [
            acc.gyro[0] as f32 * rad_per_count,
            -(acc.gyro[1] as f32) * rad_per_count,
            -(acc.gyro[2] as f32) * rad_per_count,
        ];
        if acc.n > 0 {
            // The mean's scale does not matter: the direction is normalised below.
            self.accel = [
                acc.accel[0] as f32,
                -(acc.accel[1] as f32),
                -(acc.accel[2] as f32),
            ];
            self.have_accel = true;
        }
        *acc = Accum::default();
        let m = mag.map(|m| [m[0] as f32, -(m[1] as f32), -(m[2] as f32)]);
        if !self.started {
            if let (Some(m), true) = (m, self.have_accel) {
                self.start(&self.accel.clone(), &m);
            }
            return None;
        }
        let a = self.accel;
        let (w, x, y, z) = (self.q.w(), self.q.x(), self.q.y(), self.q.z());
        // The body's down axis, R̂ᵀe_z (third row of R̂).
        let d = [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ];
        // Gravity: â × (−d).
        let na = F32(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).invsqrt().0;
        let ua = [a[0] * na, a[1] * na, a[2] * na];
        let mut e = [
            ua[2] * d[1] - ua[1] * d[2],
            ua[0] * d[2] - ua[2] * d[0],
            ua[1] * d[0] - ua[0] * d[1],
        ];
        let mut err2 = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
        let mut state = AhrsState::Tracking;
        if let Some(m) = m {
            let m2 = m[0] * m[0] + m[1] * m[1] + m[2] * m[2];
            let inv_m = inv_sqrt(m2);
            let sin_dip = (m[0] * d[0] + m[1] * d[1] + m[2] * d[2]) * inv_m;
            state = self.check_field(m2, inv_m, sin_dip);
            if state == AhrsState::Tracking {
                // h = R̂ m, its north and east components.
                let hx = (1.0 - 2.0 * (y * y + z * z)) * m[0]
                    + 2.0 * (x * y - w * z) * m[1]
                    + 2.0 * (x * z + w * y) * m[2];
                let hy = 2.0 * (x * y + w * z) * m[0]
                    + (1.0 - 2.0 * (x * x + z * z)) * m[1]
                    + 2.0 * (y * z - w * x) * m[2];
                let s = -hy * inv_sqrt(hx * hx + hy * hy);
                e = [e[0] + s * d[0], e[1] + s * d[1], e[2] + s * d[2]];
                err2 += s * s;
            }
        }
        // The smoothed error starts at the first update's.
        if self.updates == 0 {
            self.err2 = err2;
        }
        self.updates = self.updates.saturating_add(1);
        self.err2 += (err2 - self.err2) * (1.0 / 16.0);
        if self.converging && self.updates >= MIN_CONVERGE_UPDATES && self.err2 < CONVERGED_ERR2 {
            self.converging = false;
        }
        if !self.converging {
            for (b, e) in self.bias.iter_mut().zip(e) {
                *b += KI * e * dt;
            }
        }
        let h = 0.5;
        let step = Quaternion::new(
            1.0,
            h * (dtheta[0] + (KP * e[0] + self.bias[0]) * dt),
            h * (dtheta[1] + (KP * e[1] + self.bias[1]) * dt),
            h * (dtheta[2] + (KP * e[2] + self.bias[2]) * dt),
        );
        let q = self.q * step;
        self.q = q * (1.5 - 0.5 * q.norm());
        if self.converging {
            state = AhrsState::Converging;
        }
        Some(self.attitude(state))
    }

    /// The field checks; while learning, learn from tracking updates.
    fn check_field(&mut self, m2: f32, inv_m: f32, sin_dip: f32) -> AhrsState {
        let bands = match &mut self.reference {
            Reference::Set { bands, .. } | Reference::Learnt(bands) => *bands,
            Reference::Learning {
                field,
                sin_dip: s,
                n,
            } => {
                if !self.converging {
                    *field += m2 * inv_m;
                    *s += sin_dip;
                    *n += 1;
                    if *n >= LEARN_UPDATES {
                        let k = 1.0 / *n as f32;
                        let dip = libm::asinf((*s * k).clamp(-1.0, 1.0)).to_degrees();
                        self.reference = Reference::Learnt(Bands::new(*field * k, dip));
                    }
                }
                return AhrsState::Tracking;
            }
        };
        if m2 < bands.field2[0] || m2 > bands.field2[1] {
            AhrsState::MagField
        } else if sin_dip < bands.sin_dip[0] || sin_dip > bands.sin_dip[1] {
            AhrsState::MagDip
        } else {
            AhrsState::Tracking
        }
    }

    /// Roll, pitch, heading from the quaternion.
    fn attitude(&self, state: AhrsState) -> Attitude {
        let (w, x, y, z) = (self.q.w(), self.q.x(), self.q.y(), self.q.z());
        let r31 = 2.0 * (x * z - w * y);
        let r32 = 2.0 * (y * z + w * x);
        let r33 = 1.0 - 2.0 * (x * x + y * y);
        let r21 = 2.0 * (x * y + w * z);
        let r11 = 1.0 - 2.0 * (y * y + z * z);
        let c2 = r32 * r32 + r33 * r33;
        let mut heading = atan2_deg(r21, r11) + self.declination_deg;
        if heading < 0.0 {
            heading += 360.0;
        } else if heading >= 360.0 {
            heading -= 360.0;
        }
        Attitude {
            q: [w, x, y, z],
            roll_deg: atan2_deg(r32, r33),
            pitch_deg: atan2_deg(-r31, c2 * inv_sqrt(c2)),
            heading_deg: heading,
            state,
        }
    }

    /// The first attitude, from one accelerometer and one magnetometer reading (body axes):
    /// down = −â, east = down × m, north = east × down, as the rows of R; then the quaternion
    /// of R (exact functions: once per start).
    fn start(&mut self, a: &[f32; 3], m: &[f32; 3]) {
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
        let Some(down) = unit(a.map(|c| -c)) else {
            return;
        };
        let Some(east) = unit(cross(down, *m)) else {
            return;
        };
        let north = cross(east, down);
        let r = [north, east, down];
        let tr = r[0][0] + r[1][1] + r[2][2];
        let q = if tr > 0.0 {
            let s = 2.0 * libm::sqrtf(1.0 + tr);
            Quaternion::new(
                s / 4.0,
                (r[2][1] - r[1][2]) / s,
                (r[0][2] - r[2][0]) / s,
                (r[1][0] - r[0][1]) / s,
            )
        } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
            let s = 2.0 * libm::sqrtf(1.0 + r[0][0] - r[1][1] - r[2][2]);
            Quaternion::new(
                (r[2][1] - r[1][2]) / s,
                s / 4.0,
                (r[0][1] + r[1][0]) / s,
                (r[0][2] + r[2][0]) / s,
            )
        } else if r[1][1] > r[2][2] {
            let s = 2.0 * libm::sqrtf(1.0 + r[1][1] - r[0][0] - r[2][2]);
            Quaternion::new(
                (r[0][2] - r[2][0]) / s,
                (r[0][1] + r[1][0]) / s,
                s / 4.0,
                (r[1][2] + r[2][1]) / s,
            )
        } else {
            let s = 2.0 * libm::sqrtf(1.0 + r[2][2] - r[0][0] - r[1][1]);
            Quaternion::new(
                (r[1][0] - r[0][1]) / s,
                (r[0][2] + r[2][0]) / s,
                (r[1][2] + r[2][1]) / s,
                s / 4.0,
            )
        };
        let n = libm::sqrtf(q.norm());
        if n.is_finite() && n > 0.0 {
            self.q = q * (1.0 / n);
            self.started = true;
        }
    }
}
