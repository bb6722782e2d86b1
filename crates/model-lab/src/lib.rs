//! The lab workflow, written once for every lab of the project: a model made of named effects is
//! fitted to a measurement and assessed against the measurement's own uncertainty; when it is not
//! adequate, candidate edits (add an effect, or replace one by a better-founded one) are refitted
//! and tested; the best admissible one is applied and the error is shown falling, step by step,
//! until the model is adequate or nothing helps.
//!
//! A lab (the noise lab on Allan curves, the calibration lab on residuals) implements [`Lab`]:
//! how to summarise a fitted model, and which candidates it has, each refitted, tested by a
//! nested-model test and ranked by the lab's own rule (its evidence gates, its penalised
//! criterion). [`walk`] is the loop; [`Step`] is the before → after record the reports print.
//!
//! ```
//! use model_lab::{walk, Candidate, Candidates, Edit, Lab, Stop, Summary};
//!
//! /// A toy lab: the measurement holds effects 1 and 2; each one the model lacks adds 1 to
//! /// χ²/dof, and effect 3, never in the measurement, would not lower it.
//! struct Toy;
//! impl Lab for Toy {
//!     type Effect = u32;
//!     type Model = Vec<u32>;
//!     type Error = String;
//!     fn summary(&self, m: &Vec<u32>) -> Summary {
//!         let missing = [1, 2].iter().filter(|e| !m.contains(e)).count();
//!         Summary {
//!             chi2_dof: 1.0 + missing as f64,
//!             rms_residual: missing as f64,
//!             rms_unit: String::new(),
//!             adequate: missing == 0,
//!             params: m.len(),
//!         }
//!     }
//!     fn candidates(&self, m: &Vec<u32>) -> Result<Candidates<Self>, String> {
//!         let now = self.summary(m).chi2_dof;
//!         Ok([1, 2, 3].into_iter().filter(|e| !m.contains(e)).map(|e| {
//!             let model = [m.clone(), vec![e]].concat();
//!             let summary = self.summary(&model);
//!             let delta = now - summary.chi2_dof;
//!             Candidate {
//!                 edit: Edit { add: vec![e], remove: vec![] },
//!                 model, summary, delta, extra_params: 1,
//!                 p_value: if delta > 0.0 { 1e-6 } else { 1.0 },
//!                 admissible: delta > 0.0,
//!                 reason: String::new(), reading: format!("effect {e}"),
//!             }
//!         }).collect())
//!     }
//! }
//!
//! let w = walk(&Toy, vec![], 10).unwrap();
//! assert_eq!(w.stop, Stop::Adequate);
//! assert_eq!(w.last(), &vec![1, 2]);
//! // The error falls at each step: χ²/dof 3 → 2 → 1.
//! let falls: Vec<(f64, f64)> = w.steps.iter().map(|s| (s.before.chi2_dof, s.after.chi2_dof)).collect();
//! assert_eq!(falls, [(3.0, 2.0), (2.0, 1.0)]);
//! ```
use std::fmt;

/// How a fitted model compares with its measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// The goodness-of-fit statistic per degree of freedom (χ²/dof, or the lab's equivalent:
    /// residual variance over the noise floor).
    pub chi2_dof: f64,
    /// RMS residual in the lab's natural scale (log-residual of an Allan curve, residual RMS of a
    /// calibration) and its unit ("" for ratios).
    pub rms_residual: f64,
    pub rms_unit: String,
    /// Whether the model describes the measurement (the lab's verdict).
    pub adequate: bool,
    /// Free parameters.
    pub params: usize,
}

/// A change of a model: effects added and removed.
#[derive(Debug, Clone, PartialEq)]
pub struct Edit<E> {
    pub add: Vec<E>,
    pub remove: Vec<E>,
}

impl<E: fmt::Display> fmt::Display for Edit<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let add: Vec<String> = self.add.iter().map(|e| format!("+ {e}")).collect();
        let rem: Vec<String> = self.remove.iter().map(|e| format!("− {e}")).collect();
        write!(
            f,
            "{}",
            add.into_iter().chain(rem).collect::<Vec<_>>().join(", ")
        )
    }
}

