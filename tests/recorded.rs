//! A real run's `run.mcap` read back by `runtime::replay::recording_reader::load` (what `looplab replay` plays
//! back): trajectory.csv's numbers exactly, and the flags the monitor saw. The reader's
//! round trip of awkward floats and its errors are unit tests (`monitor/sinks/recorded_tests.rs`).

use crate::common;

use common::{Run, run, run_in_process};
use looplab_shared::model::layout::VectorLayout;
use looplab_shared::runtime::replay::recording_reader::{RecordedLoop, load};

/// Equal bits, or both NaN.
fn same(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

/// The run's loops as the reader gives them back, and its layout.
fn read_back(r: &Run) -> (Vec<RecordedLoop>, VectorLayout) {
    let (config, scenario) = looplab_shared::scenarios::load_resolved(&r.dir.join("launch.toml")).unwrap();
    let layout = VectorLayout::new(&config, scenario.as_ref());
    let recorded = load(&r.dir, &layout, config.loops()).unwrap();
    assert_eq!(recorded.len() as u64, r.summary["loops"].as_u64().unwrap());
    (recorded, layout)
}

/// Every cell of trajectory.csv equals the value the reader gives back, bit for bit: the state,
/// each sensor's reading, the estimate, the command and the input applied; k and t too.
fn assert_matches_trajectory(r: &Run, recorded: &[RecordedLoop], layout: &VectorLayout) {
    let text = std::fs::read_to_string(r.dir.join("trajectory.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next().unwrap().split(',').collect::<Vec<_>>(), layout.trajectory_columns());
    let rows: Vec<Vec<&str>> = lines.map(|line| line.split(',').collect()).collect();
    assert_eq!(rows.len(), recorded.len());
    for (row, got) in rows.iter().zip(recorded) {
        let k: u64 = row[0].parse().unwrap();
        let state = got.state.unwrap_or_else(|| panic!("loop {k}: no state"));
        assert_eq!((state.header.k, state.header.t.to_string()), (k, row[1].to_string()));
        // The cells in trajectory.csv's order.
        let mut values: Vec<f64> = state.x[..layout.state.len()].to_vec();
        let m = got.measurements.unwrap();
        for (s, (_, components)) in layout.sensors.iter().enumerate() {
            values.extend(&m.readings[s].value[..components.len()]);
        }
        values.extend(&got.estimate.unwrap().x[..layout.estimate.len()]);
        values.extend(&got.command.unwrap().u[..layout.input.len()]);
        values.extend(&state.u_applied[..layout.input.len()]);
        let cells: Vec<f64> = row[2..].iter().map(|cell| cell.parse().unwrap()).collect();
        assert_eq!(values.len(), cells.len());
        for (column, (value, cell)) in values.iter().zip(&cells).enumerate() {
            assert!(
                same(*value, *cell),
                "loop {k}, {}: {value:e} against {cell:e}",
                layout.trajectory_columns()[column + 2]
            );
        }
        // The measurements carry the input applied as the state does.
        assert_eq!(m.u_applied[..layout.input.len()], state.u_applied[..layout.input.len()], "loop {k}");
    }
}

/// The dropped estimates: marked lost on the estimate and the command, as the plant's loop
/// records (and summary.json) count them; the state is never lost.
fn assert_lost_as_recorded(r: &Run, recorded: &[RecordedLoop]) {
    let lost_estimates = recorded.iter().filter(|l| l.estimate.unwrap().header.lost != 0).count() as u64;
    let lost_records = recorded.iter().filter(|l| l.record.unwrap().lost != 0).count() as u64;
    assert!(lost_estimates > 10, "{lost_estimates} lost estimates");
    assert_eq!(lost_records, lost_estimates);
    assert_eq!(lost_records, r.summary["lost_commands"].as_u64().unwrap());
    assert!(recorded.iter().all(|l| l.command.unwrap().header.lost == l.record.unwrap().lost));
    assert!(recorded.iter().all(|l| l.state.unwrap().header.lost == 0 && l.measurements.unwrap().header.lost == 0));
}

const ARGS: [&str; 8] =
    ["pendulum", "--mode", "lockstep", "--duration", "1", "--fault", "drop estimator 50% at 0.3s for 0.2s", "--seed"];

#[test]
fn a_lockstep_run_over_shared_memory_reads_back_as_its_trajectory() {
    let r = run("recorded-lockstep", &[&ARGS[..], &["7"]].concat());
    let (recorded, layout) = read_back(&r);
    assert_matches_trajectory(&r, &recorded, &layout);
    assert_lost_as_recorded(&r, &recorded);
    // No process restarted: every incarnation is 0; every sensor had delivered by the end.
    assert!(recorded.iter().all(|l| l.command.unwrap().header.incarnations == [0; 4]));
    let last = recorded.last().unwrap().measurements.unwrap();
    assert!(last.readings[..layout.sensors.len()].iter().all(|r| r.valid == 1 && r.seq > 0));
    // The encoder at 1 kHz: its sample k is loop k's, fresh, the k-th it delivered.
    let encoder = layout.sensors.iter().position(|(name, _)| name == "encoder").unwrap();
    let reading = recorded[5].measurements.unwrap().readings[encoder];
    assert_eq!((reading.sample_time, reading.seq, reading.fresh, reading.valid), (0.005, 5, 1, 1));
}

#[test]
fn an_in_process_run_reads_back_as_its_trajectory() {
    let r = run_in_process("recorded-in-process", &[&ARGS[..], &["7"]].concat());
    let (recorded, layout) = read_back(&r);
    assert_matches_trajectory(&r, &recorded, &layout);
    assert_lost_as_recorded(&r, &recorded);
}
