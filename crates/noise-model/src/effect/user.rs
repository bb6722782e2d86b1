//! User-described effects: an effect the lab does not know, described in a small TOML file by its
//! autocovariance R(k) or its one-sided PSD S(f) as a formula of named parameters (or a table of
//! R), with bounds. The lab computes its exact sampled Allan variance,
//! σ²(m) = (4S(m) − S(2m))/(2m²) with S(n) = Σ_{|k|<n}(n−|k|)R(k) ([`crate::structure`]), fits it
//! like a built-in and reports it in every output under the file's name.
//!
//! ```toml
//! name = "bartlett_decimation"          # lower-case letters, digits, '_'; not a built-in name
//! physics = "Two boxcar stages of L output samples in the part's decimation filter."
//! signature = "below the white line for τ < 2L·τ0, on it beyond"   # optional
//! amplitude = "N"                       # the parameter whose square scales R
//! amplitude_unit = "u·√s"               # 'u' stands for the channel's unit
//! autocovariance = "N^2 / (L*tau0) * bspline3(k/L)"   # R(k) in u², k = lag in samples
//! # psd = "N^2 / (1 + (f/fc)^4)"        # or: one-sided S(f) in u²/Hz, 0 < f ≤ fs/2
//! # autocovariance_table = [1.0, 0.5, 0.25]   # or: R(0), R(1), … for amplitude 1
//!
//! [parameters.L]
//! unit = "samples"
//! min = 1
//! max = 64
//! scale = "log"                          # or "linear"
//! ```
//!
//! Formulas may use the lag `k` (samples) or the frequency `f` (Hz), `tau0` (s), `fs` (Hz), `pi`,
//! the parameters, numbers, `+ − * / ^`, parentheses and the functions exp, ln, log10, sqrt, abs,
//! sin, cos, tan, atan, floor, ceil, min, max, pow, sinc (sin πx/πx), tri (max(0, 1 − |x|)) and
//! bspline3 (the cubic B-spline on [−2, 2], the autocorrelation of a triangle).
use crate::effect::{Basis, ParamSpec};
use crate::psd::fft;
use crate::structure::{RTable, Structure};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::sync::Arc;

/// The amplitude parameter of a user effect.
#[derive(Debug, Clone, PartialEq)]
pub struct AmpSpec {
    pub name: String,
    /// Unit with `u` standing for the channel's unit.
    pub unit: String,
}

/// How a user effect is defined.
#[derive(Debug, Clone)]
pub enum Definition {
    /// R(k) as a formula.
    Autocovariance(Expr),
    /// One-sided S(f) as a formula.
    Psd(Expr),
    /// R(0), R(1), … for a unit amplitude.
    Table(Vec<f64>),
}

