//! A declared system's reference: what a named state or output component should follow, given
//! in the launch file as an expression of t or as a table of (t, value) rows.
//!
//! One reference may be written `[reference]`, several `[[reference]]`:
//!
//! ```toml
//! [[reference]]
//! track = "output.y"                       # state.<name> or output.<name> of [system]
//! expression = "0.1 * sin(2*PI*0.5*t)"     # of t, s: + - * / ^, sin cos exp ln sqrt abs min max ..., PI, E
//!
//! [[reference]]
//! track = "state.theta"
//! table = [[0.0, 0.0], [1.0, 0.2], [3.0, 0.2]]   # (t s, value) rows, t increasing
//! between = "linear"                              # or "hold": the row's value until the next row
//! ```
//!
//! Before a table's first row the first value holds, after its last row the last value.
//! Expressions are parsed by the `exmex` crate: floats only (`1/2` is 0.5), `^` is a power.

use std::sync::Arc;

use exmex::prelude::*;
use serde::Deserialize;

use crate::config::launch::{LaunchConfig, LaunchError};

/// How a table's value goes from one row to the next.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Between {
    /// A straight line from one row to the next.
    #[default]
    Linear,
    /// The row's value until the next row's time (a staircase).
    Hold,
}

/// One `[[reference]]` entry as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceEntry {
    /// The component that follows it: `state.<name>` or `output.<name>`.
    pub track: String,
    /// The reference as an expression of t (s).
    #[serde(default)]
    pub expression: Option<String>,
    /// The reference as (t, value) rows, t strictly increasing.
    #[serde(default)]
    pub table: Option<Vec<[f64; 2]>>,
    /// Between a table's rows (default linear).
    #[serde(default)]
    pub between: Option<Between>,
}

/// A reference signal r(t).
#[derive(Clone)]
pub enum Signal {
    Expression {
        text: String,
        expression: Arc<FlatEx<f64>>,
        /// Whether it names t (a constant expression takes no variable).
        uses_t: bool,
    },
    Table {
        t: Vec<f64>,
        value: Vec<f64>,
        between: Between,
    },
}

impl std::fmt::Debug for Signal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Signal::Expression { text, .. } => write!(f, "expression {text:?}"),
            Signal::Table { t, between, .. } => write!(f, "table of {} rows, {between:?}", t.len()),
        }
    }
}

impl Signal {
    /// An expression of t, or why not.
    pub fn expression(text: &str) -> Result<Self, String> {
        let expression = exmex::parse::<f64>(text).map_err(|e| format!("cannot parse {text:?}: {e}"))?;
        let names = expression.var_names().to_vec();
        if let Some(other) = names.iter().find(|n| n.as_str() != "t") {
            return Err(format!(
                "{text:?} names {other:?}; the only variable is t (s); constants PI, E; functions sin, cos, tan, \
                 exp, ln, log10, sqrt, abs, signum, min, max, floor, ceil, round"
            ));
        }
        let signal =
            Signal::Expression { text: text.to_owned(), expression: Arc::new(expression), uses_t: !names.is_empty() };
        let at_zero = signal.at(0.0);
        if !at_zero.is_finite() {
            return Err(format!("{text:?} is {at_zero} at t = 0"));
        }
        Ok(signal)
    }

    /// A table of (t, value) rows, or why not.
    pub fn table(rows: &[[f64; 2]], between: Between) -> Result<Self, String> {
        if rows.is_empty() {
            return Err("has no rows; give at least one [t, value]".into());
        }
        if let Some(row) = rows.iter().find(|r| !(r[0].is_finite() && r[1].is_finite())) {
            return Err(format!("row {row:?} is not two finite numbers"));
        }
        if let Some(pair) = rows.windows(2).find(|p| p[1][0] <= p[0][0]) {
            return Err(format!("t must increase from row to row: {:?} then {:?}", pair[0], pair[1]));
        }
        Ok(Signal::Table {
            t: rows.iter().map(|r| r[0]).collect(),
            value: rows.iter().map(|r| r[1]).collect(),
            between,
        })
    }

    /// r(t).
    pub fn at(&self, t: f64) -> f64 {
        match self {
            Signal::Expression { expression, uses_t, .. } => {
                let vars: &[f64] = if *uses_t { &[t] } else { &[] };
                expression.eval(vars).unwrap_or(f64::NAN)
            }
            Signal::Table { t: ts, value, between } => {
                // Rows at or before t; none: before the first row.
                let after = ts.partition_point(|&ti| ti <= t);
                if after == 0 {
                    return value[0];
                }
                let i = after - 1;
                if i + 1 == ts.len() || *between == Between::Hold {
                    return value[i];
                }
                let s = (t - ts[i]) / (ts[i + 1] - ts[i]);
                value[i] + s * (value[i + 1] - value[i])
            }
        }
    }
}

/// Where a tracked component is: the state's or the outputs' index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    State,
    Output,
}

/// A declared component and the reference it follows.
#[derive(Debug, Clone)]
pub struct Tracked {
    /// As written: `state.theta`, `output.y`.
    pub path: String,
    pub part: Part,
    /// Its index within its part.
    pub index: usize,
    pub signal: Signal,
}

