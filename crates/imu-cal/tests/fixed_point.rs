//! Fixed-point vs float corrections: ≤ 1 LSB over the whole i16 input range (the device's correction contract).
//!
//! The float reference is the correction with the *unquantised* f64 parameters,
//! `out = M·(raw − o)` (gyro: `o = b + k·(T − T_ref)`), rounded to the nearest count.
//! Tolerance: 1 LSB, from the bound in `device`'s docs (≤ 0.51 LSB from the exact value plus the
//! reference's own ≤ 0.5 LSB rounding). We also check the tighter |fixed − exact| ≤ 0.52 LSB.
#![allow(clippy::needless_range_loop)]
use imu_cal::device::{Affine, Calibration, GyroCorrection, Prepared, Sensor};
use proptest::prelude::*;

/// Parameters drawn over the ranges the device accepts: gains 0.5–1.6 on the diagonal,
/// off-diagonal up to ±0.3 (misalignment / soft iron), offsets up to ±3000 LSB.
#[derive(Debug, Clone)]
struct Params {
    m: [[f64; 3]; 3],
    o: [f64; 3],
    k: [f64; 3],
    t_ref: i16,
}

fn params() -> impl Strategy<Value = Params> {
    (
        proptest::array::uniform3(0.5f64..1.6),
        proptest::array::uniform6(-0.3f64..0.3),
        proptest::array::uniform3(-3000.0f64..3000.0),
        proptest::array::uniform3(-0.05f64..0.05),
        any::<i16>(),
    )
        .prop_map(|(d, off, o, k, t_ref)| Params {
            m: [
                [d[0], off[0], off[1]],
                [off[2], d[1], off[3]],
                [off[4], off[5], d[2]],
            ],
            o,
            k,
            t_ref,
        })
}

fn exact(p: &Params, raw: [i16; 3], dt: f64) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (i, o) in out.iter_mut().enumerate() {
        for j in 0..3 {
            *o += p.m[i][j] * (raw[j] as f64 - p.o[j] - p.k[j] * dt);
        }
    }
    out
}

fn check(fixed: [i32; 3], ex: [f64; 3], what: &str) {
    for i in 0..3 {
        let e = (fixed[i] as f64 - ex[i]).abs();
        assert!(
            e <= 0.52,
            "{what}: axis {i} fixed {} exact {} (err {e})",
            fixed[i],
            ex[i]
        );
        assert!((fixed[i] as f64 - ex[i].round()).abs() <= 1.0);
    }
}

/// Deterministic generator for the exhaustive sweeps (SplitMix64).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Exhaustive: for 8 parameter sets, every i16 value on each axis, with the other two axes at
/// random values and at the extremes (the error is a sum of per-axis terms, so sweeping each
/// axis over its whole range with the others at their extremes covers the worst cases).
#[test]
fn exhaustive_each_axis_full_i16_range() {
    let mut rng = Rng(0x5eed);
    for set in 0..8 {
        let mut m = [[0.0; 3]; 3];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = if i == j {
                    rng.uniform(0.5, 1.6)
                } else {
                    rng.uniform(-0.3, 0.3)
                };
            }
        }
        let p = Params {
            m,
            o: [0; 3].map(|_| rng.uniform(-3000.0, 3000.0)),
            k: [0; 3].map(|_| rng.uniform(-0.05, 0.05)),
            t_ref: (rng.next() as i16) / 2,
        };
        let acc = Affine::from_float(Sensor::Accel, p.m, p.o).unwrap();
        let gyr = GyroCorrection::from_float(p.m, p.o, p.k, p.t_ref).unwrap();
        let cal = Calibration::new(acc, gyr, acc).unwrap();
        for axis in 0..3 {
            for other in [i16::MIN, i16::MAX, 0, rng.next() as i16] {
                for v in i16::MIN..=i16::MAX {
                    let mut raw = [other; 3];
                    raw[axis] = v;
                    check(
                        cal.apply_accel(raw),
                        exact(&p, raw, 0.0),
                        &format!("set {set} accel"),
                    );
                }
            }
            // Temperature over its full range too (clamped difference, see GyroCorrection).
            let raw = [rng.next() as i16, rng.next() as i16, rng.next() as i16];
            for t in (i16::MIN..=i16::MAX).step_by(7) {
                let dt = (t as i32 - p.t_ref as i32).clamp(-32768, 32767) as f64;
                check(
                    cal.apply_gyro(raw, t),
                    exact(&p, raw, dt),
                    &format!("set {set} gyro"),
                );
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]
    #[test]
    fn random_params_and_inputs(p in params(), raw in proptest::array::uniform3(any::<i16>()), t in any::<i16>()) {
        let acc = Affine::from_float(Sensor::Accel, p.m, p.o).unwrap();
        let gyr = GyroCorrection::from_float(p.m, p.o, p.k, p.t_ref).unwrap();
        let cal = Calibration::new(acc, gyr, acc).unwrap();
        check(cal.apply_accel(raw), exact(&p, raw, 0.0), "accel");
        check(cal.apply_mag(raw), exact(&p, raw, 0.0), "mag");
        let dt = (t as i32 - p.t_ref as i32).clamp(-32768, 32767) as f64;
        check(cal.apply_gyro(raw, t), exact(&p, raw, dt), "gyro");
    }
}

