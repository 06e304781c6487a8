//! The bridge binary as the launcher starts it. Its being here also makes `cargo test
//! --workspace` build `looplab-bridge` beside `looplab`, where the launcher finds it for the
//! tests that place a stage on another host.

use std::process::Command;

fn bridge(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_looplab-bridge")).args(args).output().expect("start looplab-bridge")
}

#[test]
fn a_process_that_is_not_a_bridge_is_refused() {
    let out =
        bridge(&["--launch", "/nonexistent.toml", "--run-id", "x", "--run-dir", "/nonexistent", "--role", "plant"]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        "plant: error: --role must be bridge or bridge-remote, not plant\n"
    );
}

#[test]
fn a_launch_file_without_a_remote_stage_is_refused() {
    // The pendulum's defaults: a whole launch file, with every stage here.
    let launch = concat!(env!("CARGO_MANIFEST_DIR"), "/../../launch/pendulum.toml");
    let out = bridge(&["--launch", launch, "--run-id", "x", "--run-dir", "/nonexistent", "--role", "bridge"]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(String::from_utf8_lossy(&out.stderr), "bridge: error: no stage is placed on another host\n");
}
