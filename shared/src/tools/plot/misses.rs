//! A run's deadline misses by cause, as the figures draw them: each cause's kind (`timer`,
//! `queued`, `compute`, `transport`, `fault`, `skipped`, `unknown`) and its colour, the one map
//! every figure uses (misses.png, the fault zooms), and the misses read from loops.csv.

use crate::tools::ToolError;
use crate::tools::plot::figure::{Colour, Curve, Line};
use crate::tools::run_folder::Table;

/// What a miss's cause was, without its process or hop: a figure's colour for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CauseKind {
    Timer,
    Queued,
    Compute,
    Transport,
    Fault,
    Skipped,
    Unknown,
}

impl CauseKind {
    /// In the order a legend lists them: the loop's own path first, then what stopped it.
    pub const ALL: [CauseKind; 7] = [
        CauseKind::Timer,
        CauseKind::Queued,
        CauseKind::Compute,
        CauseKind::Transport,
        CauseKind::Fault,
        CauseKind::Skipped,
        CauseKind::Unknown,
    ];

    /// The kind of a cause as loops.csv writes it (`monitor::cause::Cause`'s text): the word
    /// before its colon ("queued: controller" is `Queued`); an empty or unknown text is `Unknown`.
    pub fn of(cause: &str) -> CauseKind {
        let word = cause.split(':').next().unwrap_or("").trim();
        CauseKind::ALL.into_iter().find(|kind| kind.name() == word).unwrap_or(CauseKind::Unknown)
    }

    /// Its word, as a cause's text starts.
    pub fn name(self) -> &'static str {
        match self {
            CauseKind::Timer => "timer",
            CauseKind::Queued => "queued",
            CauseKind::Compute => "compute",
            CauseKind::Transport => "transport",
            CauseKind::Fault => "fault",
            CauseKind::Skipped => "skipped",
            CauseKind::Unknown => "unknown",
        }
    }

    /// Its colour in every figure. None is the series' first two (blue, orange: the curves the
    /// misses are drawn beside), grey or black (axes, limits, truth), or the faults' markers'
    /// pure red; the fault's kind is a crimson beside that red.
    pub fn colour(self) -> Colour {
        match self {
            CauseKind::Timer => Colour::Rgb(188, 189, 34),
            CauseKind::Queued => Colour::Rgb(148, 103, 189),
            CauseKind::Compute => Colour::Rgb(44, 160, 44),
            CauseKind::Transport => Colour::Rgb(23, 190, 207),
            CauseKind::Fault => Colour::Rgb(214, 0, 120),
            CauseKind::Skipped => Colour::Rgb(140, 86, 75),
            CauseKind::Unknown => Colour::Rgb(247, 129, 191),
        }
    }
}

/// A loop that missed its deadline, from its row of loops.csv.
#[derive(Debug, Clone, PartialEq)]
pub struct Miss {
    /// Its tick's time in the run, s.
    pub t: f64,
    pub kind: CauseKind,
    /// From its tick being due to its command reaching the plant, ns; None where no command
    /// came (or the plant skipped the tick).
    pub response_ns: Option<u64>,
}

/// The rows of loops.csv flagged `deadline_miss`, in its order.
pub fn read_misses(loops: &Table) -> Result<Vec<Miss>, ToolError> {
    let t = loops.floats("t_s")?;
    let missed = loops.column::<u8>("deadline_miss")?;
    let cause = loops.column::<String>("cause")?;
    let response_ns = loops.column::<u64>("response_ns")?;
    Ok((0..t.len())
        .filter(|&row| missed[row] == Some(1))
        .map(|row| Miss {
            t: t[row],
            kind: CauseKind::of(cause[row].as_deref().unwrap_or("")),
            response_ns: response_ns[row],
        })
        .collect())
}

/// The misses as crosses at (t, `y(miss)`), one curve per cause kind present, in
/// [`CauseKind::ALL`]'s order, each in its kind's colour and labelled with its count:
/// "fault (312)".
pub fn crosses_by_cause<'a>(misses: impl IntoIterator<Item = &'a Miss>, y: impl Fn(&Miss) -> f64) -> Vec<Curve> {
    let mut points: Vec<Vec<(f64, f64)>> = vec![Vec::new(); CauseKind::ALL.len()];
    for miss in misses {
        points[miss.kind as usize].push((miss.t, y(miss)));
    }
    CauseKind::ALL
        .into_iter()
        .zip(points)
        .filter(|(_, points)| !points.is_empty())
        .map(|(kind, points)| {
            Curve::new(format!("{} ({})", kind.name(), points.len()), points, kind.colour(), Line::Crosses)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::faults::FaultKind;
    use crate::contract::role::Role;
    use crate::monitor::cause::Cause;

    #[test]
    fn every_cause_the_monitor_writes_has_its_kind() {
        let cases = [
            (Cause::Timer, CauseKind::Timer),
            (Cause::Queued(Role::Controller), CauseKind::Queued),
            (Cause::Compute(Role::Estimator), CauseKind::Compute),
            (Cause::Transport(0), CauseKind::Transport),
            (Cause::Fault(FaultKind::Stop, Role::Controller), CauseKind::Fault),
            (Cause::Skipped(Role::Sensors), CauseKind::Skipped),
            (Cause::Unknown, CauseKind::Unknown),
        ];
        for (cause, kind) in cases {
            assert_eq!(CauseKind::of(&cause.to_string()), kind, "{cause}");
        }
        assert_eq!(CauseKind::of(""), CauseKind::Unknown);
        assert_eq!(CauseKind::of("stolen"), CauseKind::Unknown);
    }

    #[test]
    fn each_kind_has_a_colour_of_its_own() {
        let colours: Vec<Colour> = CauseKind::ALL.map(CauseKind::colour).to_vec();
        for (i, colour) in colours.iter().enumerate() {
            assert!(!colours[..i].contains(colour), "{colour:?} twice");
            assert!(![Colour::Series(0), Colour::Series(1)].contains(colour));
        }
    }

    #[test]
    fn misses_are_grouped_by_kind_and_counted() {
        let miss = |t: f64, kind: CauseKind, response_ns: Option<u64>| Miss { t, kind, response_ns };
        let misses = [
            miss(0.1, CauseKind::Fault, None),
            miss(0.2, CauseKind::Timer, Some(2_000_000)),
            miss(0.3, CauseKind::Fault, None),
        ];
        let curves = crosses_by_cause(&misses, |m| m.response_ns.map_or(9.0, |ns| ns as f64 / 1e6));
        assert_eq!(
            curves,
            [
                Curve::new("timer (1)", vec![(0.2, 2.0)], CauseKind::Timer.colour(), Line::Crosses),
                Curve::new("fault (2)", vec![(0.1, 9.0), (0.3, 9.0)], CauseKind::Fault.colour(), Line::Crosses),
            ]
        );
    }

    #[test]
    fn misses_are_read_from_loops_csv_by_column_name() {
        let text = "k,t_s,deadline_miss,cause,response_ns\n\
                    0,0.000,0,,\n\
                    1,0.001,1,queued: controller,1500000\n\
                    2,0.002,1,fault: stop controller,\n";
        let loops = Table::parse("loops.csv", text).unwrap();
        assert_eq!(
            read_misses(&loops).unwrap(),
            [
                Miss { t: 0.001, kind: CauseKind::Queued, response_ns: Some(1_500_000) },
                Miss { t: 0.002, kind: CauseKind::Fault, response_ns: None },
            ]
        );
    }
}
