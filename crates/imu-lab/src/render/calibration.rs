//! The calibration lab for people: the text report (parameters with their uncertainties and
//! units, what was excluded, the verdict, the candidates, the step or the walk's step table),
//! the HTML report, and the
//! figures (scatter before/after with the fitted ellipse and the circle, residuals against
//! orientation or temperature).
use imu_cal::accel::AccelProblem;
use imu_cal::lab::{Effect, Model, Params, Problem, Report};
use imu_cal::mag::MagProblem;
use nalgebra::{Matrix3, Vector3};

use super::esc;
use super::scatter::{figure, Panel, Series};
use crate::calibration::{Data, Loaded, Outcome};

/// `v ± s` with `prec` decimals (the σ to two significant digits when it needs more).
fn pm(v: f64, s: f64, prec: usize) -> String {
    if s.is_finite() && s > 0.0 {
        format!("{v:.prec$} ± {}", super::sig(s, 2))
    } else if s == 0.0 {
        format!("{v:.prec$}")
    } else {
        format!("{v:.prec$} ± ? (no degree of freedom left)")
    }
}

fn v3(v: &[f64; 3], s: Option<&[f64; 3]>, prec: usize) -> String {
    let sg = s.copied().unwrap_or([f64::NAN; 3]);
    format!(
        "[{}, {}, {}]",
        pm(v[0], sg[0], prec),
        pm(v[1], sg[1], prec),
        pm(v[2], sg[2], prec)
    )
}

/// `  name = [x ± σ, y ± σ, z ± σ] unit` for a 3-vector parameter, nothing when it is absent.
fn vector_line(
    name: &str,
    v: Option<&[f64; 3]>,
    sigma: Option<&[f64; 3]>,
    prec: usize,
    unit: &str,
) -> String {
    match v {
        Some(v) => format!("  {name:<17}= {} {unit}\n", v3(v, sigma, prec)),
        None => String::new(),
    }
}

/// The parameters with their 1σ uncertainties, one per line, in `unit` (the data's unit).
pub fn params_text(p: &Params, sg: &Params, unit: &str) -> String {
    let mut s = String::new();
    s += &vector_line("offset", p.offset.as_ref(), sg.offset.as_ref(), 5, unit);
    s += &vector_line(
        "scale",
        p.scale.as_ref(),
        sg.scale.as_ref(),
        6,
        "(dimensionless)",
    );
    s += &vector_line(
        "misalignment",
        p.misalignment_deg.as_ref(),
        sg.misalignment_deg.as_ref(),
        4,
        "deg",
    );
    if let Some(v) = &p.gyro_misalignment_deg {
        let e = sg.gyro_misalignment_deg.unwrap_or([f64::NAN; 6]);
        let parts: Vec<String> = (0..6).map(|k| pm(v[k], e[k], 4)).collect();
        s += &format!("  misalignment     = [{}] deg (γ₁…γ₆)\n", parts.join(", "));
    }
    if let Some(g) = p.g {
        s += &format!("  g                = {g} {unit} (given)\n");
    }
    s += &vector_line("bias", p.bias.as_ref(), sg.bias.as_ref(), 5, unit);
    s += &vector_line(
        "temp_coeff",
        p.temp_coeff.as_ref(),
        sg.temp_coeff.as_ref(),
        6,
        &format!("{unit} per °C"),
    );
    if let Some(t) = p.temp_ref {
        s += &format!("  temp_ref         = {t:.3} °C (mean of the record)\n");
    }
    s += &vector_line(
        "hard_iron",
        p.hard_iron.as_ref(),
        sg.hard_iron.as_ref(),
        4,
        unit,
    );
    if let Some(m) = &p.soft_iron {
        let e = sg.soft_iron.unwrap_or([[f64::NAN; 3]; 3]);
        s += &format!(
            "  soft_iron        = [{},\n                      {},\n                      {}] (dimensionless)\n",
            v3(&m[0], Some(&e[0]), 5),
            v3(&m[1], Some(&e[1]), 5),
            v3(&m[2], Some(&e[2]), 5)
        );
    }
    if let Some(e) = &p.soft_iron_2d {
        let u = sg
            .soft_iron_2d
            .map_or([f64::NAN; 4], |u| [u.r, u.q, u.theta_deg, u.sigma]);
        s += &format!(
            "  soft_iron_2d     = r {} {unit}, q {} {unit}, θ {} deg, σ = q/r {}\n",
            pm(e.r, u[0], 4),
            pm(e.q, u[1], 4),
            pm(e.theta_deg, u[2], 3),
            pm(e.sigma, u[3], 5)
        );
    }
    if let Some(f) = p.field {
        s += &format!(
            "  field F          = {} {unit}\n",
            pm(f, sg.field.unwrap_or(f64::NAN), 4)
        );
    }
    s
}