/// A candidate edit, refitted and tested.
#[derive(Debug, Clone)]
pub struct Candidate<E, M> {
    pub edit: Edit<E>,
    /// The refitted model.
    pub model: M,
    pub summary: Summary,
    /// Drop of the goodness-of-fit statistic from the current model.
    pub delta: f64,
    /// Change in the number of free parameters.
    pub extra_params: i64,
    /// p-value of the lab's test for this edit (nested χ² or F test, or a time-domain test).
    pub p_value: f64,
    /// Whether the lab would apply it (significant, evidence present, not over-fitting).
    pub admissible: bool,
    /// Why it is, or is not, admissible: the evidence, in words.
    pub reason: String,
    /// The physical reading of the effect as fitted (e.g. "a low-pass at 5.1 Hz").
    pub reading: String,
}

/// One step of a walk: what was changed and the measurement of the error before and after.
#[derive(Debug, Clone, PartialEq)]
pub struct Step<E> {
    pub edit: Edit<E>,
    pub before: Summary,
    pub after: Summary,
    pub p_value: f64,
    pub reading: String,
    pub reason: String,
}

impl<E: Clone> Step<E> {
    /// The step that applies candidate `c` to a model summarised by `before`.
    pub fn of<M>(before: Summary, c: &Candidate<E, M>) -> Step<E> {
        Step {
            edit: c.edit.clone(),
            before,
            after: c.summary.clone(),
            p_value: c.p_value,
            reading: c.reading.clone(),
            reason: c.reason.clone(),
        }
    }
}

/// Why a walk ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop {
    /// The model is adequate.
    Adequate,
    /// No admissible candidate: nothing in the vocabulary helps.
    NothingHelps,
    /// The step limit was reached.
    StepLimit,
}

impl fmt::Display for Stop {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Stop::Adequate => "the model is adequate",
            Stop::NothingHelps => "no effect of the vocabulary helps further",
            Stop::StepLimit => "the step limit was reached",
        })
    }
}

/// A lab's candidates, best first.
pub type Candidates<L> = Vec<Candidate<<L as Lab>::Effect, <L as Lab>::Model>>;

/// A lab: how to summarise a model and which candidate edits it has.
pub trait Lab {
    type Effect: Clone + PartialEq + fmt::Display;
    type Model: Clone;
    type Error: fmt::Display;

    /// The summary of a fitted model.
    fn summary(&self, model: &Self::Model) -> Summary;

    /// The candidate edits of a model that is not adequate, refitted and tested, in the lab's
    /// order of preference (the walk takes the first admissible one).
    fn candidates(&self, model: &Self::Model) -> Result<Candidates<Self>, Self::Error>;

    /// Whether a model that no candidate improves is adequate: by default its summary's
    /// verdict. A lab whose verdict also counts findings that are tried as candidates (the noise
    /// lab's time-domain findings) settles on the one criterion instead: a finding the criterion
    /// refuses does not keep the model from being adequate.
    fn settled(
        &self,
        model: &Self::Model,
        _refused: &[Candidate<Self::Effect, Self::Model>],
    ) -> bool {
        self.summary(model).adequate
    }
}

/// The result of a walk.
#[derive(Debug, Clone)]
pub struct Walk<E, M> {
    /// Every model on the way, the start first.
    pub models: Vec<M>,
    pub steps: Vec<Step<E>>,
    pub stop: Stop,
    /// The candidates of the last model, when it was not adequate (what was tried last).
    pub last_candidates: Vec<Candidate<E, M>>,
}

impl<E, M> Walk<E, M> {
    /// The final model.
    pub fn last(&self) -> &M {
        self.models.last().expect("a walk holds its start model")
    }
}

