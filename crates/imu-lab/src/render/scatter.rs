//! Hand-written SVG figures for `imu-lab calibrate`: a grid of scatter panels with optional
//! curves (fitted ellipse, ideal circle). No plotting dependency: the figures are simple and the
//! output must be byte-stable for the docs.
use super::esc;
use std::fmt::Write;

/// One set of points in a panel.
pub struct Series {
    /// Legend text.
    pub label: String,
    /// CSS colour.
    pub color: &'static str,
    /// Data points (x, y).
    pub points: Vec<(f64, f64)>,
    /// Draw as a closed/open polyline (true) or as dots (false).
    pub line: bool,
}

impl Series {
    /// Points drawn as dots.
    pub fn dots(label: impl Into<String>, color: &'static str, points: Vec<(f64, f64)>) -> Series {
        Series {
            label: label.into(),
            color,
            points,
            line: false,
        }
    }

    /// Points joined by a polyline.
    pub fn line(label: impl Into<String>, color: &'static str, points: Vec<(f64, f64)>) -> Series {
        Series {
            label: label.into(),
            color,
            points,
            line: true,
        }
    }
}

/// One panel of a figure.
pub struct Panel {
    /// Title above the panel.
    pub title: String,
    /// X-axis label with unit.
    pub xlabel: String,
    /// Y-axis label with unit.
    pub ylabel: String,
    /// Series drawn in order.
    pub series: Vec<Series>,
    /// Same scale on both axes (scatter of vector components).
    pub equal: bool,
}

const W: f64 = 420.0;
const H: f64 = 360.0;
const ML: f64 = 62.0;
const MR: f64 = 14.0;
const MT: f64 = 30.0;
const MB: f64 = 46.0;
/// Most dots drawn per series (evenly decimated) to keep the SVG small.
const MAX_DOTS: usize = 1200;

fn nice_step(range: f64) -> f64 {
    let raw = range / 5.0;
    let p = 10f64.powf(raw.log10().floor());
    let m = raw / p;
    p * if m < 1.5 {
        1.0
    } else if m < 3.5 {
        2.0
    } else if m < 7.5 {
        5.0
    } else {
        10.0
    }
}

fn fmt_tick(v: f64, step: f64) -> String {
    let dec = if step >= 1.0 {
        0
    } else {
        (-step.log10().floor()) as usize
    };
    format!("{v:.dec$}")
}

/// Render panels on a grid of `cols` columns as one SVG document.
pub fn figure(title: &str, panels: &[Panel], cols: usize) -> String {
    let cols = cols.max(1);
    let rows = panels.len().div_ceil(cols);
    let (fw, fh) = (W * cols as f64, H * rows as f64 + 28.0);
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{fw}" height="{fh}" viewBox="0 0 {fw} {fh}" font-family="sans-serif" font-size="11">"#
    );
    let _ = write!(s, r#"<rect width="{fw}" height="{fh}" fill="white"/>"#);
    let _ = write!(
        s,
        r#"<text x="{}" y="18" text-anchor="middle" font-size="14" font-weight="bold">{}</text>"#,
        fw / 2.0,
        esc(title)
    );
    for (i, p) in panels.iter().enumerate() {
        let ox = (i % cols) as f64 * W;
        let oy = (i / cols) as f64 * H + 28.0;
        panel(&mut s, p, ox, oy);
    }
    s.push_str("</svg>\n");
    s
}