/// What the data are and what was excluded before fitting.
fn header(l: &Loaded) -> String {
    let data = &l.data;
    let unit = data.problem().unit();
    let mut s = match data {
        Data::Accel(a) => format!(
            "calibrate accel: {} static poses found (g = {} {unit})\n",
            a.poses.len(),
            a.g
        ),
        Data::Gyro(g) => format!(
            "calibrate gyro: {} blocks of {} samples{}\n",
            g.blocks[0].len(),
            g.block_len,
            if g.temp.is_some() {
                ", with temperature"
            } else {
                ", no temperature column"
            }
        ),
        Data::GyroRot(g) => format!(
            "calibrate gyro (scale/misalignment from rotations): {} moves between static \
             poses, {} skipped as saturated, {} holding excluded samples; bias removed {} \
             deg/s\n",
            g.moves.len(),
            g.skipped_saturated,
            g.skipped_flagged,
            v3(&g.bias, Some(&g.bias_sigma), 5)
        ),
        Data::Mag(m) => format!(
            "calibrate mag: {} samples, principal s.d. {:.2}/{:.2}/{:.2} {unit} ({})\n",
            m.m.len(),
            m.principal_sd[0],
            m.principal_sd[1],
            m.principal_sd[2],
            match m.plane {
                Some([i, j]) => format!(
                    "planar in the {}{} plane",
                    ["x", "y", "z"][i],
                    ["x", "y", "z"][j]
                ),
                None => "3-D".into(),
            }
        ),
    };
    if let Some(d) = l.sentinels.describe() {
        s += &format!("excluded before fitting: {d}\n");
    }
    for n in &l.notes {
        s += &format!("note: {n}\n");
    }
    s
}

fn names(m: &[Effect]) -> String {
    if m.is_empty() {
        "(none)".to_string()
    } else {
        m.iter().map(|e| e.name()).collect::<Vec<_>>().join(", ")
    }
}

/// The report on one model: parameters, residual against the floor, verdict, candidates,
/// diagnosis and the step that adds the missing effect.
fn model_text(p: &dyn Problem, r: &Report, heading: &str) -> String {
    let unit = p.unit();
    let m = &r.model;
    let mut s = format!(
        "{heading}: {}\nparams (± 1σ):\n{}",
        names(m.effects()),
        params_text(&m.fitted.params, &m.fitted.sigma, unit)
    );
    s += &format!(
        "residual RMS {:.5} {unit} over {} residuals{}; noise floor {:.5} {unit} (σ {:.5} {unit} from {})\n",
        m.fitted.rms(),
        m.fitted.n_used(),
        if m.outliers > 0 {
            format!(
                " ({} {} beyond 6σ excluded as outliers)",
                m.outliers,
                p.items()
            )
        } else {
            String::new()
        },
        m.expected_rms,
        m.floor.sigma,
        m.floor.method
    );
    s += &format!(
        "verdict: {} (s²/σ² = {})\n",
        m.verdict.word(),
        super::sig(m.ratio, 3)
    );
    let d = &r.diagnosis;
    if !d.candidates.is_empty() || !d.not_tried.is_empty() {
        s += "candidates:\n";
        for c in &d.candidates {
            s += &format!(
                "  {:<13} residual RMS {:.5} {unit}, s²/σ² {}: {}{}\n                {}\n",
                c.edit
                    .add
                    .iter()
                    .map(|e| e.name())
                    .collect::<Vec<_>>()
                    .join("+"),
                c.summary.rms_residual,
                super::sig(c.summary.chi2_dof, 3),
                c.reason,
                if c.admissible { " (admissible)" } else { "" },
                c.reading
            );
        }
        for n in &d.not_tried {
            s += &format!("  {:<13} not tried: {}\n", n.effect.name(), n.reason);
        }
    }
    s += &format!("diagnosis: {}\n", d.explanation);
    if let (Some(st), Some(next)) = (&r.step, r.next()) {
        s += &format!(
            "step: {} → model {}: residual RMS {:.5} → {:.5} {unit}, s²/σ² {} → {}, {}\nparams after the step (± 1σ):\n{}",
            st.edit,
            names(next.effects()),
            st.before.rms_residual,
            st.after.rms_residual,
            super::sig(st.before.chi2_dof, 3),
            super::sig(st.after.chi2_dof, 3),
            next.verdict.word(),
            params_text(&next.fitted.params, &next.fitted.sigma, unit)
        );
    }
    s
}

