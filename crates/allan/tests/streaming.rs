//! The streaming engine against the host estimators:
//! * bit for bit against the batch stride estimator (`stride_sums`) on random streams, lengths,
//!   gaps, resets and full-scale inputs;
//! * against the exact batch OADEV/OHDEV for m ≤ P;
//! * the overflow argument for 30 days at 1 kHz of full-scale 16-bit input;
//! * the memory budget.
use allan::batch::{deviation, stride_sums, Stat, TauSet};
use allan::{DeviceEngine, Engine, LevelSums, MagEngine};
use proptest::prelude::*;

fn run<const P: usize, const L: usize, const R: usize, const S: usize>(
    segments: &[Vec<i32>],
) -> Engine<P, L, R, S> {
    let mut e = Engine::<P, L, R, S>::new();
    for (i, seg) in segments.iter().enumerate() {
        if i > 0 {
            e.gap();
        }
        for &y in seg {
            e.push(y);
        }
    }
    e
}

fn host<const P: usize>(segments: &[Vec<i32>], levels: usize) -> Vec<LevelSums> {
    let refs: Vec<&[i32]> = segments.iter().map(|s| s.as_slice()).collect();
    stride_sums(&refs, P, levels)
}

/// The next word of a xorshift32 generator (deterministic pseudo-random inputs).
fn xorshift(s: &mut u32) -> u32 {
    *s ^= *s << 13;
    *s ^= *s >> 17;
    *s ^= *s << 5;
    *s
}

fn sample() -> impl Strategy<Value = i32> {
    prop_oneof![
        4 => -2000i32..2000,
        1 => Just(i32::MAX),
        1 => Just(i32::MIN),
        1 => Just(i16::MAX as i32),
        1 => Just(i16::MIN as i32),
        2 => any::<i32>(),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, .. ProptestConfig::default() })]

    #[test]
    fn engine_equals_host_stride_estimator(segments in prop::collection::vec(prop::collection::vec(sample(), 0..3000), 1..4)) {
        let e = run::<8, 12, 12, 8>(&segments);
        prop_assert_eq!(&e.levels().collect::<Vec<_>>()[..], &host::<8>(&segments, 12)[..]);
        let e = run::<2, 10, 3, 8>(&segments);
        prop_assert_eq!(&e.levels().collect::<Vec<_>>()[..], &host::<2>(&segments, 10)[..]);
        let e = run::<4, 11, 6, 8>(&segments);
        prop_assert_eq!(&e.levels().collect::<Vec<_>>()[..], &host::<4>(&segments, 11)[..]);
    }

    /// The engine's fast path keeps only the low words of the recent phase while every input
    /// is below 2^(30 − log2(P) − 1), and rewrites them as full values when a larger input
    /// first arrives: inputs right at that edge, and a large one arriving late (base ring full,
    /// strided levels running), must not change a bit.
    #[test]
    fn inputs_at_the_narrow_edge_and_late_large_inputs(
        prefix in prop::collection::vec(-3000i32..3000, 0..1500),
        edge_signs in prop::collection::vec(any::<bool>(), 0..1500),
        tail in prop::collection::vec(sample(), 0..600),
    ) {
        fn edge(limit: i32, signs: &[bool]) -> Vec<i32> {
            signs.iter().map(|&s| if s { limit - 1 } else { 1 - limit }).collect()
        }
        // 2^(30 − K0): K0 = 4, 3, 2 for P = 8, 4, 2.
        for (limit, p) in [(1i32 << 26, 8usize), (1 << 27, 4), (1 << 28, 2)] {
            let mut y = prefix.clone();
            y.extend(edge(limit, &edge_signs));
            y.extend(&tail);
            let segments = vec![y.clone(), y];
            let got: Vec<LevelSums> = match p {
                8 => run::<8, 12, 12, 8>(&segments).levels().collect(),
                4 => run::<4, 11, 6, 8>(&segments).levels().collect(),
                _ => run::<2, 10, 3, 8>(&segments).levels().collect(),
            };
            let want = match p {
                8 => host::<8>(&segments, 12),
                4 => host::<4>(&segments, 11),
                _ => host::<2>(&segments, 10),
            };
            prop_assert_eq!(&got[..], &want[..], "P = {}", p);
        }
    }

    #[test]
    fn reset_forgets_everything(before in prop::collection::vec(sample(), 0..2000), after in prop::collection::vec(sample(), 0..2000)) {
        let mut e = DeviceEngine::new();
        for &y in &before { e.push(y); }
        e.reset();
        for &y in &after { e.push(y); }
        prop_assert_eq!(&e.levels().collect::<Vec<_>>()[..], &host::<8>(std::slice::from_ref(&after), 24)[..]);
        prop_assert_eq!(e.samples(), after.len() as u64);
    }

    #[test]
    fn unit_stride_levels_equal_exact_batch_oadev_and_ohdev(y in prop::collection::vec(-30000i32..30000, 64..2000)) {
        let e = run::<8, 12, 12, 8>(std::slice::from_ref(&y));
        let yf: Vec<f64> = y.iter().map(|&v| v as f64).collect();
        let ms: Vec<u64> = (0..4).map(|k| 1u64 << k).collect();
        let oadev = deviation(&yf, 1.0, Stat::Oadev, &TauSet::List(ms.clone())).unwrap();
        let ohdev = deviation(&yf, 1.0, Stat::Ohdev, &TauSet::List(ms)).unwrap();
        for r in &oadev {
            let l = e.level(r.m.trailing_zeros() as usize).unwrap();
            prop_assert_eq!(l.n2, r.n);
            let d = l.oadev(1.0).unwrap();
            prop_assert!((d - r.dev).abs() <= 1e-9 * r.dev.max(1e-300), "m={} stream {} batch {}", r.m, d, r.dev);
        }
        for r in &ohdev {
            let l = e.level(r.m.trailing_zeros() as usize).unwrap();
            prop_assert_eq!(l.n3, r.n);
            let d = l.ohdev(1.0).unwrap();
            prop_assert!((d - r.dev).abs() <= 1e-9 * r.dev.max(1e-300), "m={} stream {} batch {}", r.m, d, r.dev);
        }
    }
}