/// A user-described effect.
#[derive(Debug, Clone)]
pub struct UserEffect {
    pub name: String,
    pub physics: String,
    pub signature: String,
    pub amplitude: AmpSpec,
    /// The non-linear parameters, in the order the basis expects them.
    pub params: Vec<ParamSpec>,
    pub definition: Definition,
    /// Variable slots: k or f, tau0, fs, amplitude, then the parameters.
    vars: Vec<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ParamFile {
    unit: Option<String>,
    min: f64,
    max: f64,
    scale: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    name: String,
    physics: String,
    signature: Option<String>,
    amplitude: String,
    amplitude_unit: Option<String>,
    autocovariance: Option<String>,
    psd: Option<String>,
    autocovariance_table: Option<Vec<f64>>,
    #[serde(default)]
    parameters: BTreeMap<String, ParamFile>,
}

const RESERVED: [&str; 5] = ["k", "f", "tau0", "fs", "pi"];

impl UserEffect {
    /// Parse a description file. `source` names the file in errors.
    pub fn parse(text: &str, source: &str) -> Result<UserEffect, String> {
        let f: File = toml::from_str(text).map_err(|e| format!("{source}: {e}"))?;
        let err = |m: String| format!("{source}: {m}");
        let valid = !f.name.is_empty()
            && f.name.starts_with(|c: char| c.is_ascii_lowercase())
            && f.name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
        if !valid {
            return Err(err(format!(
                "name {:?}: use lower-case letters, digits and '_', starting with a letter",
                f.name
            )));
        }
        if crate::effect::Effect::parse(&f.name).is_some() {
            return Err(err(format!(
                "name {:?} is a built-in effect; choose another name",
                f.name
            )));
        }
        let mut params = Vec::new();
        for (name, p) in &f.parameters {
            if RESERVED.contains(&name.as_str()) || *name == f.amplitude {
                return Err(err(format!(
                    "parameter {name:?} clashes with a reserved name"
                )));
            }
            if !(p.min.is_finite() && p.max.is_finite() && p.min < p.max) {
                return Err(err(format!(
                    "parameter {name}: min {} and max {} must be finite with min < max",
                    p.min, p.max
                )));
            }
            let log = match p.scale.as_deref() {
                None => p.min > 0.0 && p.max / p.min >= 10.0,
                Some("log") if p.min > 0.0 => true,
                Some("log") => {
                    return Err(err(format!(
                        "parameter {name}: a log scale needs min > 0 (got {})",
                        p.min
                    )))
                }
                Some("linear") => false,
                Some(s) => {
                    return Err(err(format!(
                        "parameter {name}: scale {s:?}: use \"log\" or \"linear\""
                    )))
                }
            };
            params.push(ParamSpec {
                name: name.clone(),
                unit: p.unit.clone().unwrap_or_default(),
                lo: p.min,
                hi: p.max,
                log,
                density: if log { 16.0 } else { 33.0 },
            });
        }
        let amp_name = f.amplitude.trim().to_string();
        if amp_name.is_empty() || RESERVED.contains(&amp_name.as_str()) {
            return Err(err(format!(
                "amplitude {:?}: give the amplitude parameter's name",
                f.amplitude
            )));
        }
        let lag_var = if f.psd.is_some() { "f" } else { "k" };
        let mut vars: Vec<String> =
            vec![lag_var.into(), "tau0".into(), "fs".into(), amp_name.clone()];
        vars.extend(params.iter().map(|p| p.name.clone()));
        let definition = match (&f.autocovariance, &f.psd, &f.autocovariance_table) {
            (Some(e), None, None) => Definition::Autocovariance(
                Expr::parse(e, &vars).map_err(|m| err(format!("autocovariance: {m}")))?,
            ),
            (None, Some(e), None) => {
                Definition::Psd(Expr::parse(e, &vars).map_err(|m| err(format!("psd: {m}")))?)
            }
            (None, None, Some(t)) => {
                if t.is_empty() || t.iter().any(|v| !v.is_finite()) || !(t[0] > 0.0) {
                    return Err(err(
                        "autocovariance_table: give finite values with R(0) > 0".into(),
                    ));
                }
                Definition::Table(t.clone())
            }
            _ => {
                return Err(err(
                    "give exactly one of autocovariance, psd or autocovariance_table".into(),
                ))
            }
        };
        let u = UserEffect {
            name: f.name,
            physics: f.physics,
            signature: f
                .signature
                .unwrap_or_else(|| "the Allan curve of its autocovariance".into()),
            amplitude: AmpSpec {
                name: amp_name,
                unit: f.amplitude_unit.unwrap_or_else(|| "u".into()),
            },
            params,
            definition,
            vars,
        };
        u.check_scaling().map_err(err)?;
        Ok(u)
    }

