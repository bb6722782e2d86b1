//! The attitude filter in `f32` (micromath's approximations, soft float on the M0+): the
//! reference the device's integer filter ([`super::Ahrs`]) is tested against on the host
//! (`tests/ahrs.rs`), the same equations in the same order. Not on the device: an update costs
//! ≈ 30,000 cycles there (docs/benchmarks.md).
//!
//! # micromath and libm
//! The update uses micromath's f32 approximations where their error is far below what the
//! result needs, and the exact (libm) functions only off the hot path (configuration, the
//! initial attitude). The measured errors are in docs/firmware.md ("Orientation") and held by
//! the test `micromath_error_on_the_values_that_matter`:
//! * `invsqrt` + one Newton step (≤ 0.2 %) scales the accelerometer to unit length and gives
//!   |h_xy|, |m| and `cos θ` in the pitch;
//! * `atan2` (≤ 0.16°) for roll, pitch and heading;
//! * the quaternion (micromath's `Quaternion`: its norm and scaling) is renormalised by a
//!   Newton step from 1 (`q (3 − |q|²)/2`, error O((|q|² − 1)²)) every fourth update; the
//!   rotation step `q + q ⊗ (0, v)` is written out (12 products, where the general product
//!   with `(1, v)` takes 16).
//!   micromath's `asin` (atan of x/√(1−x²) with the raw `invsqrt`) errs by up to 0.8° at 60°
//!   of pitch, so pitch is `atan2(−r₃₁, √(r₃₂² + r₃₃²))` instead.
use super::{
    initial_quaternion, Accum, AhrsState, Attitude, CONVERGED_ERR2, DIP_BAND_DEG, FIELD_BAND, KI,
    KP, LEARN_UPDATES, MIN_CONVERGE_UPDATES, REDIVERGED_ERR2, RENORM_EVERY, SETTLE_UPDATES,
    START_UPDATES,
};
use micromath::{Quaternion, F32};

/// Expected field: bands on |B|² (input units squared) and on sin(dip).
#[derive(Debug, Clone, Copy)]
struct Bands {
    field2: [f32; 2],
    /// The dip band's edges as `s·|s|`, `s = sin δ`: compared with `(m·d)·|m·d|/|m|²`, which
    /// needs no square root (`x·|x|` is monotonic).
    sin_dip_sq: [f32; 2],
}

impl Bands {
    fn new(field: f32, dip_deg: f32) -> Bands {
        let lo = field * (1.0 - FIELD_BAND);
        let hi = field * (1.0 + FIELD_BAND);
        let d = |x: f32| libm::sinf(x.clamp(-90.0, 90.0).to_radians());
        Bands {
            field2: [lo * lo, hi * hi],
            sin_dip_sq: [d(dip_deg - DIP_BAND_DEG), d(dip_deg + DIP_BAND_DEG)].map(|s| s * s.abs()),
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
    /// Updates since the start, for the renormalisation's turn.
    steps: u32,
    /// The rotation's rows for `q` ([`rows`]).
    rows: [[f32; 3]; 3],
    /// Gyro bias estimate times half the magnetometer's period, rad (body).
    bias_h: [f32; 3],
    started: bool,
    /// Before the start: the sums of the updates' readings so far, and how many.
    start_sums: ([f32; 3], [f32; 3], u32),
    converging: bool,
    /// Updates left of the watch after converging.
    settle: u32,
    updates: u32,
    /// The correction's error, smoothed over ≈ 16 updates.
    err: [f32; 3],
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

/// The bias estimate's bound, rad per half magnetometer period (the integer filter's: 22°/s).
const BIAS_MAX: f32 = 1.0 / 1024.0;
/// The magnetometer's period, s: the step the bias estimate is kept in.
const MAG_DT: f32 = imu_proto::MAG_PERIOD_US as f32 * 1e-6;

/// The first three rows of the body → NED rotation of a unit quaternion (the body's north,
/// east and down axes): 9 products, 15 sums.
fn rows(q: &Quaternion) -> [[f32; 3]; 3] {
    let (w, x, y, z) = (q.w(), q.x(), q.y(), q.z());
    let (x2, y2, z2) = (x + x, y + y, z + z);
    let (xx, yy, zz) = (x * x2, y * y2, z * z2);
    let (xy, xz, yz) = (x * y2, x * z2, y * z2);
    let (wx, wy, wz) = (w * x2, w * y2, w * z2);
    [
        [1.0 - yy - zz, xy - wz, xz + wy],
        [xy + wz, 1.0 - xx - zz, yz - wx],
        [xz - wy, yz + wx, 1.0 - xx - yy],
    ]
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
            steps: 0,
            rows: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            bias_h: [0.0; 3],
            started: false,
            start_sums: ([0.0; 3], [0.0; 3], 0),
            converging: true,
            settle: 0,
            updates: 0,
            err: [0.0; 3],
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
                let s = b.sin_dip_sq[0];
                let lo = libm::copysignf(libm::sqrtf(s.abs()), s);
                Some((field, libm::asinf(lo).to_degrees() + DIP_BAND_DEG))
            }
            Reference::Learning { .. } => None,
        }
    }