/// The whole text report of a run: the data, the walk when there was one, and the report on the
/// last model.
pub fn text_report(l: &Loaded, run: &Outcome) -> String {
    let p = l.data.problem();
    let mut s = header(l);
    match run.stop {
        None => s += &model_text(p, &run.report, "model"),
        Some(stop) => {
            s += &format!(
                "walk from model {}: diagnose → add the named effect → refit\n{}stop: {stop}.\n",
                names(run.start.effects()),
                super::steps::table(&run.steps, "s²/σ²", "residual RMS")
            );
            s += &model_text(p, &run.report, "final model");
        }
    }
    s + &plausibility_line(l, run)
}

/// The fitted model against the parts' datasheet bounds, one line: an adequate fit of an
/// impossible part (a wrong range or unit) is still refused by `--out` and by an upload.
fn plausibility_line(l: &Loaded, run: &Outcome) -> String {
    let parts = imu_cal::session::judged_part(l);
    match imu_cal::session::plausibility(l, run) {
        Ok(None) => format!(
            "plausibility: within the datasheet bounds of the {parts} (docs/calibration.md, \
             \"Plausibility\")\n"
        ),
        Ok(Some(why)) => format!(
            "plausibility: NOT PLAUSIBLE for the {parts}, {why}: a wrong part, range or unit? \
             --out and an upload refuse it\n"
        ),
        Err(why) => format!("plausibility: {why}\n"),
    }
}

