//! The step table of a lab walk, the same for every lab: per step the edit, the lab's
//! goodness-of-fit statistic and RMS residual before → after, the verdict before → after, and
//! the effect's physical reading with the p-value of its test.
use std::fmt::Display;

use model_lab::Step;

use super::sig;

/// The table of `steps`: `stat` names the summary's goodness-of-fit statistic (e.g. "χ²/dof"),
/// `rms` its RMS residual (e.g. "RMS log-residual"), whose unit each step's summary carries.
pub fn table<E: Display>(steps: &[Step<E>], stat: &str, rms: &str) -> String {
    if steps.is_empty() {
        return "  (no step: nothing to add)\n".into();
    }
    let yn = |b: bool| if b { "yes" } else { "no" };
    let mut s = String::new();
    for (i, st) in steps.iter().enumerate() {
        let unit = if st.after.rms_unit.is_empty() {
            String::new()
        } else {
            format!(" {}", st.after.rms_unit)
        };
        let after = format!("{}{unit}", sig(st.after.rms_residual, 3));
        let width = 7 + unit.chars().count();
        s += &format!(
            "  {}. {:<24} {stat} {:>9} → {:<9} {rms} {:>7} → {:<width$} adequate {} → {}\n     {} (p = {})\n",
            i + 1,
            st.edit.to_string(),
            sig(st.before.chi2_dof, 3),
            sig(st.after.chi2_dof, 3),
            sig(st.before.rms_residual, 3),
            after,
            yn(st.before.adequate),
            yn(st.after.adequate),
            st.reading,
            sig(st.p_value, 2)
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use model_lab::{Edit, Summary};

    fn summary(chi2_dof: f64, rms: f64, unit: &str, adequate: bool) -> Summary {
        Summary {
            chi2_dof,
            rms_residual: rms,
            rms_unit: unit.into(),
            adequate,
            params: 3,
        }
    }

    #[test]
    fn one_line_per_step_with_the_unit_after_the_residuals() {
        let step = |unit: &str| Step {
            edit: Edit {
                add: vec!["soft_iron"],
                remove: vec![],
            },
            before: summary(358.46, 3.1532, unit, false),
            after: summary(7.1412, 0.44461, unit, false),
            p_value: 1.2e-9,
            reading: "an ellipsoid".to_string(),
            reason: String::new(),
        };
        assert_eq!(
            table(&[step("µT")], "s²/σ²", "residual RMS"),
            "  1. + soft_iron              s²/σ²       358 → 7.14      residual RMS    3.15 → 0.445 µT   adequate no → no\n     an ellipsoid (p = 1.2e-9)\n"
        );
        // Without a unit the columns are those of the noise lab's table.
        assert_eq!(
            table(&[step("")], "χ²/dof", "RMS log-residual"),
            "  1. + soft_iron              χ²/dof       358 → 7.14      RMS log-residual    3.15 → 0.445   adequate no → no\n     an ellipsoid (p = 1.2e-9)\n"
        );
        assert_eq!(
            table::<&str>(&[], "χ²/dof", "RMS"),
            "  (no step: nothing to add)\n"
        );
    }
}
