//! `deviation_segments`: a record cut by gaps, as the device's engine treats it (no difference
//! spans a gap), against the single-record estimator on each segment, a brute-force sum, the
//! streaming engine fed the same gaps, and its refusals.
use allan::batch::{deviation, deviation_segments, stride_sums, Stat, TauSet};
use allan::{AllanError, Engine};

/// xorshift32 mapped to [−0.5, 0.5).
fn noise(state: u32, n: usize) -> Vec<f64> {
    let mut s = state;
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            s as f64 / 4_294_967_296.0 - 0.5
        })
        .collect()
}

fn three_segments() -> Vec<Vec<f64>> {
    vec![
        noise(0x1234_5678, 5000),
        noise(0x0bad_f00d, 1700).iter().map(|v| v + 100.0).collect(),
        noise(0x5eed_1e55, 40_000),
    ]
}

#[test]
fn one_segment_is_the_single_record_estimator() {
    let y = noise(7, 20_000);
    for stat in Stat::ALL {
        let a = deviation(&y, 0.01, stat, &TauSet::Octave).unwrap();
        let b = deviation_segments(&[&y], 0.01, stat, &TauSet::Octave).unwrap();
        assert_eq!(a, b, "{}", stat.name());
    }
}

/// Σ over segments of dev²·n (the raw sum of squared differences over the normaliser) equals
/// the segmented dev²·n at every m that every segment's own table has.
#[test]
fn sums_are_the_segments_sums() {
    let segs = three_segments();
    let refs: Vec<&[f64]> = segs.iter().map(|s| s.as_slice()).collect();
    for stat in [Stat::Adev, Stat::Oadev, Stat::Hdev, Stat::Ohdev, Stat::Mdev] {
        let all = deviation_segments(&refs, 0.01, stat, &TauSet::Octave).unwrap();
        let each: Vec<_> = refs
            .iter()
            .map(|s| deviation(s, 0.01, stat, &TauSet::Octave).unwrap())
            .collect();
        let mut checked = 0;
        for row in &all {
            let parts: Option<Vec<_>> = each
                .iter()
                .map(|t| t.iter().find(|r| r.m == row.m))
                .collect();
            let Some(parts) = parts else { continue };
            let n: u64 = parts.iter().map(|r| r.n).sum();
            assert_eq!(row.n, n, "{} m = {}", stat.name(), row.m);
            let want: f64 = parts
                .iter()
                .map(|r| r.dev * r.dev * r.n as f64)
                .sum::<f64>();
            let got = row.dev * row.dev * row.n as f64;
            assert!(
                (got / want - 1.0).abs() < 1e-12,
                "{} m = {}: {got} vs {want}",
                stat.name(),
                row.m
            );
            checked += 1;
        }
        assert!(checked >= 9, "{}: {checked} rows compared", stat.name());
        // The longest segment alone has more rows than the shortest: its long-τ rows are there.
        assert_eq!(all.len(), each[2].len(), "{}", stat.name());
    }
}

/// Overlapping Allan variance by its definition, term by term inside each segment.
fn brute_oavar(segs: &[Vec<f64>], m: usize) -> (f64, u64) {
    let (mut s, mut n) = (0.0, 0u64);
    for y in segs {
        let mut x = vec![0.0];
        for v in y {
            x.push(x.last().unwrap() + v);
        }
        for k in 0..x.len().saturating_sub(2 * m) {
            let d = x[k + 2 * m] - 2.0 * x[k + m] + x[k];
            s += d * d;
            n += 1;
        }
    }
    (s / (2.0 * (m * m) as f64 * n as f64), n)
}

#[test]
fn against_the_brute_force_sum() {
    let segs = three_segments();
    let refs: Vec<&[f64]> = segs.iter().map(|s| s.as_slice()).collect();
    let ms = vec![1u64, 2, 3, 5, 8, 100, 900, 2000, 6000];
    let rows = deviation_segments(&refs, 1.0, Stat::Oadev, &TauSet::List(ms.clone())).unwrap();
    assert_eq!(rows.len(), ms.len());
    for (row, &m) in rows.iter().zip(&ms) {
        let (var, n) = brute_oavar(&segs, m as usize);
        assert_eq!(row.n, n, "m = {m}");
        assert!(
            (row.dev * row.dev / var - 1.0).abs() < 1e-9,
            "m = {m}: {} vs {var}",
            row.dev * row.dev
        );
    }
}