    /// The definition must scale as amplitude² (the fit's coefficient is amplitude²).
    fn check_scaling(&self) -> Result<(), String> {
        let mid: Vec<f64> = self
            .params
            .iter()
            .map(|p| {
                if p.log {
                    (p.lo * p.hi).sqrt()
                } else {
                    (p.lo + p.hi) / 2.0
                }
            })
            .collect();
        let (tau0, fs) = (0.01, 100.0);
        let eval = |amp: f64, x: f64| match &self.definition {
            Definition::Autocovariance(e) | Definition::Psd(e) => {
                let mut v = vec![x, tau0, fs, amp];
                v.extend(&mid);
                e.eval(&v)
            }
            Definition::Table(t) => amp * amp * t[0],
        };
        let x = if matches!(self.definition, Definition::Psd(_)) {
            1.0
        } else {
            0.0
        };
        let (a, b) = (eval(1.0, x), eval(2.0, x));
        if !(a.is_finite() && b.is_finite() && a > 0.0) {
            return Err(format!(
                "the definition at amplitude 1 and mid-range parameters is {a}, not a positive number"
            ));
        }
        if (b / a - 4.0).abs() > 1e-9 {
            return Err(format!(
                "the definition must be proportional to {}² (doubling it multiplied R by {:.6}, not 4)",
                self.amplitude.name,
                b / a
            ));
        }
        Ok(())
    }

    /// R(0..) for unit amplitude and parameters `theta`.
    fn table(&self, theta: &[f64], tau0: f64) -> Result<RTable, String> {
        let fs = 1.0 / tau0;
        for (p, &v) in self.params.iter().zip(theta) {
            if !(v.is_finite()) {
                return Err(format!(
                    "{}: parameter {} = {v} is not finite",
                    self.name, p.name
                ));
            }
        }
        let vars = |x: f64| {
            let mut v = vec![x, tau0, fs, 1.0];
            v.extend_from_slice(theta);
            v
        };
        match &self.definition {
            Definition::Table(t) => Ok(RTable::new(t)),
            Definition::Autocovariance(e) => {
                RTable::from_fn(|k| e.eval(&vars(k as f64)), 1e-12, 20_000_000)
                    .map_err(|m| format!("{}: {m}", self.name))
            }
            Definition::Psd(e) => {
                // R(k) = ∫_0^{fs/2} S(f) cos(2πfkτ0) df, midpoint rule on 2^18 bins, by one FFT.
                let nf = 1usize << 18;
                let df = fs / (2.0 * nf as f64);
                let mut re = vec![0.0; 2 * nf];
                let mut im = vec![0.0; 2 * nf];
                for (i, r) in re.iter_mut().take(nf).enumerate() {
                    let s = e.eval(&vars((i as f64 + 0.5) * df));
                    if !s.is_finite() || s < 0.0 {
                        return Err(format!(
                            "{}: S({} Hz) = {s}: the PSD must be finite and non-negative",
                            self.name,
                            (i as f64 + 0.5) * df
                        ));
                    }
                    *r = s * df;
                }
                fft(&mut re, &mut im);
                // fft computes Σ x_i e^{−2πi·ik/2nf}; R(k) = Re[e^{−iπk/(2nf)} · that]
                let r: Vec<f64> = (0..nf)
                    .map(|k| {
                        let ph = -std::f64::consts::PI * k as f64 / (2.0 * nf as f64);
                        re[k] * ph.cos() - im[k] * ph.sin()
                    })
                    .collect();
                RTable::from_fn(|k| r.get(k).copied().unwrap_or(0.0), 1e-9, nf - 1)
                    .map_err(|m| format!("{}: {m}", self.name))
            }
        }
    }

    /// The Allan basis for parameters `theta` (unit amplitude²).
    pub fn basis(&self, theta: &[f64], tau0: f64) -> Result<Basis, String> {
        Ok(Basis::Stochastic {
            structure: Structure::Table(Arc::new(self.table(theta, tau0)?)),
            factor: 1.0,
        })
    }

