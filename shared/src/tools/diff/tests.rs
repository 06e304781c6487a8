use super::*;

const NAN: f64 = f64::NAN;

fn at(k: u64) -> LoopAt {
    LoopAt { k, t_s: k as f64 / 1000.0 }
}

#[test]
fn cells_compare_exactly_nan_equal_to_nan() {
    assert_eq!(compare_cells(Some(1.5), Some(1.5), 0.0, 0.0), CellDiff::Same);
    assert_eq!(compare_cells(Some(NAN), Some(NAN), 0.0, 0.0), CellDiff::Same);
    assert_eq!(compare_cells(Some(-0.0), Some(0.0), 0.0, 0.0), CellDiff::Same);
    assert_eq!(compare_cells(Some(f64::INFINITY), Some(f64::INFINITY), 0.0, 0.0), CellDiff::Same);
    assert_eq!(compare_cells(Some(NAN), Some(1.0), 1e9, 0.0), CellDiff::NonFinite);
    assert_eq!(compare_cells(Some(1.0), Some(f64::INFINITY), 1e9, 0.0), CellDiff::NonFinite);
    assert_eq!(compare_cells(None, None, 0.0, 0.0), CellDiff::BothEmpty);
    assert_eq!(compare_cells(None, Some(1.0), 0.0, 0.0), CellDiff::EmptyOnlyInA);
    assert_eq!(compare_cells(Some(NAN), None, 0.0, 0.0), CellDiff::EmptyOnlyInB);
    // The smallest difference there is, at tolerance 0.
    let next = f64::from_bits(1.0f64.to_bits() + 1);
    assert_eq!(compare_cells(Some(1.0), Some(next), 0.0, 0.0), CellDiff::Finite { delta: f64::EPSILON, over: true });
}

#[test]
fn over_tolerance_is_beyond_abs_plus_rtol_times_a() {
    // |b − a| = abs exactly is within.
    assert_eq!(compare_cells(Some(1.0), Some(1.5), 0.5, 0.0), CellDiff::Finite { delta: 0.5, over: false });
    assert_eq!(compare_cells(Some(1.0), Some(1.75), 0.5, 0.0), CellDiff::Finite { delta: 0.75, over: true });
    // The relative part is against A: 1 ≤ 0.5·2 from A = 2, but 1 > 0.5·1 from A = 1.
    assert_eq!(compare_cells(Some(2.0), Some(1.0), 0.0, 0.5), CellDiff::Finite { delta: -1.0, over: false });
    assert_eq!(compare_cells(Some(1.0), Some(2.0), 0.0, 0.5), CellDiff::Finite { delta: 1.0, over: true });
    assert_eq!(compare_cells(Some(-4.0), Some(-3.0), 0.5, 0.125), CellDiff::Finite { delta: 1.0, over: false });
}

#[test]
fn a_field_counts_its_differences_empties_and_first_loop_over() {
    let loops: Vec<LoopAt> = (0..7).map(at).collect();
    let a = [Some(1.0), Some(2.0), Some(3.0), None, Some(5.0), Some(NAN), Some(NAN)];
    let b = [Some(1.0), Some(2.5), Some(2.0), Some(4.0), None, Some(NAN), Some(6.0)];
    let f = compare_field("est.x", Group::Est, &loops, &a, &b, 0.5, 0.0);
    assert_eq!((f.compared, f.differing, f.non_finite), (5, 3, 1));
    assert_eq!((f.empty_only_in_a, f.empty_only_in_b), (1, 1));
    // Over: loop 2 (|−1| > 0.5), the empties (3, 4) and NaN against 6 (6); 0.5 is within.
    assert_eq!(f.over, 4);
    assert_eq!(f.first_over, Some(at(2)));
    assert_eq!((f.max_abs, f.max_at), (1.0, Some(at(2))));
    // Over the finite differences 0, 0.5, −1, 0.
    assert_eq!(f.rms, (1.25f64 / 4.0).sqrt());
    assert_eq!(f.delta[..3], [0.0, 0.5, -1.0]);
    assert!(f.delta[3].is_nan() && f.delta[4].is_nan() && f.delta[6].is_nan());
    assert_eq!(f.delta[5], 0.0);
    assert!(f.differs());

    let same = compare_field("x", Group::State, &loops[..2], &[Some(1.0), None], &[Some(1.0), None], 0.0, 0.0);
    assert_eq!((same.compared, same.differing, same.over, same.rms, same.max_at), (1, 0, 0, 0.0, None));
    assert!(!same.differs());
}

#[test]
fn columns_group_by_prefix() {
    let groups = ["k", "t_s", "theta_rad", "meas.imu.x_m", "est.bias_rad", "cmd.current_A", "applied.current_A"]
        .map(Group::of_column);
    let expected =
        [None, None, Some(Group::State), Some(Group::Meas), Some(Group::Est), Some(Group::Cmd), Some(Group::Applied)];
    assert_eq!(groups, expected);
}