/// Parameters outside the fixed-point range are refused, not silently wrapped.
#[test]
fn out_of_range_parameters_are_rejected() {
    let big = [[3.0, 0.9, 0.2], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    assert!(Affine::from_float(Sensor::Mag, big, [0.0; 3]).is_err());
    let id = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    assert!(Affine::from_float(Sensor::Accel, id, [70000.0, 0.0, 0.0]).is_err());
    assert!(Affine::from_float(Sensor::Accel, id, [f64::NAN, 0.0, 0.0]).is_err());
    assert!(GyroCorrection::from_float(id, [0.0; 3], [2.5, 0.0, 0.0], 0).is_err());
}

/// Coefficients at the edges of the accepted ranges (row gain 3.999, |c| just under 2¹⁶ LSB,
/// |κ| just under 2) with every sign combination and the extreme inputs: no i32 overflow
/// (this debug build would panic) and the same error bound.
#[test]
fn range_limits_do_not_overflow() {
    let mut ran = 0;
    for signs in 0..64u32 {
        let sg = |k: u32| if signs >> k & 1 == 1 { -1.0 } else { 1.0 };
        let g = 3.999 / 3.0;
        let m = [
            [sg(0) * g, sg(1) * g, sg(2) * g],
            [sg(3) * g, -sg(4) * g, sg(5) * g],
            [-sg(0) * g, sg(2) * g, -sg(5) * g],
        ];
        // o chosen so that c = M·o is close to ±65535 LSB on the first row.
        let o = [sg(0) * 16383.0, sg(1) * 16383.0, sg(2) * 16383.0];
        let k = [sg(3) * 0.499, sg(4) * 0.499, sg(5) * 0.499];
        let Ok(gyr) = GyroCorrection::from_float(m, o, k, 0) else {
            continue; // κ or c beyond the limit for this sign pattern: refused, fine.
        };
        let acc = Affine::from_float(Sensor::Accel, m, o).unwrap();
        let cal = Calibration::new(acc, gyr, acc).unwrap();
        let p = Params { m, o, k, t_ref: 0 };
        ran += 1;
        for a in [i16::MIN, -1, 0, i16::MAX] {
            for b in [i16::MIN, i16::MAX] {
                for t in [i16::MIN, 0, i16::MAX] {
                    let raw = [a, b, if signs % 2 == 0 { a } else { b }];
                    check(cal.apply_accel(raw), exact(&p, raw, 0.0), "limit accel");
                    check(
                        cal.apply_gyro(raw, t),
                        exact(&p, raw, t as f64),
                        "limit gyro",
                    );
                }
            }
        }
    }
    // c = 3.999·16383 < 2¹⁶ and |κ| ≤ 1.996 < 2 for every pattern: none may be refused.
    assert_eq!(ran, 64);
}

/// Parameters with some matrices diagonal (Jaime et al.'s accelerometer model and a bias-only gyro)
/// and some full, so both paths of the firmware's prepared form are exercised.
fn maybe_diagonal() -> impl Strategy<Value = Params> {
    (params(), any::<bool>()).prop_map(|(mut p, diagonal)| {
        if diagonal {
            for i in 0..3 {
                for j in 0..3 {
                    if i != j {
                        p.m[i][j] = 0.0;
                    }
                }
            }
        }
        p
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]
    /// The firmware applies `Prepared` (split coefficients, diagonal fast path): it must give
    /// exactly what `Calibration` gives, for every parameter set and input.
    #[test]
    fn the_prepared_form_is_bit_exact(
        p in maybe_diagonal(),
        raw in proptest::array::uniform3(any::<i16>()),
        t in any::<i16>(),
    ) {
        let acc = Affine::from_float(Sensor::Accel, p.m, p.o).unwrap();
        let gyr = GyroCorrection::from_float(p.m, p.o, p.k, p.t_ref).unwrap();
        let mag = Affine::from_float(Sensor::Mag, p.m, [0.0; 3]).unwrap();
        let cal = Calibration::new(acc, gyr, mag).unwrap();
        let fast = Prepared::new(&cal);
        prop_assert_eq!(fast.apply_accel(raw), cal.apply_accel(raw));
        prop_assert_eq!(fast.apply_gyro(raw, t), cal.apply_gyro(raw, t));
        prop_assert_eq!(fast.apply_mag(raw), cal.apply_mag(raw));
    }
}

/// The extremes of every input for a diagonal and a full matrix, and the identity.
#[test]
fn the_prepared_form_is_bit_exact_at_the_extremes() {
    let full = [[1.6, -0.3, 0.3], [0.3, 0.5, -0.3], [-0.3, 0.3, 1.6]];
    let diag = [[1.6, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 1.0001]];
    let mut cals = vec![Calibration::identity()];
    for m in [full, diag] {
        let acc = Affine::from_float(Sensor::Accel, m, [2999.5, -3000.0, 0.25]).unwrap();
        let gyr =
            GyroCorrection::from_float(m, [-100.0, 7.5, 3000.0], [0.05, -0.05, 0.0], -123).unwrap();
        cals.push(Calibration::new(acc, gyr, acc).unwrap());
    }
    let ends = [i16::MIN, -1, 0, 1, i16::MAX];
    let mut n = 0;
    for cal in &cals {
        let fast = Prepared::new(cal);
        for a in ends {
            for b in ends {
                for c in ends {
                    let raw = [a, b, c];
                    assert_eq!(fast.apply_accel(raw), cal.apply_accel(raw), "{raw:?}");
                    assert_eq!(fast.apply_mag(raw), cal.apply_mag(raw), "{raw:?}");
                    for t in ends {
                        assert_eq!(
                            fast.apply_gyro(raw, t),
                            cal.apply_gyro(raw, t),
                            "{raw:?} {t}"
                        );
                        n += 1;
                    }
                }
            }
        }
    }
    assert_eq!(n, 3 * 125 * 5);
}
