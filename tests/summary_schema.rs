//! `summary.json` describes itself: real summaries (five processes, one with a killed and
//! restarted process, and in-process) validate against the JSON Schema kept in the repo, say
//! what wrote them and where, and give each incarnation of a process its own counts.

use crate::common;

use common::*;

/// Every problem the schema in `shared/schema/` finds in `summary`, and the keys it does not
/// describe (the schema admits unknown keys, so a key missing from it would pass unseen).
fn problems(summary: &serde_json::Value) -> Vec<String> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/shared/schema/summary.schema.json");
    let schema: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let validator = jsonschema::validator_for(&schema).expect("the schema is a valid JSON Schema");
    let mut found: Vec<String> =
        validator.iter_errors(summary).map(|e| format!("{}: {e}", e.instance_path())).collect();
    for key in summary.as_object().unwrap().keys() {
        if schema["properties"].get(key).is_none() {
            found.push(format!("{key}: not in the schema"));
        }
    }
    found
}

/// What says where the summary came from.
fn assert_describes_itself(run: &Run) {
    let s = &run.summary;
    assert_eq!(s["schema_version"], 1);
    assert_eq!(s["looplab_version"], env!("CARGO_PKG_VERSION"));
    let commit = s["git_commit"].as_str().unwrap();
    let hash = commit.strip_suffix("-dirty").unwrap_or(commit);
    assert!(
        commit == "unknown" || (hash.len() == 40 && hash.bytes().all(|b| b.is_ascii_hexdigit())),
        "git_commit {commit:?}"
    );
    let command_line: Vec<&str> = s["command_line"].as_array().unwrap().iter().map(|a| a.as_str().unwrap()).collect();
    assert!(command_line[0].ends_with("looplab"), "{command_line:?}");
    assert_eq!(command_line[1], "run");
    assert!(command_line.contains(&"--mode") && command_line.contains(&"-q"), "{command_line:?}");
    let machine = &s["machine"];
    assert!(machine["cpus"].as_u64().unwrap() >= 1, "{machine}");
    assert!(!machine["kernel"].as_str().unwrap().is_empty() && !machine["hostname"].as_str().unwrap().is_empty());
}

#[test]
fn a_lockstep_summary_validates_against_the_schema_and_says_what_wrote_it() {
    let r = run("schema-lockstep", &["--mode", "lockstep", "--duration", "0.5"]);
    assert_eq!(r.summary().loops, 500);
    assert_eq!(problems(&r.summary), Vec::<String>::new());
    assert_describes_itself(&r);
    // The schema does see a wrong value and a key it does not describe.
    let mut wrong = r.summary.clone();
    wrong["loops"] = "500".into();
    wrong["machine"]["cpus"] = (-1).into();
    wrong["surprise"] = true.into();
    assert_eq!(problems(&wrong).len(), 3, "{:?}", problems(&wrong));
}

#[test]
fn an_in_process_summary_validates_against_the_schema_and_says_what_wrote_it() {
    let r = run_in_process("schema-in-process", &["--mode", "lockstep", "--duration", "0.5"]);
    assert_eq!(r.summary().loops, 500);
    assert_eq!(problems(&r.summary), Vec::<String>::new());
    assert_describes_itself(&r);
    assert!(r.summary["command_line"].as_array().unwrap().contains(&"--in-process".into()));
}

/// A process killed once: its two incarnations each have their own count (the killed one's from
/// the monitor's loop records, the restarted one's from its report), which add up to the loops.
#[test]
fn each_incarnation_of_a_killed_process_has_its_own_counts() {
    let r = run("schema-kill", &["--mode", "lockstep", "--duration", "2", "--fault", "kill estimator at 0.5s"]);
    let s = r.summary();
    assert!(s.completed, "{:?}", s.stopped_because);
    assert_eq!(s.loops, 2000);
    assert_eq!(problems(&r.summary), Vec::<String>::new());
    let counts = |role: Role| -> Vec<Option<u64>> {
        s.processes.iter().filter(|p| p.name == role).map(|p| p.processed).collect()
    };
    // Lockstep holds the loop at 0.5 s while the estimator is killed and replaced.
    assert_eq!(counts(Role::Estimator), [Some(500), Some(1500)]);
    let skipped: Vec<_> = s.processes.iter().filter(|p| p.name == Role::Estimator).map(|p| p.skipped).collect();
    assert_eq!(skipped, [None, Some(0)], "the killed one sent no report");
    assert_eq!(counts(Role::Sensors), [Some(2000)]);
    assert_eq!(counts(Role::Controller), [Some(2000)]);
    assert_eq!(counts(Role::Plant), [None]);
}

/// A simulation that diverges (a state that overflows at the first step: gravity of 1e307 m/s²
/// still gives a finite model, which the integration step cannot follow) keeps its report: every
/// loop recorded, the metrics it could compute, the others as "NaN", where it diverged, a summary
/// valid against the schema, and figures drawn; five processes and in-process alike.
#[test]
fn a_diverged_simulation_keeps_its_report_and_says_where_it_diverged() {
    let args = ["--mode", "lockstep", "--duration", "0.3", "--set", "model.g=1e307"];
    for (name, r) in
        [("diverged", run("diverged", &args)), ("diverged-in-process", run_in_process("diverged-ip", &args))]
    {
        assert_eq!((r.summary().loops, r.summary().monitor.records), (300, 300), "{name}");
        assert_eq!(r.summary().diverged_at_loop, Some(1), "{name}");
        assert_eq!(r.summary["metrics"]["theta_final_rad"], "NaN", "{name}");
        // A maximum over the run is not a number either (not the largest value before).
        assert_eq!(r.summary["metrics"]["theta_max_abs_rad"], "NaN", "{name}");
        assert_eq!(r.summary["metrics"]["bias_true_rad"], 0.1, "{name}");
        assert!(r.summary().notes[0].starts_with("the simulation diverged at loop 1 (t = 0.001 s)"), "{name}");
        assert_eq!(problems(&r.summary), Vec::<String>::new(), "{name}");
        let report = looplab().arg("report").arg(&r.dir).output().unwrap();
        let report = String::from_utf8_lossy(&report.stdout).into_owned();
        assert!(
            report.contains("  completed, the simulation DIVERGED at loop 1: 300 of 300 loops"),
            "{name}: {report}"
        );
        let plot = looplab().arg("plot").arg(&r.dir).output().unwrap();
        assert!(plot.status.success(), "{name}: {}", String::from_utf8_lossy(&plot.stderr));
        assert!(r.dir.join("estimate.png").is_file(), "{name}");
    }
}