#[test]
fn a_fields_own_tolerance_beats_its_groups_and_the_last_given_wins() {
    let given: Vec<(String, f64)> =
        [("est.x", 1e-3), ("est", 0.5), ("est", 0.25), ("state", 2.0)].map(|(n, v)| (n.to_string(), v)).into();
    assert_eq!(tolerance_for("est.x", Group::Est, &given), 1e-3);
    assert_eq!(tolerance_for("est.y", Group::Est, &given), 0.25);
    assert_eq!(tolerance_for("theta", Group::State, &given), 2.0);
    assert_eq!(tolerance_for("cmd.u", Group::Cmd, &given), 0.0);
}

#[test]
fn tolerances_parse_or_say_why_not() {
    assert_eq!(parse_tolerance("est.theta_rad=1e-9").unwrap(), ("est.theta_rad".to_string(), 1e-9));
    assert_eq!(parse_tolerance("latency=2").unwrap(), ("latency".to_string(), 2.0));
    let why = |text: &str| match parse_tolerance(text) {
        Err(ToolError::BadInput(why)) => why,
        other => panic!("{text}: {other:?}"),
    };
    assert_eq!(why("est"), "--tolerance est: give FIELD=ABS, for example est.theta_rad=1e-9");
    assert_eq!(why("est=abc"), "--tolerance est=abc: \"abc\" is not a number");
    assert_eq!(why("est=-1"), "--tolerance est=-1: a tolerance is a finite number, 0 or more");
    assert_eq!(why("est=inf"), "--tolerance est=inf: a tolerance is a finite number, 0 or more");
    assert_eq!(
        why("latency=0.5"),
        "--tolerance latency=0.5: latency=R takes a ratio of 1 or more (2: B within half to twice A)"
    );
}

fn stats(p50: u64, p99: u64, max: u64) -> Stats {
    Stats { count: 10, p50: Some(p50), p99: Some(p99), max: Some(max), ..Stats::default() }
}

#[test]
fn latency_ratios_are_judged_within_one_over_r_to_r() {
    let (a, b) = (stats(1000, 2000, 4000), stats(500, 4000, 9000));
    let l = LatencyRatio::of("end to end", Some(&a), Some(&b), None);
    assert_eq!(l.ratio, [Some(0.5), Some(2.0), Some(2.25)]);
    assert_eq!(l.within, None);
    let l = LatencyRatio::of("end to end", Some(&a), Some(&b), Some(2.0));
    assert_eq!(l.within, Some([true, true, false]));
    assert_eq!(l.over().collect::<Vec<_>>(), [2]);
    // A hop one run lacks has no ratio and is over; both lacking it are the same.
    let l = LatencyRatio::of("hop", Some(&a), None, Some(2.0));
    assert_eq!((l.ratio, l.within), ([None; 3], Some([false; 3])));
    let l = LatencyRatio::of("hop", None, None, Some(2.0));
    assert_eq!(l.within, Some([true; 3]));
}

fn run_diff(fields: Vec<FieldDiff>) -> RunDiff {
    RunDiff { scenario: "pendulum".into(), rate_hz: 1000.0, fields, ..RunDiff::default() }
}

#[test]
fn the_verdict_names_the_field_over_tolerance_first() {
    let loops: Vec<LoopAt> = (0..500).map(at).collect();
    let field = |name: &str, group, jump: usize, tolerance: f64| {
        let a: Vec<Option<f64>> = vec![Some(0.0); 500];
        let b: Vec<Option<f64>> = (0..500).map(|k| Some(if k >= jump { 1.0 } else { 0.0 })).collect();
        compare_field(name, group, &loops, &a, &b, tolerance, 0.0)
    };
    let same = compare_field("theta_rad", Group::State, &loops, &[Some(1.0); 500], &[Some(1.0); 500], 0.0, 0.0);
    assert!(run_diff(vec![same.clone()]).within_tolerance());
    assert_eq!(run_diff(vec![same.clone()]).verdict(), "identical in every loop");

    let diff = run_diff(vec![same.clone(), field("cmd.u", Group::Cmd, 450, 0.0), field("est.x", Group::Est, 412, 0.0)]);
    assert!(!diff.within_tolerance());
    assert_eq!(diff.verdict(), "2 fields over tolerance; first: est.x at loop 412 (t = 0.412 s)");
    let text = diff.render();
    assert!(text.contains("\n  estimate (est.*)\n    est.x "), "{text}");
    assert!(!text.contains("theta_rad"), "an identical field is not listed:\n{text}");

    let within = run_diff(vec![same, field("est.x", Group::Est, 412, 1.0)]);
    assert!(within.within_tolerance());
    assert_eq!(within.verdict(), "1 field differs, within its tolerance");
}
