//! The physical reading of a fitted effect, and where on the τ axis a term or a misfit shows.
use crate::assess::{Assessment, TauRange};
use crate::effect::Effect;
use crate::fit::Fit;

pub(super) fn fmt_s(t: f64) -> String {
    if !t.is_finite() {
        "n/a".into()
    } else if t < 1e-3 {
        format!("{:.1} µs", t * 1e6)
    } else if t < 1.0 {
        format!("{:.3} s", t)
    } else if t < 100.0 {
        format!("{:.2} s", t)
    } else {
        format!("{:.0} s", t)
    }
}

/// The physical reading of an effect as fitted, its amplitude with its 1σ and its unit (the
/// column's `unit`).
pub fn reading(fit: &Fit, e: &Effect, unit: &str) -> String {
    let Some(t) = fit.terms.iter().rev().find(|t| t.effect == *e) else {
        return String::new();
    };
    let th = t.theta0().unwrap_or(f64::NAN);
    // "+1.2345e-2 ± 3.1e-3 deg/s": the amplitude as the parameter table gives it
    let amp = |signed: bool| {
        let u = t.effect.amp_unit(unit, fit.ctx.temp_avar.is_none());
        let (a, s) = (t.amplitude(), t.amplitude_sigma());
        let sigma = if s.is_finite() {
            format!(" ± {s:.1e}")
        } else {
            String::new()
        };
        if signed {
            format!("{a:+.4e}{sigma} {u}")
        } else {
            format!("{a:.4e}{sigma} {u}")
        }
    };
    let two_pi = 2.0 * std::f64::consts::PI;
    match e {
        Effect::Markov => format!(
            "correlated noise with τ_c = {} (peak of σ at τ ≈ {}); as a low-pass on white noise it \
             would be a corner at {:.3} Hz",
            fmt_s(th),
            fmt_s(1.89 * th),
            1.0 / (two_pi * th)
        ),
        Effect::Sinusoid => format!(
            "a sinusoid of {} at {:.4} Hz (period {}); σ has nulls at τ = k/f",
            amp(false),
            th,
            fmt_s(1.0 / th)
        ),
        Effect::Lowpass | Effect::Lowpass2 => {
            let dlpf = [
                (188.0, 1),
                (98.0, 2),
                (42.0, 3),
                (20.0, 4),
                (10.0, 5),
                (5.0, 6),
            ]
            .iter()
            .find(|(bw, _)| (th / bw - 1.0).abs() < 0.25)
            .map(|(bw, cfg)| {
                format!(" — close to the MPU-6050's DLPF_CFG = {cfg} ({bw} Hz gyro bandwidth)")
            })
            .unwrap_or_default();
            format!(
                "the sensor's own {}low-pass filter at f_c = {:.3} Hz on its white noise{dlpf}",
                if *e == Effect::Lowpass2 {
                    "two-pole "
                } else {
                    ""
                },
                th
            )
        }
        Effect::Boxcar | Effect::Bartlett => format!(
            "a {} decimation filter {:.2} samples long ({})",
            if *e == Effect::Boxcar {
                "moving-average"
            } else {
                "triangular"
            },
            th,
            fmt_s(th * fit.tau0)
        ),
        Effect::BiasStep => format!(
            "a bias step of {} at t = {} — a non-stationarity of this record, not noise",
            amp(true),
            fmt_s(th)
        ),
        Effect::Temperature => {
            if fit.ctx.temp_avar.is_some() {
                format!("the bias follows the temperature with {}", amp(true))
            } else {
                format!(
                    "a warm-up transient of {} with time constant {}{}",
                    amp(true),
                    fmt_s(th),
                    t.theta_sigma
                        .first()
                        .filter(|s| s.is_finite())
                        .map_or(String::new(), |s| format!(" ± {}", fmt_s(*s)))
                )
            }
        }
        Effect::Resonance => format!(
            "a resonance at f0 = {:.3} Hz, ζ = {:.3}, σ = {} — a mount or structural mode \
             (band ≈ {:.2} Hz wide in the PSD)",
            th,
            t.theta.get(1).copied().unwrap_or(f64::NAN),
            amp(false),
            2.0 * t.theta.get(1).copied().unwrap_or(f64::NAN) * th
        ),
        Effect::Resolution => format!("rounding to the data's LSB of {}", amp(false)),
        Effect::Drift { .. } => format!(
            "a smooth drift of the bias, {} rms over the record (a ramp and {} cosine \
             component{} of the record's length) — a non-stationarity of this record, not noise",
            amp(false),
            t.theta.len().saturating_sub(1),
            if t.theta.len() == 2 { "" } else { "s" }
        ),
        e => format!("{} = {}", e.amp_name(), amp(false)),
    }
}

/// The τ range where a term shows: the points where its share of the model variance is at least
/// half its largest share.
pub fn tau_range(fit: &Fit, k: usize) -> Option<(f64, f64)> {
    let share: Vec<f64> = fit
        .term_avar(k)
        .iter()
        .zip(&fit.model_avar)
        .map(|(a, m)| if *m > 0.0 { a / m } else { 0.0 })
        .collect();
    let max = share.iter().copied().fold(0.0, f64::max);
    if !(max > 0.0) {
        return None;
    }
    let idx: Vec<usize> = (0..share.len())
        .filter(|&j| share[j] >= 0.5 * max)
        .collect();
    Some((fit.points[*idx.first()?].tau, fit.points[*idx.last()?].tau))
}

/// The union of failing (or else outside) τ ranges of an assessment.
pub fn misfit_range(a: &Assessment) -> Option<(f64, f64)> {
    let rs: &[TauRange] = if a.failing.is_empty() {
        &a.outside
    } else {
        &a.failing
    };
    if rs.is_empty() {
        return None;
    }
    Some((
        rs.iter().map(|r| r.lo).fold(f64::INFINITY, f64::min),
        rs.iter().map(|r| r.hi).fold(0.0, f64::max),
    ))
}
