use super::*;

/// Direct sum σ²(m) = Σ_d C(d) R(|d|) / (2m²) for an AR(1) with coefficient φ.
fn brute(m: usize, phi: f64) -> f64 {
    let mut s = 0.0;
    let mm = m as i64;
    for d in -(2 * mm - 1)..=(2 * mm - 1) {
        let ad = d.abs();
        let c = if ad == 0 {
            2 * mm
        } else if ad < mm {
            2 * mm - 3 * ad
        } else {
            -(2 * mm - ad)
        };
        s += c as f64 * phi.powi(ad as i32);
    }
    s / (2.0 * (m * m) as f64)
}

#[test]
fn markov_sampled_matches_direct_sum() {
    for &tc in &[0.3, 2.0, 31.8, 5000.0] {
        let phi = (-1.0f64 / tc).exp();
        for &m in &[1usize, 2, 3, 7, 64, 1000] {
            let a = markov_avar_unit(m as f64, 1.0, tc);
            let b = brute(m, phi);
            assert!(
                (a - b).abs() <= 1e-7 * b.abs().max(1e-12),
                "tc {tc} m {m}: {a} vs {b}"
            );
        }
    }
}

#[test]
fn markov_tends_to_continuous() {
    for &x in &[1e-4, 1e-2, 0.4, 0.6, 1.0, 10.0, 1e3] {
        let c = markov_avar_continuous(x, 1.0);
        let s = markov_avar_unit(x, x.min(1.0) / 1e4, 1.0);
        assert!((c - s).abs() < 1e-6 * c, "x {x}: {c} vs {s}");
    }
    let h = |x: f64| 2.0 / x - (3.0 - 4.0 * (-x).exp() + (-2.0 * x).exp()) / (x * x);
    assert!((markov_avar_continuous(0.4999999, 1.0) - h(0.4999999)).abs() < 1e-12);
    let (mut best, mut bt) = (0.0, 0.0);
    for i in 0..2000 {
        let t = 0.5 + i as f64 * 0.002;
        let v = markov_avar_continuous(t, 1.0);
        if v > best {
            best = v;
            bt = t;
        }
    }
    assert!((bt - 1.89).abs() < 0.01 && (best.sqrt() - 0.618).abs() < 0.002);
}

#[test]
fn sinusoid_sampled_matches_continuous_for_slow_sines() {
    let a = sinusoid_avar_unit(0.37, 1e-5, 1.0);
    let b = sinusoid_avar_unit(0.37, 0.0, 1.0);
    assert!((a - b).abs() < 1e-6 * b);
    assert!(sinusoid_avar_unit(2.0, 0.01, 1.0) < 1e-25);
}

/// Direct OADEV expectation of a deterministic signal: mean over differences of (ȳ2 − ȳ1)²/2.
fn signal_avar(x: &[f64], segs: &[(u64, u64)], m: usize) -> f64 {
    let (mut acc, mut n) = (0.0, 0usize);
    for &(a, l) in segs {
        let (a, l) = (a as usize, l as usize);
        for i in a..=(a + l).saturating_sub(2 * m) {
            if i + 2 * m > a + l {
                break;
            }
            let y1: f64 = x[i..i + m].iter().sum::<f64>() / m as f64;
            let y2: f64 = x[i + m..i + 2 * m].iter().sum::<f64>() / m as f64;
            acc += (y2 - y1).powi(2);
            n += 1;
        }
    }
    acc / (2.0 * n as f64)
}

#[test]
fn step_and_warmup_bases_are_exact() {
    let segs = vec![(0u64, 700u64), (750, 500)];
    let ctx = Context {
        tau0: 0.01,
        segments: segs.clone(),
        ..Context::default()
    };
    for s in [1u64, 40, 350, 699, 760, 1100] {
        let x: Vec<f64> = (0..1250)
            .map(|k| if k as u64 >= s { 1.0 } else { 0.0 })
            .collect();
        for m in [1usize, 3, 16, 100, 240] {
            let want = signal_avar(&x, &segs, m);
            let got = step_avar(s, m as u64, &ctx);
            assert!(
                (got - want).abs() <= 1e-12 + 1e-9 * want,
                "s {s} m {m}: {got} vs {want}"
            );
        }
    }
    let kappa = 180.0;
    let x: Vec<f64> = (0..1250).map(|k| (-(k as f64) / kappa).exp()).collect();
    for m in [1usize, 5, 64, 200] {
        let want = signal_avar(&x, &segs, m);
        let got = warmup_avar(kappa, m as u64, &ctx);
        assert!((got - want).abs() <= 1e-9 * want, "m {m}: {got} vs {want}");
    }
}

#[test]
fn filters_join_the_white_line_and_match_their_impulse_responses() {
    let ctx = Context::uniform(0.01, 1 << 16);
    let white = Effect::White.basis(&[], &ctx).unwrap();
    for (e, th) in [
        (Effect::Lowpass, 5.0),
        (Effect::Lowpass2, 5.0),
        (Effect::Boxcar, 8.0),
        (Effect::Bartlett, 8.0),
    ] {
        let b = e.basis(&[th], &ctx).unwrap();
        let (lo, hi) = (b.avar(1.0, 0.01), b.avar(4096.0, 0.01));
        assert!(lo < 0.7 * white.avar(1.0, 0.01), "{e}: {lo}");
        assert!(
            (hi / white.avar(4096.0, 0.01) - 1.0).abs() < 0.01,
            "{e}: {hi}"
        );
    }
    // two cascaded sections: the direct impulse-response sum
    let (fc, tau0) = (5.0, 0.01);
    let phi = (-2.0 * std::f64::consts::PI * fc * tau0).exp();
    let h: Vec<f64> = (0..5000)
        .map(|n| (1.0 - phi).powi(2) * (n as f64 + 1.0) * phi.powi(n))
        .collect();
    let r = |k: usize| h.iter().zip(&h[k..]).map(|(a, b)| a * b).sum::<f64>() / tau0;
    let v = |n: usize| n as f64 * r(0) + 2.0 * (1..n).map(|k| (n - k) as f64 * r(k)).sum::<f64>();
    let b = Effect::Lowpass2.basis(&[fc], &ctx).unwrap();
    for m in [1usize, 3, 10, 77] {
        let want = (4.0 * v(m) - v(2 * m)) / (2.0 * (m * m) as f64);
        let got = b.avar(m as f64, tau0);
        assert!((got - want).abs() < 1e-9 * want, "m {m}: {got} vs {want}");
    }
}

#[test]
fn names_roundtrip() {
    for e in ALL_EFFECTS {
        assert_eq!(Effect::parse(e.name()), Some(e.clone()));
    }
}