#[test]
fn long_stream_reaches_high_levels_and_matches() {
    // 2^18 samples of a deterministic pseudo-random walk-ish signal reach m = 2^16.
    let mut s = 0x1234_5678u32;
    let mut drift = 0i32;
    let y: Vec<i32> = (0..1 << 18)
        .map(|_| {
            let r = xorshift(&mut s);
            drift += (r % 3) as i32 - 1;
            (r >> 20) as i32 - 2048 + drift
        })
        .collect();
    let e = run::<8, 24, 12, 20>(std::slice::from_ref(&y));
    let h = host::<8>(&[y], 24);
    assert_eq!(&e.levels().collect::<Vec<_>>()[..], &h[..]);
    assert!(h[16].n2 > 0 && h[16].n3 > 0, "level m = 2^16 has terms");
    assert_eq!(
        (h[17].n2, h[17].n3),
        (1, 0),
        "m = 2^17: one second difference at t = 2^18, no third"
    );
}

/// The overflow argument (docs/allan.md): at level m with stride s, |D2| ≤ 2·m·A and
/// |D3| ≤ 4·m·A (A = max |y|), and at most N/s + 1 terms are summed, so the sums stay below
/// (N/s + 1)·(4·m·A)². This evaluates the bound for 30 days at 1 kHz, A = 2^15, with checked
/// u128 arithmetic, for every level of the device engine; and shows the per-term bound is
/// attained by a square wave, so the argument is not loose by construction.
#[test]
fn no_accumulator_overflows_in_30_days_at_1khz_full_scale_16_bit() {
    let n: u128 = 30 * 86_400 * 1000;
    let a: u128 = 1 << 15;
    for l in DeviceEngine::new().levels() {
        let l = &l;
        let (m, s) = (l.m as u128, l.stride as u128);
        let terms = n / s + 1;
        let bound = (4 * m * a)
            .checked_pow(2)
            .and_then(|sq| sq.checked_mul(terms))
            .expect("bound fits u128");
        assert!(
            bound < u128::MAX / 2,
            "m = {m}: bound {bound} leaves headroom"
        );
        assert!(terms < u64::MAX as u128);
    }
    // θ over 30 days: |θ| ≤ N·A < 2^63 (and differences stay exact even if θ wraps).
    assert!(n * a < i64::MAX as u128);

    // A square wave of half-period m drives |D2| to exactly 2·m·A at level m on every term.
    let m = 64usize;
    let y: Vec<i32> = (0..16 * m)
        .map(|i| {
            if (i / m).is_multiple_of(2) {
                32767
            } else {
                -32767
            }
        })
        .collect();
    let e = run::<8, 12, 12, 8>(&[y]);
    let l = e.level(6).unwrap();
    assert_eq!(l.m as usize, m);
    let per_term = (2 * m as u128 * 32767).pow(2);
    // At stride s, the terms whose window is aligned with the wave reach the maximum.
    assert!(l.sum2 <= per_term * l.n2 as u128);
    assert!(
        l.sum2 >= per_term * (l.n2 as u128) / 4,
        "the bound is tight to within a small factor"
    );
}

