//! The reference: where a scenario's system should be at each instant. It is computed in one
//! place per scenario, so that what the controller tracks is exactly what the metrics and the
//! fault reports' error measure judge against.

use std::sync::Arc;

use exmex::prelude::*;
use serde::Deserialize;

use crate::config::launch::{LaunchConfig, LaunchError};

/// A scenario's reference trajectory (a setpoint is a constant one).
pub trait Reference: Send {
    /// What the controller tracks at one instant: a setpoint, or a point with its derivatives.
    type Point;
    /// The reference at simulation time `t`.
    fn at(&mut self, t: f64) -> Self::Point;
    /// How far true state `x` is from the reference at `t`, in the units of the scenario's
    /// error measure.
    fn error(&mut self, t: f64, x: &[f64]) -> f64;
}

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

/// One `[[reference]]` of a declared system, as written: the component it names, its key
/// (`reference` or `reference[i]`, for errors) and its signal.
#[derive(Debug, Clone)]
pub struct NamedReference {
    /// `state.<name>` or `output.<name>`.
    pub track: String,
    pub key: String,
    pub signal: Signal,
}

/// A declared system's references (`[reference]` or `[[reference]]`), in order; none for a
/// built-in scenario, whose `[reference]` is its own (its README says what it is).
pub fn declared_references(c: &LaunchConfig) -> Result<Vec<NamedReference>, LaunchError> {
    if c.is_declared() { references(c) } else { Ok(Vec::new()) }
}

/// `c`'s `[reference]` or `[[reference]]` read as a declared system's, in order.
pub fn references(c: &LaunchConfig) -> Result<Vec<NamedReference>, LaunchError> {
    // One entry as [reference], several as [[reference]].
    let (entries, one): (Vec<ReferenceEntry>, bool) = match c.document.get("reference") {
        None => return Ok(Vec::new()),
        Some(toml::Value::Table(t)) if t.is_empty() => return Ok(Vec::new()),
        Some(toml::Value::Table(_)) => (vec![c.section("reference")?], true),
        Some(_) => (c.section("reference")?, false),
    };
    let mut named: Vec<NamedReference> = Vec::new();
    for (i, entry) in entries.iter().enumerate() {
        let at = if one { "reference".to_owned() } else { format!("reference[{i}]") };
        let key = |k: &str| format!("{at}.{k}");
        if named.iter().any(|t| t.track == entry.track) {
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
        named.push(NamedReference { track: entry.track.clone(), key: at, signal });
    }
    Ok(named)
}