/// A self-contained HTML page: the text report and the figure.
pub fn html_report(l: &Loaded, run: &Outcome, svg: &str) -> String {
    let sensor = l.data.problem().sensor();
    format!(
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>imu-lab calibrate {sensor}</title>\
         <style>body{{font-family:sans-serif;max-width:1300px;margin:2em auto}}pre{{background:#f6f6f6;padding:1em;white-space:pre-wrap}}</style>\
         </head><body><h1>Calibration lab: {sensor}</h1><pre>{}</pre>{svg}</body></html>\n",
        esc(&text_report(l, run))
    )
}

fn mag_matrix(p: &Params) -> Matrix3<f64> {
    p.soft_iron
        .map(|s| Matrix3::from_row_slice(&s.concat()))
        .unwrap_or_else(Matrix3::identity)
}

/// Central section of the fitted ellipsoid {m : |S(m − h)| = f} by the plane of axes (i, j)
/// through h: the radius along a direction d of that plane is f/|S·d|.
fn section(p: &Params, i: usize, j: usize, f: f64) -> Vec<(f64, f64)> {
    let s = mag_matrix(p);
    let h = p.hard_iron.unwrap_or([0.0; 3]);
    (0..=180)
        .map(|k| {
            let a = 2.0 * std::f64::consts::PI * k as f64 / 180.0;
            let mut d = Vector3::zeros();
            d[i] = a.cos();
            d[j] = a.sin();
            let r = f / (s * d).norm();
            (h[i] + r * d[i], h[j] + r * d[j])
        })
        .collect()
}

fn circle(r: f64) -> Vec<(f64, f64)> {
    (0..=180)
        .map(|k| {
            let a = 2.0 * std::f64::consts::PI * k as f64 / 180.0;
            (r * a.cos(), r * a.sin())
        })
        .collect()
}

const AX: [&str; 3] = ["X", "Y", "Z"];

/// The figure of a run (an SVG document): the `before` model against `after` (the model after
/// the step or the walk) when there is one.
pub fn plot(data: &Data, before: &Model, after_model: Option<&Model>) -> String {
    let has_after = after_model.is_some();
    let after_m = after_model.unwrap_or(before);
    let after = &after_m.fitted.params;
    let join = |m: &[Effect]| m.iter().map(|e| e.name()).collect::<Vec<_>>().join("+");
    let after_name = join(after_m.effects());
    let before_name = join(before.effects());
    let before_name = if before_name.is_empty() {
        "no correction".to_string()
    } else {
        before_name
    };
    // The residuals of the `before` model (orange) and, when there is one, the after model
    // (green).
    let residuals = |before: Vec<(f64, f64)>, after: Vec<(f64, f64)>| {
        let mut s = vec![Series::dots(before_name.clone(), "#ff7f0e", before)];
        if has_after {
            s.push(Series::dots(after_name.clone(), "#2ca02c", after));
        }
        s
    };
    match data {
        Data::Mag(m) => {
            let unit = m.unit.as_str();
            let corr: Vec<Vector3<f64>> =
                m.m.iter().map(|v| MagProblem::correct(after, *v)).collect();
            let before_corr: Vec<Vector3<f64>> =
                m.m.iter()
                    .map(|v| MagProblem::correct(&before.fitted.params, *v))
                    .collect();
            // With tilt the fitted F is the full field: the planar views draw the in-plane part
            // it leaves on average, √(F² − mean out-of-plane²).
            let after_tilt = after_m.effects().contains(&Effect::Tilt);
            let f = match (m.plane, after_tilt) {
                (Some([i, j]), true) => {
                    let k = 3 - i - j;
                    let z2 = corr.iter().map(|v| v[k] * v[k]).sum::<f64>() / corr.len() as f64;
                    (after.field.unwrap_or(1.0).powi(2) - z2).max(0.0).sqrt()
                }
                _ => after.field.unwrap_or(1.0),
            };
            // Planar data are fitted (and so drawn) in their plane; 3-D data in XY and YZ.
            let pairs: Vec<(usize, usize)> = match m.plane {
                Some([i, j]) => vec![(i, j)],
                None => vec![(0, 1), (1, 2)],
            };
            let mut panels = Vec::new();
            for &(i, j) in &pairs {
                let (ni, nj) = (AX[i].to_lowercase(), AX[j].to_lowercase());
                // Components i and j of the field, at one scale.
                let plane = |title: String, series: Vec<Series>| Panel {
                    title,
                    xlabel: format!("m{ni} ({unit})"),
                    ylabel: format!("m{nj} ({unit})"),
                    series,
                    equal: true,
                };
                panels.push(plane(
                    format!("{}{} before (raw) with the fitted ellipse", AX[i], AX[j]),
                    vec![
                        Series::dots(
                            "measured",
                            "#1f77b4",
                            m.m.iter().map(|v| (v[i], v[j])).collect(),
                        ),
                        Series::line(
                            format!("fitted ({after_name}) section"),
                            "#d62728",
                            section(after, i, j, f),
                        ),
                    ],
                ));
                panels.push(plane(
                    format!("{}{} after ({after_name})", AX[i], AX[j]),
                    vec![
                        Series::dots(
                            "corrected",
                            "#2ca02c",
                            corr.iter().map(|v| (v[i], v[j])).collect(),
                        ),
                        Series::line(
                            if after_tilt && m.plane.is_some() {
                                format!("in-plane field {f:.2} {unit}")
                            } else {
                                format!("circle F = {f:.2} {unit}")
                            },
                            "#d62728",
                            circle(f),
                        ),
                    ],
                ));
            }
            // Residuals on the lab's basis (the problem's own residual: in-plane magnitude for
            // planar data, full magnitude in 3-D or with tilt) against the orientation of the
            // corrected field.
            type VecFn<'a> = Box<dyn Fn(&Vector3<f64>) -> f64 + 'a>;
            type Ang<'a> = (&'static str, VecFn<'a>);
            let angles: Vec<Ang> = match m.plane {
                Some([i, j]) => vec![(
                    "in-plane angle",
                    Box::new(move |v: &Vector3<f64>| v[j].atan2(v[i]).to_degrees()),
                )],
                None => vec![
                    (
                        "azimuth",
                        Box::new(|v: &Vector3<f64>| v.y.atan2(v.x).to_degrees()),
                    ),
                    (
                        "elevation",
                        Box::new(|v: &Vector3<f64>| (v.z / v.norm()).asin().to_degrees()),
                    ),
                ],
            };
            let after_model = &after_m.fitted.model;
            let res_before: Vec<f64> =
                m.m.iter()
                    .map(|v| m.residual(&before.fitted.model, &before.fitted.params, *v))
                    .collect();
            let res_after: Vec<f64> =
                m.m.iter()
                    .map(|v| m.residual(after_model, after, *v))
                    .collect();
            for (name, ang) in &angles {
                panels.push(Panel {
                    title: format!("residual |m| − F against {name}"),
                    xlabel: format!("{name} of the corrected field (deg)"),
                    ylabel: format!("|m| − F ({unit})"),
                    series: residuals(
                        before_corr
                            .iter()
                            .zip(&res_before)
                            .map(|(v, e)| (ang(v), *e))
                            .collect(),
                        corr.iter()
                            .zip(&res_after)
                            .map(|(v, e)| (ang(v), *e))
                            .collect(),
                    ),
                    equal: false,
                });
            }
            figure("imu-lab calibrate mag", &panels, 2)
        }
        Data::Accel(a) => {
            let g = a.g;
            let unit = a.unit.as_str();
            let raw: Vec<[f64; 3]> = a.poses.iter().map(|p| p.mean).collect();
            let corr: Vec<[f64; 3]> = raw
                .iter()
                .map(|v| AccelProblem::correct(after, *v))
                .collect();
            let bef: Vec<[f64; 3]> = raw
                .iter()
                .map(|v| AccelProblem::correct(&before.fitted.params, *v))
                .collect();
            let mut panels = Vec::new();
            for (i, j) in [(0, 1), (1, 2)] {
                panels.push(Panel {
                    title: format!("{}{} pose means before / after", AX[i], AX[j]),
                    xlabel: format!("a{} ({unit})", AX[i].to_lowercase()),
                    ylabel: format!("a{} ({unit})", AX[j].to_lowercase()),
                    series: vec![
                        Series::dots("raw", "#1f77b4", raw.iter().map(|v| (v[i], v[j])).collect()),
                        Series::dots(
                            format!("corrected ({after_name})"),
                            "#2ca02c",
                            corr.iter().map(|v| (v[i], v[j])).collect(),
                        ),
                        Series::line(format!("circle g = {g} {unit}"), "#d62728", circle(g)),
                    ],
                    equal: true,
                });
            }
            let el = |v: &[f64; 3]| (v[2] / Vector3::from(*v).norm()).asin().to_degrees();
            let az = |v: &[f64; 3]| v[1].atan2(v[0]).to_degrees();
            for (name, ang) in [
                ("elevation", &el as &dyn Fn(&[f64; 3]) -> f64),
                ("azimuth", &az),
            ] {
                panels.push(Panel {
                    title: format!("pose residual |a| − g against {name}"),
                    xlabel: format!("{name} of gravity in the sensor frame (deg)"),
                    ylabel: format!("|a| − g ({unit})"),
                    series: residuals(
                        bef.iter()
                            .map(|v| (ang(v), Vector3::from(*v).norm() - g))
                            .collect(),
                        corr.iter()
                            .map(|v| (ang(v), Vector3::from(*v).norm() - g))
                            .collect(),
                    ),
                    equal: false,
                });
            }
            figure("imu-lab calibrate accel", &panels, 2)
        }
        Data::GyroRot(gp) => {
            // Residual per move (two components, deg) against the turn angle of the move.
            let angle = |mv: &imu_cal::gyro_rot::Move| mv.u0.angle(&mv.u1).to_degrees();
            let pts = |res: &[f64]| -> Vec<(f64, f64)> {
                gp.moves
                    .iter()
                    .enumerate()
                    .flat_map(|(k, mv)| [(angle(mv), res[2 * k]), (angle(mv), res[2 * k + 1])])
                    .collect()
            };
            let after_res = if has_after {
                after_m.fitted.residuals.clone()
            } else {
                vec![]
            };
            let mut series = vec![Series::dots(
                before_name.clone(),
                "#ff7f0e",
                pts(&before.fitted.residuals),
            )];
            if after_res.len() == before.fitted.residuals.len() {
                series.push(Series::dots(after_name.clone(), "#2ca02c", pts(&after_res)));
            }
            let panels = vec![Panel {
                title: "gravity-direction residual per move".into(),
                xlabel: "tilt change of the move (deg)".into(),
                ylabel: "residual component (deg)".into(),
                series,
                equal: false,
            }];
            figure("imu-lab calibrate gyro (rotations)", &panels, 1)
        }
        Data::Gyro(gp) => {
            let nb = gp.blocks[0].len();
            let t: Vec<f64> = gp
                .temp
                .clone()
                .unwrap_or_else(|| (0..nb).map(|i| i as f64).collect());
            let xl = if gp.temp.is_some() {
                "block mean temperature (°C)"
            } else {
                "block index (no temperature column)"
            };
            let resid = |p: &Params, j: usize| -> Vec<(f64, f64)> {
                let b = p.bias.map(|b| b[j]).unwrap_or(0.0);
                let k = p.temp_coeff.map(|k| k[j]).unwrap_or(0.0);
                let tr = p.temp_ref.unwrap_or(0.0);
                (0..nb)
                    .map(|i| (t[i], gp.blocks[j][i] - b - k * (t[i] - tr)))
                    .collect()
            };
            let panels: Vec<Panel> = (0..3)
                .map(|j| Panel {
                    title: format!("g{} residual against temperature", AX[j].to_lowercase()),
                    xlabel: xl.into(),
                    ylabel: format!("block-mean residual ({})", gp.unit),
                    series: residuals(resid(&before.fitted.params, j), resid(after, j)),
                    equal: false,
                })
                .collect();
            figure("imu-lab calibrate gyro", &panels, 3)
        }
    }
}
