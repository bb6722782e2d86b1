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
fn the_drift_basis_is_exact_with_gaps_and_random_shapes() {
    let segs = vec![(0u64, 700u64), (750, 500)];
    let ctx = Context {
        tau0: 0.01,
        segments: segs.clone(),
        ..Context::default()
    };
    let span = super::drift_span(&ctx);
    assert_eq!(span, 1250.0);
    let mut state = 0x5eed_d41f_u64;
    let mut uniform = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    for j in [1usize, 2, 5, 16] {
        // a ramp per sample, then j cosine amplitudes
        let c: Vec<f64> = (0..=j)
            .map(|i| uniform() * if i == 0 { 1e-3 } else { 1.0 })
            .collect();
        let x: Vec<f64> = (0..1250)
            .map(|k| {
                c[0] * k as f64
                    + c[1..]
                        .iter()
                        .enumerate()
                        .map(|(i, ci)| {
                            ci * (std::f64::consts::PI * (i + 1) as f64 * k as f64 / span).cos()
                        })
                        .sum::<f64>()
            })
            .collect();
        for m in [1usize, 3, 16, 100, 240, 300] {
            let want = signal_avar(&x, &segs, m);
            let got = super::drift_avar(&c, m as u64, &ctx);
            assert!(
                (got - want).abs() <= 1e-15 + 1e-9 * want,
                "J {j} m {m}: {got} vs {want}"
            );
        }
        // its size: the rms about the mean of the continuous curve over the record's span, which
        // the 1250 samples' own rms meets to O(1/n)
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let rms = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / x.len() as f64).sqrt();
        let got = super::drift_norm(&c, span);
        assert!((got / rms - 1.0).abs() < 2e-3, "J {j}: {got} vs {rms}");
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

#[test]
fn resonance_psd_is_the_sampled_spectrum_of_its_autocovariance() {
    // ∫_0^{fs/2} S(f) df = R(0) = 1 (aliasing included), S equal to the direct Fourier sum of
    // R(k), and for a slow mode the continuous oscillator's spectrum
    let tau0 = 0.01;
    for (f0, zeta) in [(12.0, 0.1), (45.0, 0.05), (3.0, 0.6), (20.0, 0.99)] {
        let s = |f: f64| resonance_psd_unit(f, tau0, f0, zeta);
        let n = 200_000;
        let df = 0.5 / tau0 / n as f64;
        // midpoint rule
        let total: f64 = (0..n).map(|i| s((i as f64 + 0.5) * df)).sum::<f64>() * df;
        assert!((total - 1.0).abs() < 1e-6, "f0 {f0} ζ {zeta}: ∫S = {total}");
        let w = 2.0 * std::f64::consts::PI * f0 * tau0;
        let (alpha, beta) = (zeta * w, w * (1.0 - zeta * zeta).sqrt());
        let r = |k: f64| (-alpha * k).exp() * ((beta * k).cos() + alpha / beta * (beta * k).sin());
        for f in [0.0, 1.0, f0, 31.0, 49.0] {
            let th = 2.0 * std::f64::consts::PI * f * tau0;
            let direct = 2.0
                * tau0
                * (1.0
                    + 2.0
                        * (1..200_000)
                            .map(|k| r(k as f64) * (th * k as f64).cos())
                            .sum::<f64>());
            assert!((s(f) / direct - 1.0).abs() < 1e-8, "f0 {f0} ζ {zeta} f {f}");
        }
    }
    let (f0, zeta, tau0) = (0.5, 0.2, 1e-4);
    let w0 = 2.0 * std::f64::consts::PI * f0;
    for f in [0.05, 0.4, 0.5, 0.6, 2.0] {
        let w = 2.0 * std::f64::consts::PI * f;
        let h2 = 1.0 / ((w0 * w0 - w * w).powi(2) + (2.0 * zeta * w0 * w).powi(2));
        let cont = 2.0 * 4.0 * zeta * w0.powi(3) * h2;
        let got = resonance_psd_unit(f, tau0, f0, zeta);
        assert!((got / cont - 1.0).abs() < 1e-3, "f {f}: {got} vs {cont}");
    }
}

#[test]
fn resonance_basis_and_its_allan_bump() {
    let ctx = Context::uniform(0.01, 1 << 20);
    let b = Effect::Resonance.basis(&[12.0, 0.1], &ctx).unwrap();
    for m in [1.0, 3.0, 50.0] {
        let want = resonance_avar_unit(m * 0.01, 0.01, 12.0, 0.1);
        assert_eq!(b.avar(m, 0.01), want);
    }
    assert!(Effect::Resonance.basis(&[12.0, 1.0], &ctx).is_err());
    assert!(Effect::Resonance.basis(&[60.0, 0.1], &ctx).is_err());
    assert!(matches!(
        Effect::Resonance.basis(&[f64::NAN, 0.1], &ctx),
        Ok(Basis::Zero)
    ));
    // the bump of the signature text: for small ζ near τ = 0.37/f0 with σ ≈ 1.0·sigma (the
    // random-phase sinusoid of variance sigma², amplitude √2·sigma: 0.725·√2 = 1.03); a slow
    // mode sampled fast so that the continuous shape shows
    for (zeta, lo, hi) in [(0.01, 0.95, 1.05), (0.1, 0.85, 1.0), (0.3, 0.8, 0.9)] {
        let (f0, tau0) = (1.0, 1e-3);
        let (mut best, mut bt) = (0.0, 0.0);
        for m in 1..3000 {
            let v = resonance_avar_unit(m as f64 * tau0, tau0, f0, zeta);
            if v > best {
                best = v;
                bt = m as f64 * tau0;
            }
        }
        eprintln!(
            "ζ {zeta}: σ peak {:.3}·sigma at τ = {bt:.3}/f0",
            best.sqrt()
        );
        assert!((bt - 0.37).abs() < 0.03, "ζ {zeta}: peak at {bt}");
        assert!(
            best.sqrt() > lo && best.sqrt() < hi,
            "ζ {zeta}: {}",
            best.sqrt()
        );
    }
}