fn panel(s: &mut String, p: &Panel, ox: f64, oy: f64) {
    let pts = p
        .series
        .iter()
        .flat_map(|se| se.points.iter())
        .filter(|(x, y)| x.is_finite() && y.is_finite());
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, y) in pts {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if !x0.is_finite() {
        (x0, x1, y0, y1) = (-1.0, 1.0, -1.0, 1.0);
    }
    if x1 - x0 < 1e-12 {
        x0 -= 1.0;
        x1 += 1.0;
    }
    if y1 - y0 < 1e-12 {
        y0 -= 1.0;
        y1 += 1.0;
    }
    let (pw, ph) = (W - ML - MR, H - MT - MB);
    let pad = 0.05;
    let (dx, dy) = ((x1 - x0) * pad, (y1 - y0) * pad);
    (x0, x1, y0, y1) = (x0 - dx, x1 + dx, y0 - dy, y1 + dy);
    if p.equal {
        // Same units per pixel on both axes.
        let k = ((x1 - x0) / pw).max((y1 - y0) / ph);
        let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        (x0, x1) = (cx - k * pw / 2.0, cx + k * pw / 2.0);
        (y0, y1) = (cy - k * ph / 2.0, cy + k * ph / 2.0);
    }
    let px = |x: f64| ox + ML + (x - x0) / (x1 - x0) * pw;
    let py = |y: f64| oy + MT + ph - (y - y0) / (y1 - y0) * ph;
    let _ = write!(
        s,
        r##"<text x="{}" y="{}" text-anchor="middle" font-size="12" font-weight="bold">{}</text>"##,
        ox + ML + pw / 2.0,
        oy + MT - 10.0,
        esc(&p.title)
    );
    let _ = write!(
        s,
        r##"<rect x="{}" y="{}" width="{pw}" height="{ph}" fill="none" stroke="#444"/>"##,
        ox + ML,
        oy + MT
    );
    // Ticks and grid.
    let sx = nice_step(x1 - x0);
    // Ticks at integer multiples of the step (no accumulated rounding, no "-0.0").
    for t in ((x0 / sx).ceil() as i64..=(x1 / sx).floor() as i64).map(|k| k as f64 * sx + 0.0) {
        let x = px(t);
        let _ = write!(
            s,
            r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#ddd"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
            oy + MT,
            oy + MT + ph,
            oy + MT + ph + 14.0,
            fmt_tick(t, sx)
        );
    }
    let sy = nice_step(y1 - y0);
    for t in ((y0 / sy).ceil() as i64..=(y1 / sy).floor() as i64).map(|k| k as f64 * sy + 0.0) {
        let y = py(t);
        let _ = write!(
            s,
            r##"<line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
            ox + ML,
            ox + ML + pw,
            ox + ML - 4.0,
            y + 4.0,
            fmt_tick(t, sy)
        );
    }
    let _ = write!(
        s,
        r##"<text x="{}" y="{}" text-anchor="middle">{}</text>"##,
        ox + ML + pw / 2.0,
        oy + H - 12.0,
        esc(&p.xlabel)
    );
    let _ = write!(
        s,
        r##"<text x="{}" y="{}" text-anchor="middle" transform="rotate(-90 {} {})">{}</text>"##,
        ox + 14.0,
        oy + MT + ph / 2.0,
        ox + 14.0,
        oy + MT + ph / 2.0,
        esc(&p.ylabel)
    );
    for (k, se) in p.series.iter().enumerate() {
        if se.line {
            let mut d = String::new();
            for (i, &(x, y)) in se
                .points
                .iter()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .enumerate()
            {
                let _ = write!(
                    d,
                    "{}{:.1},{:.1}",
                    if i == 0 { "M" } else { " L" },
                    px(x),
                    py(y)
                );
            }
            let _ = write!(
                s,
                r##"<path d="{d}" fill="none" stroke="{}" stroke-width="1.8"/>"##,
                se.color
            );
        } else {
            let step = se.points.len().div_ceil(MAX_DOTS).max(1);
            let r = if se.points.len() < 100 { 3.0 } else { 1.3 };
            let _ = write!(s, r##"<g fill="{}" fill-opacity="0.6">"##, se.color);
            for &(x, y) in se
                .points
                .iter()
                .step_by(step)
                .filter(|(x, y)| x.is_finite() && y.is_finite())
            {
                let _ = write!(
                    s,
                    r##"<circle cx="{:.1}" cy="{:.1}" r="{r}"/>"##,
                    px(x),
                    py(y)
                );
            }
            s.push_str("</g>");
        }
        // Legend.
        let ly = oy + MT + 12.0 + 13.0 * k as f64;
        let lx = ox + ML + 8.0;
        let _ = write!(
            s,
            r##"<rect x="{}" y="{}" width="{:.0}" height="13" fill="white" fill-opacity="0.85"/><rect x="{lx}" y="{}" width="10" height="3" fill="{}"/><text x="{}" y="{ly}">{}</text>"##,
            lx - 2.0,
            ly - 10.0,
            18.0 + 6.2 * se.label.chars().count() as f64,
            ly - 5.0,
            se.color,
            lx + 14.0,
            esc(&se.label)
        );
    }
}