    /// Whether the expected field is (or is being) learnt rather than the host's.
    pub fn reference_learnt(&self) -> bool {
        !matches!(self.reference, Reference::Set { .. })
    }

    /// The attitude now.
    pub fn quaternion(&self) -> [f32; 4] {
        self.q.to_array()
    }

    /// As [`super::Ahrs::convergence_errors2`].
    pub fn convergence_errors2(&self) -> (f32, f32) {
        let d = self.rows[2];
        let e2: f32 = self.err.iter().map(|x| x * x).sum();
        let along = self.err[0] * d[0] + self.err[1] * d[1] + self.err[2] * d[2];
        (e2, e2 - along * along)
    }

    /// One update. `acc`: the IMU sums since the last update (emptied); `rad_per_count`: gyro
    /// count × sample period → rad; `mag`: corrected magnetometer counts (sensor axes), `None`
    /// for an update without it; `dt`: the time since the last update, s (the correction's
    /// step). Returns the attitude once the filter has started (it starts at the first update
    /// with both an accelerometer and a magnetometer reading).
    ///
    /// Soft float on the M0+ (≈ 150 cycles an operation in the emulator): the rotation's rows
    /// are kept from the previous update, the gains are folded into the constants, and the
    /// convergence and learning sums only run while they are needed.
    pub fn update(
        &mut self,
        acc: &mut Accum,
        rad_per_count: f32,
        mag: Option<&[i32; 3]>,
        dt: f32,
    ) -> Option<Attitude> {
        // Half the rotation since the last update, body axes (sensor forward-left-up →
        // forward-right-down: the sign flips are free).
        let k = 0.5 * rad_per_count;
        let mut v = [
            acc.gyro[0] as f32 * k,
            -(acc.gyro[1] as f32 * k),
            -(acc.gyro[2] as f32 * k),
        ];
        if acc.n > 0 {
            // The sum's scale does not matter: the direction is normalised below.
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
                let (a_sum, m_sum, n) = &mut self.start_sums;
                for i in 0..3 {
                    a_sum[i] += self.accel[i];
                    m_sum[i] += m[i];
                }
                *n += 1;
                if *n >= START_UPDATES {
                    let (a, m, _) = self.start_sums;
                    self.start_sums = ([0.0; 3], [0.0; 3], 0);
                    self.start(&a, &m);
                }
            }
            return None;
        }
        let a = self.accel;
        let [r1, r2, d] = self.rows;
        // Gravity: â × (−d) = (d × a)/|a|; the gain and the half step folded into one factor.
        let kph = 0.5 * KP * dt;
        let da = [
            d[1] * a[2] - d[2] * a[1],
            d[2] * a[0] - d[0] * a[2],
            d[0] * a[1] - d[1] * a[0],
        ];
        let ca = kph * inv_sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
        let mut cm = 0.0;
        let mut state = AhrsState::Tracking;
        if let Some(m) = m {
            let m2 = m[0] * m[0] + m[1] * m[1] + m[2] * m[2];
            let md = m[0] * d[0] + m[1] * d[1] + m[2] * d[2];
            state = self.check_field(m2, md);
            if state == AhrsState::Tracking {
                // h = R̂ m, north and east: the heading error about the vertical, sin of the
                // angle of h's horizontal part from north (its scale only scales the gain).
                let hx = r1[0] * m[0] + r1[1] * m[1] + r1[2] * m[2];
                let hy = r2[0] * m[0] + r2[1] * m[1] + r2[2] * m[2];
                cm = -hy * kph * inv_sqrt(hx * hx + hy * hy);
            }
        }
        // The correction, kP e Δt/2, per axis.
        let c = [0, 1, 2].map(|i| ca * da[i] + cm * d[i]);
        let learning = matches!(self.reference, Reference::Learning { .. });
        if self.converging || self.settle > 0 || learning {
            // The error smoothed (from the first update's on), then squared.
            let e = c.map(|x| x * (1.0 / kph));
            if self.updates == 0 {
                self.err = e;
            }
            for (s, x) in self.err.iter_mut().zip(e) {
                *s += (x - *s) * (1.0 / 16.0);
            }
            let err2 = self.err.iter().map(|x| x * x).sum::<f32>();
            self.updates = self.updates.saturating_add(1);
            if self.converging {
                if self.updates >= MIN_CONVERGE_UPDATES && err2 < CONVERGED_ERR2 {
                    self.converging = false;
                    self.settle = SETTLE_UPDATES;
                }
            } else {
                // As [`super::Ahrs::update`]: the tilt past its threshold while settling,
                // converging again, a learnt reference learnt afresh.
                let along = self.err[0] * d[0] + self.err[1] * d[1] + self.err[2] * d[2];
                if err2 - along * along > REDIVERGED_ERR2 {
                    self.converging = true;
                    self.settle = 0;
                    if self.reference_learnt() {
                        self.reference = Reference::Learning {
                            field: 0.0,
                            sin_dip: 0.0,
                            n: 0,
                        };
                    }
                } else {
                    self.settle = self.settle.saturating_sub(1);
                }
            }
        }
        // b̂ Δt/2 += kI e Δt · Δt/2 = (kI/kP) Δt · (kP e Δt/2), while converging too, with the
        // integer filter's bounds (its step taken as at most 110 ms, |b̂ Δt/2| ≤ 2⁻¹⁰ rad).
        let kb = (KI / KP) * dt.min(0.11);
        for (b, c) in self.bias_h.iter_mut().zip(c) {
            *b = (*b + kb * c).clamp(-BIAS_MAX, BIAS_MAX);
        }
        // The bias is kept per magnetometer period: scaled only for an update without it.
        let bias = if mag.is_some() {
            self.bias_h
        } else {
            self.bias_h.map(|b| b * (dt * (1.0 / MAG_DT)))
        };
        for i in 0..3 {
            v[i] += c[i] + bias[i];
        }
        // q ← q + q ⊗ (0, v), then back to unit norm by a Newton step from 1: every fourth
        // update (each step grows |q|² by |v|² ≲ 1e-5 at the rates the part measures), and
        // after every update without the magnetometer (a longer step).
        let (w, x, y, z) = (self.q.w(), self.q.x(), self.q.y(), self.q.z());
        let q = Quaternion::new(
            w - x * v[0] - y * v[1] - z * v[2],
            x + w * v[0] + y * v[2] - z * v[1],
            y + w * v[1] - x * v[2] + z * v[0],
            z + w * v[2] + x * v[1] - y * v[0],
        );
        self.steps = self.steps.wrapping_add(1);
        self.q = if mag.is_none() || self.steps.is_multiple_of(RENORM_EVERY) {
            q * (1.5 - 0.5 * q.norm())
        } else {
            q
        };
        self.rows = rows(&self.q);
        if self.converging {
            state = AhrsState::Converging;
        }
        Some(self.attitude(state))
    }

    /// The field checks on |m|² and m·d (d the body's down axis); while learning, learn from
    /// tracking updates.
    fn check_field(&mut self, m2: f32, md: f32) -> AhrsState {
        let bands = match &mut self.reference {
            Reference::Set { bands, .. } | Reference::Learnt(bands) => *bands,
            Reference::Learning { field, sin_dip, n } => {
                if !self.converging {
                    let inv = inv_sqrt(m2);
                    *field += m2 * inv;
                    *sin_dip += md * inv;
                    *n += 1;
                    if *n >= LEARN_UPDATES {
                        let k = 1.0 / *n as f32;
                        let dip = libm::asinf((*sin_dip * k).clamp(-1.0, 1.0)).to_degrees();
                        self.reference = Reference::Learnt(Bands::new(*field * k, dip));
                    }
                }
                return AhrsState::Tracking;
            }
        };
        if m2 < bands.field2[0] || m2 > bands.field2[1] {
            return AhrsState::MagField;
        }
        // sin δ = m·d/|m| within [lo, hi] ⟺ (m·d)|m·d| within [lo|lo|, hi|hi|]·|m|².
        let md2 = md * md.abs();
        if md2 < bands.sin_dip_sq[0] * m2 || md2 > bands.sin_dip_sq[1] * m2 {
            AhrsState::MagDip
        } else {
            AhrsState::Tracking
        }
    }

    /// Roll, pitch, heading from the rotation's rows.
    fn attitude(&self, state: AhrsState) -> Attitude {
        let [r1, r2, d] = self.rows;
        let c2 = d[1] * d[1] + d[2] * d[2];
        let mut heading = atan2_deg(r2[0], r1[0]) + self.declination_deg;
        if heading < 0.0 {
            heading += 360.0;
        } else if heading >= 360.0 {
            heading -= 360.0;
        }
        Attitude {
            q: self.q.to_array(),
            roll_deg: atan2_deg(d[1], d[2]),
            pitch_deg: atan2_deg(-d[0], c2 * inv_sqrt(c2)),
            heading_deg: heading,
            state,
        }
    }

    /// The first attitude, from one accelerometer and one magnetometer reading (body axes).
    fn start(&mut self, a: &[f32; 3], m: &[f32; 3]) {
        if let Some([w, x, y, z]) = initial_quaternion(a, m) {
            self.q = Quaternion::new(w, x, y, z);
            self.rows = rows(&self.q);
            self.started = true;
        }
    }
}
