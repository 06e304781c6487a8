//! A killed controller resumes its integrators: in lockstep the launcher replaces it while the
//! plant holds the loop, so with its frozen state thawed the run is the run without the kill,
//! byte for byte. One that started afresh would lose its integrators (the library's tests in
//! `runtime/task_tests.rs` show a fresh controller commanding otherwise).

use crate::common;

use common::*;

#[test]
fn a_controller_killed_in_lockstep_resumes_and_the_trajectory_is_the_one_without_the_kill() {
    // The tethered vehicle's thrust compensator and the tilt-rotor's integrators and prefilters.
    for scenario in ["tethered", "tiltrotor"] {
        let common = [scenario, "--mode", "lockstep", "--duration", "2", "--seed", "7"];
        let nominal = run(&format!("{scenario}-nominal"), &common);
        let mut args = common.to_vec();
        args.extend(["--fault", "kill controller at 1s"]);
        let killed = run(&format!("{scenario}-killed"), &args);
        let s = killed.summary();
        assert_eq!(s.restarts[&Role::Controller], 1, "{scenario}: {:?}", s.restarts);
        assert!(s.faults[0].restarted_after_ms.is_some(), "{scenario}: {:?}", s.faults[0]);
        let bytes = |r: &Run| std::fs::read(r.dir.join("trajectory.csv")).unwrap();
        assert!(bytes(&killed) == bytes(&nominal), "{scenario}: the restarted controller did not resume");
    }
}
