//! Hand-written SVG plots of a noise-model fit (no font files or system fonts are needed: text is
//! left to the SVG viewer). One figure = the Allan panel (measured σ with its 68.3 % bars, the
//! total model, each term dashed) above a residual panel (r per τ, the ±1 band, the τ ranges
//! outside the interval shaded, failing ones in red).
// SVG/HTML fragments are raw multi-line strings that end in a newline.
#![allow(clippy::write_with_newline)]

use super::esc;
pub use super::svg_to_png;
use noise_model::{Assessment, Effect, Fit, Standing};
use std::fmt::Write;

pub const W: f64 = 640.0;
pub const H: f64 = 580.0;
const ML: f64 = 78.0; // margins
const MR: f64 = 175.0;
const MT: f64 = 36.0;
const TOP_H: f64 = 330.0;
const GAP: f64 = 56.0;
const BOT_H: f64 = 110.0;

fn color(e: &Effect) -> &'static str {
    match e {
        Effect::Quantization => "#9467bd",
        Effect::White => "#1f77b4",
        Effect::Flicker => "#2ca02c",
        Effect::RateRandomWalk => "#ff7f0e",
        Effect::RateRamp => "#8c564b",
        Effect::Markov => "#d62728",
        Effect::Sinusoid => "#e377c2",
        Effect::Resolution => "#7f7f7f",
        Effect::BiasStep => "#bcbd22",
        Effect::Temperature => "#17becf",
        Effect::Drift { .. } => "#5f9ea0",
        Effect::Lowpass | Effect::Lowpass2 => "#1f3f9f",
        Effect::Boxcar | Effect::Bartlett => "#3f9f1f",
        Effect::Resonance => "#ff1f8f",
        Effect::User(_) => "#aa5500",
    }
}

fn tick_label(d: i32) -> String {
    let v = 10f64.powi(d);
    if (-3..=4).contains(&d) {
        format!("{}", v)
    } else {
        format!("1e{d}")
    }
}

