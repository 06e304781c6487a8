//! The shared crate's layers depend only downwards, and its modules have no import cycle.
//!
//! Each folder of `shared/src` is a layer (ARCHITECTURE.md has the picture). A source file may
//! name `crate::<layer>` only for its own layer or one below it. Read from the source text: a
//! path written in full (`crate::config::launch::Mode`) or a `use crate::{...}` group.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Bottom to top.
const LAYERS: [&str; 9] =
    ["contract", "config", "model", "scenarios", "runtime", "monitor", "launcher", "tools", "cli"];

fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The module a file defines, as path segments under the crate (`config/launch.rs` →
/// [config, launch]; `monitor/mod.rs` → [monitor]).
fn module_of(root: &Path, file: &Path) -> Vec<String> {
    let relative = file.strip_prefix(root).unwrap().with_extension("");
    let mut segments: Vec<String> = relative.iter().map(|s| s.to_string_lossy().into_owned()).collect();
    if segments.last().is_some_and(|s| s == "mod" || s == "lib") {
        segments.pop();
    }
    segments
}

/// Every `crate::a::b` path a source names, as its first two segments, with `use crate::{a::b,
/// c}` groups expanded. Comments are skipped.
fn crate_paths(text: &str) -> Vec<Vec<String>> {
    let code: String = text.lines().map(|line| line.split("//").next().unwrap_or("")).collect::<Vec<_>>().join("\n");
    let mut out = Vec::new();
    let mut rest = code.as_str();
    while let Some(at) = rest.find("crate::") {
        let preceded = rest[..at].chars().next_back().is_some_and(|c| c.is_alphanumeric() || c == '_');
        rest = &rest[at + "crate::".len()..];
        if preceded {
            continue; // `looplab_shared::...` or another crate's path
        }
        if let Some(group) = rest.strip_prefix('{') {
            let end = matching_brace(group);
            for item in split_top_level(&group[..end]) {
                // `config::{launch, faults}` names both modules.
                match item.split_once("::{") {
                    Some((prefix, inner)) => {
                        let inner = &inner[..matching_brace(inner)];
                        for sub in split_top_level(inner) {
                            out.push(segments(&format!("{prefix}::{sub}")));
                        }
                    }
                    None => out.push(segments(item)),
                }
            }
            continue;
        }
        out.push(segments(rest));
    }
    out.retain(|p| !p.is_empty());
    out
}

fn matching_brace(text: &str) -> usize {
    let mut depth = 0;
    for (i, c) in text.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => return i,
            '}' => depth -= 1,
            _ => {}
        }
    }
    text.len()
}

fn split_top_level(text: &str) -> Vec<&str> {
    let (mut parts, mut depth, mut start) = (Vec::new(), 0, 0);
    for (i, c) in text.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(text[start..i].trim());
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(text[start..].trim());
    parts
}

/// The first two identifiers of a path (`config::launch::Mode` → [config, launch]).
fn segments(path: &str) -> Vec<String> {
    path.split("::")
        .take(2)
        .map(|s| s.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect::<String>())
        .take_while(|s| !s.is_empty())
        .collect()
}

fn layer(name: &str) -> Option<usize> {
    LAYERS.iter().position(|l| *l == name)
}

#[test]
fn every_import_runs_down_or_across_and_no_module_is_in_a_cycle() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("shared/src");
    let mut files = Vec::new();
    sources(&root, &mut files);
    files.sort();
    let mut wrong = Vec::new();
    // Module (first two segments) → the modules it names.
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in &files {
        let module = module_of(&root, file);
        let Some(own) = module.first() else { continue }; // lib.rs declares the layers
        let name = file.strip_prefix(&root).unwrap().display().to_string();
        let Some(own_layer) = layer(own) else {
            wrong.push(format!("{name}: `{own}` is not a layer; put the file in one of {LAYERS:?}"));
            continue;
        };
        let from = module.iter().take(2).cloned().collect::<Vec<_>>().join("::");
        let text = std::fs::read_to_string(file).unwrap();
        for path in crate_paths(&text) {
            match layer(&path[0]) {
                None => wrong.push(format!("{name}: `crate::{}` is not a layer path", path.join("::"))),
                Some(l) if l > own_layer => {
                    wrong.push(format!("{name}: imports `crate::{}` from a layer above its own", path.join("::")))
                }
                Some(_) => {
                    let to = path.join("::");
                    // A folder's own module and its files are one unit.
                    if to != from && !to.starts_with(&format!("{from}::")) && !from.starts_with(&format!("{to}::")) {
                        graph.entry(from.clone()).or_default().insert(to);
                    }
                }
            }
        }
    }
    assert!(wrong.is_empty(), "imports against the layers:\n{}", wrong.join("\n"));

    // Depth-first search for a cycle among modules.
    fn visit(
        node: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(node.to_string(), 1);
        stack.push(node.to_string());
        for next in graph.get(node).into_iter().flatten() {
            match state.get(next.as_str()) {
                Some(1) => {
                    let from = stack.iter().position(|n| n == next).unwrap();
                    let mut cycle = stack[from..].to_vec();
                    cycle.push(next.clone());
                    return Some(cycle);
                }
                Some(_) => {}
                None => {
                    if let Some(cycle) = visit(next, graph, state, stack) {
                        return Some(cycle);
                    }
                }
            }
        }
        stack.pop();
        state.insert(node.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for node in graph.keys() {
        if !state.contains_key(node.as_str())
            && let Some(cycle) = visit(node, &graph, &mut state, &mut Vec::new())
        {
            panic!("import cycle: {}", cycle.join(" → "));
        }
    }
}

#[test]
fn the_checker_sees_paths_in_full_and_in_groups() {
    let text = "use crate::{contract::msg::X, config::{launch, faults}};\n// crate::tools in a comment\nlet a = crate::model::sensors::f();";
    let paths = crate_paths(text);
    let names: Vec<String> = paths.iter().map(|p| p.join("::")).collect();
    assert_eq!(names, ["contract::msg", "config::launch", "config::faults", "model::sensors"]);
}
