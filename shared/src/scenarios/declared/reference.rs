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

use crate::config::launch::{LaunchConfig, LaunchError};
pub use crate::model::reference::{Between, ReferenceEntry, Signal};

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
    let mut tracked = Vec::new();
    for named in crate::model::reference::references(c)? {
        let (part, index) =
            locate(&named.track, state, outputs).map_err(|e| c.error(&format!("{}.track", named.key), e))?;
        tracked.push(Tracked { path: named.track, part, index, signal: named.signal });
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