/// One figure as an SVG fragment (a nested `<svg>` placed at `x0`), with its title.
/// `adequate` is the lab's whole verdict (the Allan test, the time-domain checks and the
/// candidates), printed under the legend. `compensated` (τ, σ) is drawn as open diamonds: the
/// Allan curve of the record with the model's time-domain signals (steps, temperature, warm-up)
/// removed.
pub fn figure(
    fit: &Fit,
    a: &Assessment,
    adequate: bool,
    compensated: &[(f64, f64)],
    title: &str,
    unit: &str,
    x0: f64,
) -> String {
    let pts = &fit.points;
    let mut s = String::new();
    let pw = W - ML - MR;
    let (tmin, tmax) = (
        pts.first().map_or(0.01, |p| p.tau),
        pts.last().map_or(1.0, |p| p.tau),
    );
    let (xd0, xd1) = (tmin.log10().floor() as i32, tmax.log10().ceil() as i32);
    let ylo = pts
        .iter()
        .map(|p| p.lo.max(p.dev * 0.05))
        .fold(f64::INFINITY, f64::min);
    let yhi = pts.iter().map(|p| p.hi).fold(0.0, f64::max);
    let (yd0, yd1) = (
        (ylo / 2.0).log10().floor() as i32,
        (yhi * 1.5).log10().ceil() as i32,
    );
    let px = |t: f64| ML + (t.log10() - xd0 as f64) / (xd1 - xd0).max(1) as f64 * pw;
    let py = |v: f64| {
        MT + TOP_H - (v.max(1e-300).log10() - yd0 as f64) / (yd1 - yd0).max(1) as f64 * TOP_H
    };
    let clip = format!("clip{}", x0 as i64);
    let _ = write!(
        s,
        r#"<svg x="{x0}" y="0" width="{W}" height="{H}" viewBox="0 0 {W} {H}" font-family="sans-serif" font-size="12">
<defs><clipPath id="{clip}"><rect x="{ML}" y="{MT}" width="{pw}" height="{TOP_H}"/></clipPath></defs>
<rect x="0" y="0" width="{W}" height="{H}" fill="white"/>
<text x="{}" y="20" text-anchor="middle" font-size="13" font-weight="bold">{}</text>
"#,
        ML + pw / 2.0,
        esc(title)
    );
    // grid and axes
    for d in xd0..=xd1 {
        let x = px(10f64.powi(d));
        let _ = write!(
            s,
            r##"<line x1="{x:.1}" y1="{MT}" x2="{x:.1}" y2="{}" stroke="#ddd"/><text x="{x:.1}" y="{}" text-anchor="middle">{}</text>
<line x1="{x:.1}" y1="{}" x2="{x:.1}" y2="{}" stroke="#ddd"/>
"##,
            MT + TOP_H,
            MT + TOP_H + 16.0,
            tick_label(d),
            MT + TOP_H + GAP,
            MT + TOP_H + GAP + BOT_H
        );
    }
    for d in yd0..=yd1 {
        let y = py(10f64.powi(d));
        let _ = write!(
            s,
            r##"<line x1="{ML}" y1="{y:.1}" x2="{}" y2="{y:.1}" stroke="#ddd"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>
"##,
            ML + pw,
            ML - 6.0,
            y + 4.0,
            tick_label(d)
        );
    }
    let _ = write!(
        s,
        r##"<rect x="{ML}" y="{MT}" width="{pw}" height="{TOP_H}" fill="none" stroke="#333"/>
<text x="{}" y="{}" text-anchor="middle">τ [s]</text>
<text x="18" y="{}" text-anchor="middle" transform="rotate(-90 18 {})">Allan deviation σ(τ) [{}]</text>
"##,
        ML + pw / 2.0,
        MT + TOP_H + 32.0,
        MT + TOP_H / 2.0,
        MT + TOP_H / 2.0,
        esc(unit)
    );
    // model curves on a fine grid
    let ngrid = 240;
    // the model exists from one sample period (m = 1) on
    let grid: Vec<f64> = (0..=ngrid)
        .map(|i| 10f64.powf(xd0 as f64 + (xd1 - xd0) as f64 * i as f64 / ngrid as f64))
        .map(|t| t.max(fit.tau0))
        .collect();
    let path = |vals: &[f64]| {
        let mut d = String::new();
        let mut pen = false;
        for (t, v) in grid.iter().zip(vals) {
            if *v > 0.0 && v.is_finite() {
                let _ = write!(
                    d,
                    "{}{:.1},{:.1} ",
                    if pen { "L" } else { "M" },
                    px(*t),
                    py(*v).min(MT + TOP_H + 40.0)
                );
                pen = true;
            } else {
                pen = false;
            }
        }
        d
    };
    let mut legend: Vec<(String, String, bool)> = Vec::new();
    for t in &fit.terms {
        if t.coef <= 0.0 {
            continue;
        }
        let vals: Vec<f64> = grid.iter().map(|&g| t.avar(g, &fit.ctx).sqrt()).collect();
        let _ = write!(
            s,
            r#"<path d="{}" fill="none" stroke="{}" stroke-width="1.5" stroke-dasharray="6 4" clip-path="url(#{clip})"/>
"#,
            path(&vals),
            color(&t.effect)
        );
        legend.push((
            format!(
                "{}{}",
                t.effect.name(),
                if t.detected { "" } else { " (n.d.)" }
            ),
            color(&t.effect).to_string(),
            true,
        ));
    }
    let total: Vec<f64> = grid.iter().map(|&g| fit.model_dev(g)).collect();
    let _ = write!(
        s,
        r#"<path d="{}" fill="none" stroke="black" stroke-width="2" clip-path="url(#{clip})"/>
"#,
        path(&total)
    );
    legend.insert(0, ("model (total)".into(), "black".into(), false));
    // measurement with CI bars
    let status = |i: usize| match a.standing(i) {
        Standing::Failing => "#c00",
        Standing::Outside => "#e08000",
        Standing::Fine => "#333",
    };
    for (i, p) in pts.iter().enumerate() {
        let (x, y, ylo, yhi) = (px(p.tau), py(p.dev), py(p.lo.max(1e-300)), py(p.hi));
        let col = status(i);
        let _ = write!(
            s,
            r#"<line x1="{x:.1}" y1="{yhi:.1}" x2="{x:.1}" y2="{:.1}" stroke="{col}" stroke-width="1.2"/><line x1="{:.1}" y1="{yhi:.1}" x2="{:.1}" y2="{yhi:.1}" stroke="{col}"/><line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{col}"/><circle cx="{x:.1}" cy="{y:.1}" r="3.2" fill="{col}"/>
"#,
            ylo.min(MT + TOP_H),
            x - 3.0,
            x + 3.0,
            x - 3.0,
            ylo.min(MT + TOP_H),
            x + 3.0,
            ylo.min(MT + TOP_H)
        );
    }
    for &(t, d) in compensated {
        let (x, y) = (px(t), py(d));
        let _ = write!(
            s,
            r##"<path d="M{:.1},{y:.1} L{x:.1},{:.1} L{:.1},{y:.1} L{x:.1},{:.1} Z" fill="none" stroke="#2060c0" stroke-width="1.3"/>
"##,
            x - 4.0,
            y - 4.0,
            x + 4.0,
            y + 4.0
        );
    }
    if !compensated.is_empty() {
        legend.insert(0, ("compensated record".into(), "#2060c0".into(), false));
    }
    legend.insert(0, ("measured ± 68.3 %".into(), "#333".into(), false));
    for (i, (name, col, dashed)) in legend.iter().enumerate() {
        let y = MT + 12.0 + 18.0 * i as f64;
        let x = ML + pw + 10.0;
        let _ = write!(
            s,
            r#"<line x1="{x}" y1="{y}" x2="{}" y2="{y}" stroke="{col}" stroke-width="2"{}/><text x="{}" y="{}" font-size="11">{}</text>
"#,
            x + 22.0,
            if *dashed {
                r#" stroke-dasharray="6 4""#
            } else {
                ""
            },
            x + 28.0,
            y + 4.0,
            esc(name)
        );
    }
    let _ = write!(
        s,
        r#"<text x="{}" y="{}">χ²/dof = {:.2}</text><text x="{}" y="{}">{}</text>
"#,
        ML + pw + 10.0,
        MT + 12.0 + 18.0 * legend.len() as f64 + 10.0,
        fit.chi2_dof(),
        ML + pw + 10.0,
        MT + 12.0 + 18.0 * legend.len() as f64 + 28.0,
        if adequate { "adequate" } else { "NOT adequate" }
    );
    // residual panel
    let y0 = MT + TOP_H + GAP;
    let rmax = a
        .residuals
        .iter()
        .filter(|r| r.is_finite())
        .fold(3.0f64, |m, r| m.max(r.abs()))
        .min(50.0)
        .ceil();
    let ry = |r: f64| y0 + BOT_H / 2.0 - r.clamp(-rmax, rmax) / rmax * BOT_H / 2.0;
    let half_step = |i: usize| -> (f64, f64) {
        let t = pts[i].tau;
        let l = if i > 0 {
            (pts[i - 1].tau * t).sqrt()
        } else {
            t / 1.41
        };
        let r = if i + 1 < pts.len() {
            (pts[i + 1].tau * t).sqrt()
        } else {
            t * 1.41
        };
        (px(l), px(r))
    };
    for rng in &a.outside {
        let failing = a.failing.contains(rng);
        let (xa, _) = half_step(rng.first);
        let (_, xb) = half_step(rng.last);
        let _ = write!(
            s,
            r#"<rect x="{xa:.1}" y="{MT}" width="{:.1}" height="{}" fill="{}" opacity="{}"/>
"#,
            (xb - xa).max(1.0),
            TOP_H + GAP + BOT_H,
            if failing { "#f33" } else { "#fa0" },
            if failing { 0.18 } else { 0.10 }
        );
    }
    let _ = write!(
        s,
        r##"<rect x="{ML}" y="{y0}" width="{pw}" height="{BOT_H}" fill="none" stroke="#333"/>
<rect x="{ML}" y="{:.1}" width="{pw}" height="{:.1}" fill="#eee" opacity="0.6"/>
<line x1="{ML}" y1="{:.1}" x2="{}" y2="{:.1}" stroke="#666"/>
<text x="{}" y="{:.1}" text-anchor="end">+{rmax}</text><text x="{}" y="{:.1}" text-anchor="end">0</text><text x="{}" y="{:.1}" text-anchor="end">−{rmax}</text>
<text x="18" y="{}" text-anchor="middle" transform="rotate(-90 18 {})">r [CI half-widths]</text>
<text x="{}" y="{}" text-anchor="middle">τ [s] — orange: model outside the 68.3 % interval; red: significant misfit</text>
"##,
        ry(1.0),
        ry(-1.0) - ry(1.0),
        ry(0.0),
        ML + pw,
        ry(0.0),
        ML - 6.0,
        y0 + 10.0,
        ML - 6.0,
        ry(0.0) + 4.0,
        ML - 6.0,
        y0 + BOT_H,
        y0 + BOT_H / 2.0,
        y0 + BOT_H / 2.0,
        ML + pw / 2.0,
        y0 + BOT_H + 30.0,
    );
    for (i, (p, r)) in pts.iter().zip(&a.residuals).enumerate() {
        let x = px(p.tau);
        let col = status(i);
        let _ = write!(
            s,
            r#"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="{col}" stroke-width="2"/><circle cx="{x:.1}" cy="{:.1}" r="3" fill="{col}"/>
"#,
            ry(0.0),
            ry(*r),
            ry(*r)
        );
    }
    s.push_str("</svg>\n");
    s
}

/// A standalone SVG document of one figure, or of several side by side (before → after).
pub fn document(figs: &[String]) -> String {
    let w = W * figs.len().max(1) as f64;
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{H}" viewBox="0 0 {w} {H}">
"#
    );
    for f in figs {
        s.push_str(f);
    }
    s.push_str("</svg>\n");
    s
}