    /// The variable names the formula uses, in slot order (lag or frequency first).
    pub fn variables(&self) -> &[String] {
        &self.vars
    }
}

/// A parsed arithmetic expression over numbered variables.
#[derive(Debug, Clone, PartialEq)]
pub enum Expr {
    Num(f64),
    Var(usize),
    Neg(Box<Expr>),
    Bin(char, Box<Expr>, Box<Expr>),
    Call(Func, Vec<Expr>),
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Func {
    Exp,
    Ln,
    Log10,
    Sqrt,
    Abs,
    Sin,
    Cos,
    Tan,
    Atan,
    Floor,
    Ceil,
    Min,
    Max,
    Pow,
    Sinc,
    Tri,
    Bspline3,
}

impl Func {
    fn parse(s: &str) -> Option<(Func, usize)> {
        Some(match s {
            "exp" => (Func::Exp, 1),
            "ln" => (Func::Ln, 1),
            "log10" => (Func::Log10, 1),
            "sqrt" => (Func::Sqrt, 1),
            "abs" => (Func::Abs, 1),
            "sin" => (Func::Sin, 1),
            "cos" => (Func::Cos, 1),
            "tan" => (Func::Tan, 1),
            "atan" => (Func::Atan, 1),
            "floor" => (Func::Floor, 1),
            "ceil" => (Func::Ceil, 1),
            "min" => (Func::Min, 2),
            "max" => (Func::Max, 2),
            "pow" => (Func::Pow, 2),
            "sinc" => (Func::Sinc, 1),
            "tri" => (Func::Tri, 1),
            "bspline3" => (Func::Bspline3, 1),
            _ => return None,
        })
    }
}

struct Parser<'a> {
    toks: Vec<Tok>,
    pos: usize,
    vars: &'a [String],
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Ident(String),
    Op(char),
}

fn lex(s: &str) -> Result<Vec<Tok>, String> {
    let mut out = Vec::new();
    let cs: Vec<char> = s.chars().collect();
    let mut i = 0;
    while i < cs.len() {
        let c = cs[i];
        if c.is_whitespace() {
            i += 1;
        } else if c.is_ascii_digit() || c == '.' {
            let st = i;
            while i < cs.len() && (cs[i].is_ascii_digit() || cs[i] == '.') {
                i += 1;
            }
            if i < cs.len() && (cs[i] == 'e' || cs[i] == 'E') {
                let mut j = i + 1;
                if j < cs.len() && (cs[j] == '+' || cs[j] == '-') {
                    j += 1;
                }
                if j < cs.len() && cs[j].is_ascii_digit() {
                    i = j;
                    while i < cs.len() && cs[i].is_ascii_digit() {
                        i += 1;
                    }
                }
            }
            let t: String = cs[st..i].iter().collect();
            out.push(Tok::Num(t.parse().map_err(|_| {
                format!("bad number {t:?} at character {}", st + 1)
            })?));
        } else if c.is_ascii_alphabetic() || c == '_' {
            let st = i;
            while i < cs.len() && (cs[i].is_ascii_alphanumeric() || cs[i] == '_') {
                i += 1;
            }
            out.push(Tok::Ident(cs[st..i].iter().collect()));
        } else if "+-*/^(),".contains(c) {
            out.push(Tok::Op(c));
            i += 1;
        } else {
            return Err(format!("unexpected character {c:?} at position {}", i + 1));
        }
    }
    Ok(out)
}

impl Parser<'_> {
    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.pos)
    }
    fn eat(&mut self, c: char) -> bool {
        if self.peek() == Some(&Tok::Op(c)) {
            self.pos += 1;
            true
        } else {
            false
        }
    }
    fn expr(&mut self, depth: usize) -> Result<Expr, String> {
        if depth > 200 {
            return Err("expression nested too deeply".into());
        }
        self.binary(depth, ['+', '-'], Self::term)
    }
    fn term(&mut self, depth: usize) -> Result<Expr, String> {
        self.binary(depth, ['*', '/'], Self::unary)
    }
    /// A left-associative chain of `operand`s joined by either of the operators `ops`.
    fn binary(
        &mut self,
        depth: usize,
        ops: [char; 2],
        operand: fn(&mut Self, usize) -> Result<Expr, String>,
    ) -> Result<Expr, String> {
        let mut l = operand(self, depth + 1)?;
        while let Some(&op) = ops.iter().find(|&&c| self.eat(c)) {
            let r = operand(self, depth + 1)?;
            l = Expr::Bin(op, Box::new(l), Box::new(r));
        }
        Ok(l)
    }
    fn unary(&mut self, depth: usize) -> Result<Expr, String> {
        if depth > 200 {
            return Err("expression nested too deeply".into());
        }
        if self.eat('-') {
            return Ok(Expr::Neg(Box::new(self.unary(depth + 1)?)));
        }
        if self.eat('+') {
            return self.unary(depth + 1);
        }
        let base = self.atom(depth + 1)?;
        if self.eat('^') {
            let e = self.unary(depth + 1)?;
            return Ok(Expr::Bin('^', Box::new(base), Box::new(e)));
        }
        Ok(base)
    }
    fn atom(&mut self, depth: usize) -> Result<Expr, String> {
        match self.peek().cloned() {
            Some(Tok::Num(v)) => {
                self.pos += 1;
                Ok(Expr::Num(v))
            }
            Some(Tok::Op('(')) => {
                self.pos += 1;
                let e = self.expr(depth + 1)?;
                if !self.eat(')') {
                    return Err("missing ')'".into());
                }
                Ok(e)
            }
            Some(Tok::Ident(name)) => {
                self.pos += 1;
                if self.eat('(') {
                    let (f, arity) =
                        Func::parse(&name).ok_or_else(|| format!("unknown function {name:?}"))?;
                    let mut args = vec![self.expr(depth + 1)?];
                    while self.eat(',') {
                        args.push(self.expr(depth + 1)?);
                    }
                    if !self.eat(')') {
                        return Err(format!("missing ')' after the arguments of {name}"));
                    }
                    if args.len() != arity {
                        return Err(format!(
                            "{name} takes {arity} argument(s), got {}",
                            args.len()
                        ));
                    }
                    return Ok(Expr::Call(f, args));
                }
                if name == "pi" {
                    return Ok(Expr::Num(std::f64::consts::PI));
                }
                self.vars
                    .iter()
                    .position(|v| *v == name)
                    .map(Expr::Var)
                    .ok_or_else(|| {
                        format!(
                            "unknown name {name:?} (known: {}, pi)",
                            self.vars.join(", ")
                        )
                    })
            }
            Some(Tok::Op(c)) => Err(format!("unexpected {c:?}")),
            None => Err("the expression ends too early".into()),
        }
    }
}