/// Walk from `start`: apply the lab's first admissible candidate while there is one, at most
/// `max_steps` times. A model that passes the lab's goodness-of-fit verdict is still improvable
/// when a candidate is admissible (a test against a specific alternative has power that an
/// omnibus goodness-of-fit test lacks); such a step records the model before it as not adequate.
/// The walk ends adequate when the verdict passes and no candidate is admissible.
pub fn walk<L: Lab>(
    lab: &L,
    start: L::Model,
    max_steps: usize,
) -> Result<Walk<L::Effect, L::Model>, L::Error> {
    let mut models = vec![start];
    let mut steps = Vec::new();
    loop {
        let cur = models.last().expect("start model");
        let mut before = lab.summary(cur);
        let cands = lab.candidates(cur)?;
        let Some(best) = cands.iter().position(|c| c.admissible) else {
            let stop = if lab.settled(cur, &cands) {
                Stop::Adequate
            } else {
                Stop::NothingHelps
            };
            return Ok(Walk {
                models,
                steps,
                stop,
                last_candidates: cands,
            });
        };
        if steps.len() >= max_steps {
            return Ok(Walk {
                models,
                steps,
                stop: Stop::StepLimit,
                last_candidates: cands,
            });
        }
        before.adequate = false;
        steps.push(Step::of(before, &cands[best]));
        models.push(cands[best].model.clone());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A toy lab: the measurement needs effects 1 and 2 and each present one lowers χ²/dof;
    /// effect 3 is never admissible. With `verdict_passes` the goodness-of-fit verdict says
    /// adequate whatever is missing (a test with no power against the missing effects).
    struct Toy {
        verdict_passes: bool,
    }

    impl Lab for Toy {
        type Effect = u8;
        type Model = Vec<u8>;
        type Error = String;
        fn summary(&self, m: &Vec<u8>) -> Summary {
            let missing = [1u8, 2].iter().filter(|e| !m.contains(e)).count();
            Summary {
                chi2_dof: 1.0 + 10.0 * missing as f64,
                rms_residual: missing as f64,
                rms_unit: String::new(),
                adequate: self.verdict_passes || missing == 0,
                params: m.len(),
            }
        }
        fn candidates(&self, m: &Vec<u8>) -> Result<Candidates<Self>, String> {
            Ok([3u8, 2, 1]
                .into_iter()
                .filter(|e| !m.contains(e))
                .map(|e| {
                    let mut n = m.clone();
                    n.push(e);
                    Candidate {
                        edit: Edit {
                            add: vec![e],
                            remove: vec![],
                        },
                        summary: self.summary(&n),
                        delta: 0.0,
                        extra_params: 1,
                        p_value: if e == 3 { 0.5 } else { 1e-9 },
                        admissible: e != 3,
                        reason: String::new(),
                        reading: format!("effect {e}"),
                        model: n,
                    }
                })
                .collect())
        }
    }

    #[test]
    fn walks_to_adequate_taking_admissible_candidates_in_order() {
        let lab = Toy {
            verdict_passes: false,
        };
        let w = walk(&lab, vec![], 5).unwrap();
        assert_eq!(w.stop, Stop::Adequate);
        assert_eq!(w.steps.len(), 2);
        assert_eq!(w.steps[0].edit.add, vec![2]);
        assert!(w.steps[0].after.chi2_dof < w.steps[0].before.chi2_dof);
        assert_eq!(w.last(), &vec![2, 1]);
        let w = walk(&lab, vec![], 1).unwrap();
        assert_eq!((w.stop, w.steps.len()), (Stop::StepLimit, 1));
    }

    #[test]
    fn a_passing_verdict_with_an_admissible_candidate_is_improved() {
        let w = walk(
            &Toy {
                verdict_passes: true,
            },
            vec![],
            5,
        )
        .unwrap();
        assert_eq!((w.stop, w.steps.len()), (Stop::Adequate, 2));
        assert!(!w.steps[0].before.adequate && w.steps[0].after.adequate);
        assert_eq!(w.last(), &vec![2, 1]);
    }
}