/// New extremes after the base ring is full raise the gate and stay on the steady path while
/// the base ring stays narrow; the strided levels that can no longer be summed in 32-bit words
/// must then leave it. Steps to just below 2^(30 − K0) after small noise (all one sign for
/// hundreds of samples, so the strided differences exceed 2^31), and a ramp on which every
/// sample is a new extreme, must match the host bit for bit.
#[test]
fn late_extremes_in_the_steady_state() {
    fn check<const P: usize, const L: usize, const R: usize, const S: usize>(limit: i32) {
        let mut s = 0x9e37_79b9u32;
        let mut noise = |n: usize| -> Vec<i32> {
            (0..n)
                .map(|_| (xorshift(&mut s) >> 22) as i32 - 512)
                .collect()
        };
        let mut step = noise(100);
        step.extend(std::iter::repeat_n(limit - 1, 700));
        step.extend(noise(50));
        step.extend(std::iter::repeat_n(1 - limit, 900));
        step.extend(noise(300));
        let ramp: Vec<i32> = (0..3000).map(|i| i * (limit / 3000)).collect();
        for (name, y) in [("step", step), ("ramp", ramp)] {
            let segments = vec![y.clone(), y];
            assert_eq!(
                &run::<P, L, R, S>(&segments).levels().collect::<Vec<_>>()[..],
                &host::<P>(&segments, L)[..],
                "{name}, P = {P}"
            );
        }
    }
    // 2^(30 − K0): K0 = 4, 3, 2 for P = 8, 4, 2.
    check::<8, 12, 12, 8>(1 << 26);
    check::<8, 24, 12, 20>(1 << 26);
    check::<4, 11, 6, 8>(1 << 27);
    check::<2, 10, 3, 8>(1 << 28);
}

/// A square wave of amplitude `a` and half-period `h` about `mid` (starting at phase `phase`),
/// `n` samples, after one sample of `mid` (the engine subtracts a segment's first sample from
/// all of them, so the wave's amplitude is what it sees).
fn square_wave(mid: i32, a: i32, h: usize, phase: usize, n: usize) -> Vec<i32> {
    std::iter::once(mid)
        .chain((phase..phase + n).map(|i| {
            if (i / h).is_multiple_of(2) {
                mid + a
            } else {
                mid - a
            }
        }))
        .collect()
}