/// A bias jump of 100 units at a gap is invisible to the segmented estimator (no difference
/// spans it) but dominates the same samples taken as one record.
#[test]
fn no_difference_spans_a_gap() {
    let segs = three_segments();
    let refs: Vec<&[f64]> = segs.iter().map(|s| s.as_slice()).collect();
    let seg = deviation_segments(&refs, 1.0, Stat::Oadev, &TauSet::Octave).unwrap();
    let joined: Vec<f64> = segs.concat();
    let one = deviation(&joined, 1.0, Stat::Oadev, &TauSet::Octave).unwrap();
    // White noise of variance 1/12: σ(m) = 1/√(12 m).
    for r in seg.iter().take(8) {
        let white = (1.0 / (12.0 * r.m as f64)).sqrt();
        assert!((r.dev / white - 1.0).abs() < 0.1, "m = {}: {}", r.m, r.dev);
    }
    assert!(
        one[5].dev > 3.0 * seg[5].dev,
        "{} vs {}",
        one[5].dev,
        seg[5].dev
    );
}

/// The device's engine fed the same segments (integer counts, a gap between them) gives the
/// same fully overlapping sums at m ≤ P as the batch estimator.
#[test]
fn agrees_with_the_engine_across_gaps() {
    let ints: Vec<Vec<i32>> = three_segments()
        .iter()
        .map(|s| s.iter().map(|v| (v * 2000.0).round() as i32).collect())
        .collect();
    let mut e = Engine::<8, 20, 12, 16>::new();
    for (i, s) in ints.iter().enumerate() {
        if i > 0 {
            e.gap();
        }
        for &v in s {
            e.push(v);
        }
    }
    let refs: Vec<&[i32]> = ints.iter().map(|s| s.as_slice()).collect();
    let host = stride_sums(&refs, 8, 20);
    let f: Vec<Vec<f64>> = ints
        .iter()
        .map(|s| s.iter().map(|&v| v as f64).collect())
        .collect();
    let fr: Vec<&[f64]> = f.iter().map(|s| s.as_slice()).collect();
    let rows = deviation_segments(&fr, 1.0, Stat::Oadev, &TauSet::Octave).unwrap();
    for k in 0..4 {
        let lv = e.level(k).unwrap();
        assert_eq!(lv, host[k]);
        assert_eq!(rows[k].n, lv.n2, "m = {}", lv.m);
        assert!((rows[k].dev / lv.oadev(1.0).unwrap() - 1.0).abs() < 1e-9);
    }
}

#[test]
fn edf_adds_over_segments() {
    let segs = three_segments();
    let refs: Vec<&[f64]> = segs.iter().map(|s| s.as_slice()).collect();
    let all = deviation_segments(&refs, 1.0, Stat::Oadev, &TauSet::Octave).unwrap();
    let each: Vec<_> = refs
        .iter()
        .map(|s| deviation(s, 1.0, Stat::Oadev, &TauSet::Octave).unwrap())
        .collect();
    for row in all.iter().take(6) {
        let parts: Vec<_> = each
            .iter()
            .map(|t| t.iter().find(|r| r.m == row.m).unwrap())
            .collect();
        if parts.iter().all(|p| p.alpha == row.alpha) {
            let sum: f64 = parts.iter().map(|p| p.edf).sum();
            assert!((row.edf / sum - 1.0).abs() < 1e-12, "m = {}", row.m);
        }
    }
}

#[test]
fn refusals_name_what_and_where() {
    let a = noise(1, 100);
    let mut b = noise(2, 100);
    b[37] = f64::NAN;
    assert_eq!(
        deviation_segments(&[&a, &b], 1.0, Stat::Oadev, &TauSet::Octave),
        Err(AllanError::NotFinite { index: 137 })
    );
    assert!(matches!(
        deviation_segments(&[&a, &a], 1.0, Stat::Totdev, &TauSet::Octave),
        Err(AllanError::Unsupported(_))
    ));
    assert_eq!(
        deviation_segments(&[&a[..2], &a[..1]], 1.0, Stat::Oadev, &TauSet::Octave),
        Err(AllanError::TooShort {
            samples: 2,
            needed: 3
        })
    );
    assert!(matches!(
        deviation_segments(&[&a, &a], 0.0, Stat::Oadev, &TauSet::Octave),
        Err(AllanError::BadTau0(_))
    ));
    // A τ list that fits no segment gives no rows (the caller words the refusal).
    assert_eq!(
        deviation_segments(&[&a, &a], 1.0, Stat::Oadev, &TauSet::List(vec![999_999])),
        Ok(vec![])
    );
}
