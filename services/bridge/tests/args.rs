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
    let dir = std::env::temp_dir().join(format!("looplab-bridge-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let launch = dir.join("launch.toml");
    std::fs::write(&launch, "scenario = \"pendulum\"\n").unwrap();
    let out = bridge(&[
        "--launch",
        launch.to_str().unwrap(),
        "--run-id",
        "x",
        "--run-dir",
        dir.to_str().unwrap(),
        "--role",
        "bridge",
    ]);
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(String::from_utf8_lossy(&out.stderr), "bridge: error: no stage is placed on another host\n");
}