/// While max |y| < 2^(14 − log2 P) the engine squares the unit-stride differences with one
/// 32-bit multiply and no range test, relying on |D3| ≤ 4·m·max|y| < 2^16. A square wave of
/// half-period m = P attains |D3| = 4·P·max|y| exactly, so amplitudes at the edge of that bound
/// (and one past it, which must leave the small path) must still match bit for bit; a bound one
/// bit too generous would wrap the 32-bit squares.
#[test]
fn small_inputs_at_the_edge_of_the_one_multiply_bound() {
    fn check<const P: usize, const L: usize, const R: usize, const S: usize>() {
        let bits = 14 - P.trailing_zeros();
        // The largest amplitude of the small path, the smallest past it, and two past the
        // bound of an engine one or two bits too generous; and the same at half the amplitude
        // for the lowest strided level (m = 2P: |D3| ≤ 8·P·max|y|), waves up to h = 2P.
        let half = 1i32 << (bits - 1);
        for a in [
            half - 2,
            half - 1,
            (1 << bits) - 2,
            (1 << bits) - 1,
            (2 << bits) - 2,
            (4 << bits) - 2,
        ] {
            let mut h = 1;
            while h <= 2 * P {
                for (phase, mid) in [(0, 0), (h / 2, 16_384), (h, -3_000_000)] {
                    let y = square_wave(mid, a, h, phase, 40 * P + 7);
                    let segments = vec![y.clone(), y];
                    let e = run::<P, L, R, S>(&segments);
                    assert_eq!(
                        &e.levels().collect::<Vec<_>>()[..],
                        &host::<P>(&segments, L)[..],
                        "P = {P}, a = {a}, h = {h}, phase = {phase}, mid = {mid}"
                    );
                    assert!(
                        h < P
                            || e.level(h.trailing_zeros() as usize).unwrap().sum3
                                >= (4 * h as u128 * a as u128).pow(2),
                        "the wave of half-period h ≥ P reaches |D3| = 4·h·a at m = h"
                    );
                }
                h *= 2;
            }
        }
    }
    check::<8, 12, 12, 8>();
    check::<4, 11, 6, 8>();
    check::<2, 10, 3, 8>();
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, .. ProptestConfig::default() })]

    /// Random runs of ± twice the largest amplitude of the small path and smaller values about a
    /// random level, with a gap: the one-multiply squares must match the host bit for bit.
    #[test]
    fn small_inputs_match_the_host(
        runs in prop::collection::vec((any::<bool>(), 1usize..20, 0u32..5), 0..400),
        cut in 0usize..3000,
        mid in prop_oneof![Just(0i32), -40_000i32..40_000],
    ) {
        for p in [8usize, 4, 2] {
            // Twice the small path's largest amplitude, halved 0 to 4 times.
            let a = (2i32 << (14 - p.trailing_zeros())) - 4;
            let mut y = Vec::new();
            for &(sign, len, shift) in &runs {
                let v = a >> shift;
                y.extend(std::iter::repeat_n(mid + if sign { v } else { -v }, len));
            }
            // Each segment starts at `mid`, the offset the engine then subtracts.
            let cut = cut.min(y.len());
            let segments: Vec<Vec<i32>> = [&y[..cut], &y[cut..]]
                .iter()
                .map(|s| std::iter::once(mid).chain(s.iter().copied()).collect())
                .collect();
            let (got, want): (Vec<LevelSums>, Vec<LevelSums>) = match p {
                8 => (run::<8, 12, 12, 8>(&segments).levels().collect(), host::<8>(&segments, 12)),
                4 => (run::<4, 11, 6, 8>(&segments).levels().collect(), host::<4>(&segments, 11)),
                _ => (run::<2, 10, 3, 8>(&segments).levels().collect(), host::<2>(&segments, 10)),
            };
            prop_assert_eq!(&got[..], &want[..], "P = {}", p);
        }
    }
}

#[test]
fn device_engine_fits_the_memory_budget() {
    // repr(C), and the same sizes and alignments on thumbv6m (u64/i64 align to 8 under the
    // AAPCS too); stream.rs asserts the same numbers at compile time for every target.
    let imu = core::mem::size_of::<DeviceEngine>();
    let mag = core::mem::size_of::<MagEngine>();
    println!(
        "DeviceEngine (P = 8, L = 24): {imu} B, MagEngine (P = 8, L = 22): {mag} B per channel"
    );
    assert_eq!(
        imu, 3328,
        "DeviceEngine layout changed: update docs/allan.md"
    );
    assert_eq!(mag, 3040, "MagEngine layout changed: update docs/allan.md");
    let nine = 9 * imu;
    assert!(nine <= 32 * 1024, "9 channels take {nine} B > 32 KiB");
    // The firmware: 6 IMU axes and the temperature at 1 kHz, 3 magnetometer axes at 200 Hz.
    assert!(7 * imu + 3 * mag <= 32 * 1024);
}