/// Finds `path` (`state.<name>` or `output.<name>`) among the declared names.
pub fn locate(path: &str, state: &[String], outputs: &[String]) -> Result<(Part, usize), String> {
    let listed = |names: &[String], prefix: &str| names.iter().map(|n| format!("{prefix}.{n}")).collect::<Vec<_>>();
    let mut allowed = listed(state, "state");
    allowed.extend(listed(outputs, "output"));
    let found = match path.split_once('.') {
        Some(("state", name)) => state.iter().position(|n| n == name).map(|i| (Part::State, i)),
        Some(("output", name)) => outputs.iter().position(|n| n == name).map(|i| (Part::Output, i)),
        _ => None,
    };
    found.ok_or_else(|| format!("{path:?} is not a declared component; one of: {}", allowed.join(", ")))
}

/// The `[[reference]]` entries of `c`, checked against the declared state and output names.
pub fn load(c: &LaunchConfig, state: &[String], outputs: &[String]) -> Result<Vec<Tracked>, LaunchError> {
    // One entry as [reference], several as [[reference]].
    let (entries, one): (Vec<ReferenceEntry>, bool) = match c.document.get("reference") {
        None => return Ok(Vec::new()),
        Some(toml::Value::Table(t)) if t.is_empty() => return Ok(Vec::new()),
        Some(toml::Value::Table(_)) => (vec![c.section("reference")?], true),
        Some(_) => (c.section("reference")?, false),
    };
    let mut tracked: Vec<Tracked> = Vec::new();
    for (i, entry) in entries.iter().enumerate() {
        let at = if one { "reference".to_owned() } else { format!("reference[{i}]") };
        let key = |k: &str| format!("{at}.{k}");
        let (part, index) = locate(&entry.track, state, outputs).map_err(|e| c.error(&key("track"), e))?;
        if tracked.iter().any(|t| t.path == entry.track) {
            return Err(c.error(&key("track"), format!("{} has a reference already", entry.track)));
        }
        let signal = match (&entry.expression, &entry.table) {
            (Some(text), None) => {
                if entry.between.is_some() {
                    return Err(c.error(&key("between"), "applies to a table only"));
                }
                Signal::expression(text).map_err(|e| c.error(&key("expression"), e))?
            }
            (None, Some(rows)) => {
                Signal::table(rows, entry.between.unwrap_or_default()).map_err(|e| c.error(&key("table"), e))?
            }
            _ => return Err(c.error(&at, "give exactly one of expression or table")),
        };
        tracked.push(Tracked { path: entry.track.clone(), part, index, signal });
    }
    Ok(tracked)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * b.abs().max(1.0)
    }

    #[test]
    fn an_expression_of_t_evaluates_as_written() {
        let r = Signal::expression("0.1 * sin(2*PI*0.5*t) + 1/2").unwrap();
        for t in [0.0, 0.25, 0.5, 1.3, 7.0] {
            assert!(close(r.at(t), 0.1 * (std::f64::consts::PI * t).sin() + 0.5), "t = {t}");
        }
        let r = Signal::expression("exp(-t/2)*t^2").unwrap();
        assert!(close(r.at(3.0), (-1.5f64).exp() * 9.0));
    }

    /// `1/2` is 0.5, not integer division's 0.
    #[test]
    fn a_constant_expression_is_float_arithmetic() {
        let r = Signal::expression("1/2").unwrap();
        assert_eq!(r.at(0.0), 0.5);
        assert_eq!(r.at(100.0), 0.5);
    }

    #[test]
    fn an_expression_with_another_variable_or_bad_syntax_is_refused() {
        let e = Signal::expression("x * t").unwrap_err();
        assert!(e.contains("names \"x\"") && e.contains("the only variable is t"), "{e}");
        let e = Signal::expression("sin(t").unwrap_err();
        assert!(e.contains("cannot parse"), "{e}");
        let e = Signal::expression("1/t").unwrap_err();
        assert!(e.contains("at t = 0"), "{e}");
    }

    #[test]
    fn a_linear_table_interpolates_and_holds_its_ends() {
        let r = Signal::table(&[[1.0, 0.0], [2.0, 1.0], [4.0, -1.0]], Between::Linear).unwrap();
        for (t, want) in
            [(0.0, 0.0), (1.0, 0.0), (1.25, 0.25), (2.0, 1.0), (3.0, 0.0), (3.5, -0.5), (4.0, -1.0), (9.0, -1.0)]
        {
            assert!(close(r.at(t), want), "t = {t}: {} != {want}", r.at(t));
        }
    }

    #[test]
    fn a_held_table_is_a_staircase() {
        let r = Signal::table(&[[0.0, 1.0], [2.0, 3.0]], Between::Hold).unwrap();
        assert_eq!([r.at(-1.0), r.at(0.0), r.at(1.999), r.at(2.0), r.at(5.0)], [1.0, 1.0, 1.0, 3.0, 3.0]);
    }

    #[test]
    fn a_bad_table_is_refused() {
        assert!(Signal::table(&[], Between::Linear).unwrap_err().contains("no rows"));
        assert!(Signal::table(&[[0.0, 1.0], [0.0, 2.0]], Between::Linear).unwrap_err().contains("t must increase"));
        assert!(Signal::table(&[[0.0, f64::NAN]], Between::Hold).unwrap_err().contains("finite"));
    }

    #[test]
    fn a_path_names_a_declared_state_or_output() {
        let (state, outputs) = (vec!["x".to_owned(), "v".to_owned()], vec!["y".to_owned()]);
        assert_eq!(locate("state.v", &state, &outputs), Ok((Part::State, 1)));
        assert_eq!(locate("output.y", &state, &outputs), Ok((Part::Output, 0)));
        let e = locate("input.u", &state, &outputs).unwrap_err();
        assert!(e.contains("state.x, state.v, output.y"), "{e}");
        assert!(locate("state.y", &state, &outputs).is_err());
    }
}
