//! The physical reading of an effect as fitted: one phrase with its numbers, their 1σ and units,
//! for the candidates and the steps of the lab.
use super::{Effect, Params};

/// `v ± s`, both to the decimal place of s's second significant digit; `v` alone for a given
/// value (s = 0); "σ unknown" when the data leave no degree of freedom.
fn pm(v: f64, s: f64) -> String {
    if s.is_finite() && s > 0.0 {
        let d = (1 - s.log10().floor() as i32).clamp(0, 12) as usize;
        format!("{v:.d$} ± {s:.d$}")
    } else if s == 0.0 {
        format!("{v}")
    } else {
        format!("{v:.4} (σ unknown)")
    }
}

fn vec_pm(v: &[f64], s: Option<&[f64]>) -> String {
    let parts: Vec<String> = v
        .iter()
        .enumerate()
        .map(|(k, x)| pm(*x, s.and_then(|s| s.get(k)).copied().unwrap_or(f64::NAN)))
        .collect();
    format!("({})", parts.join(", "))
}

/// Radii of the ellipsoid `{m : |S(m − h)| = F}`: F over the eigenvalues of the symmetric S,
/// largest first.
fn ellipsoid_radii(s: &[[f64; 3]; 3], f: f64) -> Vec<f64> {
    let m = nalgebra::Matrix3::from_row_slice(&s.concat());
    let mut r: Vec<f64> = m
        .symmetric_eigen()
        .eigenvalues
        .iter()
        .map(|l| f / l)
        .collect();
    r.sort_by(|a, b| b.total_cmp(a));
    r
}

/// The reading of effect `e` in the fitted parameters `p` (1σ in `s`), in `unit`, the data's.
pub fn reading(e: Effect, p: &Params, s: &Params, unit: &str) -> String {
    let missing = || format!("{} (not in the parameters)", e.name());
    match e {
        Effect::Offset => p.offset.map_or_else(missing, |v| {
            format!(
                "a zero-g offset of {} {unit}",
                vec_pm(&v, s.offset.as_ref().map(|x| &x[..]))
            )
        }),
        Effect::Scale => p.scale.map_or_else(missing, |v| {
            let pct: Vec<f64> = v.iter().map(|x| (x - 1.0) * 100.0).collect();
            let spct: Option<Vec<f64>> = s.scale.map(|x| x.iter().map(|y| y * 100.0).collect());
            format!(
                "gains off by {} % (scale factors − 1)",
                vec_pm(&pct, spct.as_deref())
            )
        }),
        Effect::Misalignment => match (&p.misalignment_deg, &p.gyro_misalignment_deg) {
            (Some(v), _) => format!(
                "axes off orthogonal by {} deg (y from x, z from x, z from y)",
                vec_pm(v, s.misalignment_deg.as_ref().map(|x| &x[..]))
            ),
            (None, Some(v)) => format!(
                "gyro axes turned by {} deg (γ₁…γ₆)",
                vec_pm(v, s.gyro_misalignment_deg.as_ref().map(|x| &x[..]))
            ),
            (None, None) => missing(),
        },
        Effect::Bias => p.bias.map_or_else(missing, |v| {
            format!(
                "a rate offset at rest of {} {unit}",
                vec_pm(&v, s.bias.as_ref().map(|x| &x[..]))
            )
        }),
        Effect::Temperature => p.temp_coeff.map_or_else(missing, |v| {
            format!(
                "the bias moves by {} {unit} per °C around {}",
                vec_pm(&v, s.temp_coeff.as_ref().map(|x| &x[..])),
                p.temp_ref
                    .map_or("the mean temperature".into(), |t| format!("{t:.2} °C"))
            )
        }),
        Effect::HardIron => p.hard_iron.map_or_else(missing, |v| {
            format!(
                "a constant field of {} {unit} from magnetised parts",
                vec_pm(&v, s.hard_iron.as_ref().map(|x| &x[..]))
            )
        }),
        Effect::SoftIron => match (&p.soft_iron, p.field) {
            (Some(m), Some(f)) => {
                let r = ellipsoid_radii(m, f);
                format!(
                    "the sphere is an ellipsoid of radii {:.2}/{:.2}/{:.2} {unit} (F over the \
                     eigenvalues of S; S and F = {} {unit} with their 1σ in the parameters)",
                    r[0],
                    r[1],
                    r[2],
                    pm(f, s.field.unwrap_or(f64::NAN))
                )
            }
            _ => missing(),
        },
        Effect::SoftIron2d => p.soft_iron_2d.map_or_else(missing, |v| {
            let u = s.soft_iron_2d;
            let su = |g: fn(&super::SoftIron2d) -> f64| u.as_ref().map_or(f64::NAN, g);
            format!(
                "an ellipse of semi-axes r = {} {unit}, q = {} {unit}, tilted θ = {} deg, \
                 σ = q/r = {}",
                pm(v.r, su(|x| x.r)),
                pm(v.q, su(|x| x.q)),
                pm(v.theta_deg, su(|x| x.theta_deg)),
                pm(v.sigma, su(|x| x.sigma))
            )
        }),
        Effect::Tilt => match (&p.hard_iron, p.field) {
            (Some(h), Some(f)) => format!(
                "the turn wobbles out of its plane: full field F = {} {unit}, hard iron {} {unit} \
                 with its out-of-plane component",
                pm(f, s.field.unwrap_or(f64::NAN)),
                vec_pm(h, s.hard_iron.as_ref().map(|x| &x[..]))
            ),
            _ => missing(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_and_sigma_share_the_sigmas_decimals() {
        assert_eq!(pm(0.987984, 2.7e-4), "0.98798 ± 0.00027");
        assert_eq!(pm(-20.593, 0.017), "-20.593 ± 0.017");
        assert_eq!(pm(53.4681, 1.3), "53.5 ± 1.3");
        assert_eq!(pm(9.80665, 0.0), "9.80665");
        assert!(pm(1.0, f64::NAN).contains("σ unknown"));
    }

    #[test]
    fn ellipsoid_radii_are_f_over_the_eigenvalues() {
        let s = [[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.5]];
        assert_eq!(ellipsoid_radii(&s, 10.0), vec![20.0, 10.0, 5.0]);
        let p = Params {
            scale: Some([1.01, 0.98, 1.0]),
            ..Params::default()
        };
        let sg = Params {
            scale: Some([0.001, 0.002, 0.0005]),
            ..Params::default()
        };
        assert_eq!(
            reading(Effect::Scale, &p, &sg, "m/s²"),
            "gains off by (1.00 ± 0.10, -2.00 ± 0.20, 0.000 ± 0.050) % (scale factors − 1)"
        );
    }
}