impl Expr {
    /// Parse `s` with the variables `vars` (slot i = vars[i]).
    pub fn parse(s: &str, vars: &[String]) -> Result<Expr, String> {
        let mut p = Parser {
            toks: lex(s)?,
            pos: 0,
            vars,
        };
        let e = p.expr(0)?;
        if p.pos != p.toks.len() {
            return Err(format!(
                "unexpected {:?} after a complete expression",
                p.toks[p.pos]
            ));
        }
        Ok(e)
    }

    /// Evaluate with variable values `v`.
    pub fn eval(&self, v: &[f64]) -> f64 {
        match self {
            Expr::Num(x) => *x,
            Expr::Var(i) => v.get(*i).copied().unwrap_or(f64::NAN),
            Expr::Neg(e) => -e.eval(v),
            Expr::Bin(op, a, b) => {
                let (a, b) = (a.eval(v), b.eval(v));
                match op {
                    '+' => a + b,
                    '-' => a - b,
                    '*' => a * b,
                    '/' => a / b,
                    _ => a.powf(b),
                }
            }
            Expr::Call(f, args) => {
                let a = args[0].eval(v);
                let b = || args[1].eval(v);
                match f {
                    Func::Exp => a.exp(),
                    Func::Ln => a.ln(),
                    Func::Log10 => a.log10(),
                    Func::Sqrt => a.sqrt(),
                    Func::Abs => a.abs(),
                    Func::Sin => a.sin(),
                    Func::Cos => a.cos(),
                    Func::Tan => a.tan(),
                    Func::Atan => a.atan(),
                    Func::Floor => a.floor(),
                    Func::Ceil => a.ceil(),
                    Func::Min => a.min(b()),
                    Func::Max => a.max(b()),
                    Func::Pow => a.powf(b()),
                    Func::Sinc => {
                        let x = std::f64::consts::PI * a;
                        if x.abs() < 1e-12 {
                            1.0
                        } else {
                            x.sin() / x
                        }
                    }
                    Func::Tri => (1.0 - a.abs()).max(0.0),
                    Func::Bspline3 => crate::structure::bspline3(a),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effect::{Context, Effect};

    const MARKOV: &str = r#"
name = "my_markov"
physics = "the built-in Markov term, described by hand"
amplitude = "sigma"
amplitude_unit = "u"
autocovariance = "sigma^2 * exp(-k*tau0/tau_c)"
[parameters.tau_c]
unit = "s"
min = 0.01
max = 1000
"#;

    #[test]
    fn expressions_evaluate() {
        let vars: Vec<String> = ["k", "a"].map(String::from).to_vec();
        let e = Expr::parse("-2^2 + 3*a/(1+k) + max(0, tri(0.5)) - sinc(0)", &vars).unwrap();
        assert!((e.eval(&[1.0, 4.0]) - (-4.0 + 6.0 + 0.5 - 1.0)).abs() < 1e-12);
        assert!(Expr::parse("foo(1)", &vars)
            .unwrap_err()
            .contains("unknown function"));
        assert!(Expr::parse("b + 1", &vars)
            .unwrap_err()
            .contains("unknown name"));
        assert!(Expr::parse("(1 + 2", &vars).is_err());
        assert!(Expr::parse(&"(".repeat(500), &vars).is_err());
    }

    #[test]
    fn a_user_markov_has_the_builtin_basis() {
        let u = UserEffect::parse(MARKOV, "my_markov.toml").unwrap();
        let ctx = Context::uniform(0.01, 1 << 16);
        let mine = Effect::User(Arc::new(u)).basis(&[0.7], &ctx).unwrap();
        let builtin = Effect::Markov.basis(&[0.7], &ctx).unwrap();
        for m in [1.0, 3.0, 64.0, 4096.0] {
            let (a, b) = (mine.avar(m, 0.01), builtin.avar(m, 0.01));
            assert!((a - b).abs() < 1e-9 * b, "m {m}: {a} vs {b}");
        }
    }

    #[test]
    fn a_psd_definition_gives_its_autocovariance() {
        // one-sided S(f) = 2σ²τc/(1 + (2πfτc)²) is (up to aliasing) the Markov PSD
        let text = r#"
name = "lorentzian"
physics = "a Markov process described by its spectrum"
amplitude = "sigma"
psd = "4 * sigma^2 * tau_c / (1 + (2*pi*f*tau_c)^2)"
[parameters.tau_c]
min = 0.01
max = 10
"#;
        let u = UserEffect::parse(text, "l.toml").unwrap();
        let ctx = Context::uniform(0.001, 1 << 20);
        let mine = Effect::User(Arc::new(u)).basis(&[0.05], &ctx).unwrap();
        let builtin = Effect::Markov.basis(&[0.05], &ctx).unwrap();
        for m in [10.0, 100.0, 1000.0] {
            let (a, b) = (mine.avar(m, 0.001), builtin.avar(m, 0.001));
            assert!((a / b - 1.0).abs() < 0.02, "m {m}: {a} vs {b}");
        }
    }

    #[test]
    fn bad_files_are_refused_with_the_reason() {
        let cases = [
            (MARKOV.replace("my_markov", "markov"), "built-in"),
            (MARKOV.replace("sigma^2 *", "sigma *"), "proportional"),
            (MARKOV.replace("min = 0.01", "min = 5000"), "min < max"),
            (MARKOV.replace("exp(", "exq("), "unknown function"),
            (
                MARKOV.replace("autocovariance =", "psd = \"1\"\nautocovariance ="),
                "exactly one",
            ),
            ("name = 3".to_string(), "invalid type"),
        ];
        for (text, want) in cases {
            let e = UserEffect::parse(&text, "x.toml").unwrap_err();
            assert!(e.contains(want) && e.starts_with("x.toml"), "{e}");
        }
    }
}
