//! The layers depend only downwards, and no folder's files are in an import cycle.
//!
//! Each folder of `shared/sdk/src` (the stage SDK: contract, config, model, runtime) and of
//! `shared/src` (the scenarios and the rest of LoopLab, which names the SDK's layers through its
//! re-exports) is a layer (ARCHITECTURE.md has the picture). A source file may
//! name `crate::<layer>` only for its own layer or one below it. Read from the source text:
//! every `crate::`, `super::` and `self::` path, written in full or in `{...}` groups, taken to
//! the module file it names (the longest prefix of the path that is a file, so an item or an
//! inline module counts as its file). Within each folder, its files and subfolders (its parts)
//! must not import each other in a circle; a folder's `mod.rs` and its parts are one unit (the
//! parts use what it declares, it assembles them).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Bottom to top.
const LAYERS: [&str; 9] =
    ["contract", "config", "model", "scenarios", "runtime", "monitor", "launcher", "tools", "cli"];

type Module = Vec<String>;

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

/// The module a file defines, from its path under the crate (`config/launch.rs` → [config,
/// launch]; `monitor/mod.rs` → [monitor]; `lib.rs` → []).
fn module_of(relative: &str) -> Module {
    let relative = Path::new(relative).with_extension("");
    let mut segments: Module = relative.iter().map(|s| s.to_string_lossy().into_owned()).collect();
    if segments.last().is_some_and(|s| s == "mod" || s == "lib") {
        segments.pop();
    }
    segments
}

/// The source with comments, strings and character literals blanked, so that only code is read.
fn code_only(text: &str) -> Vec<char> {
    let s: Vec<char> = text.chars().collect();
    let mut out = s.clone();
    let blank = |out: &mut Vec<char>, from: usize, to: usize| {
        for c in &mut out[from..to.min(s.len())] {
            if *c != '\n' {
                *c = ' ';
            }
        }
    };
    let mut i = 0;
    while i < s.len() {
        let next = s.get(i + 1).copied();
        if s[i] == '/' && next == Some('/') {
            let end = s[i..].iter().position(|c| *c == '\n').map_or(s.len(), |p| i + p);
            blank(&mut out, i, end);
            i = end;
        } else if s[i] == '/' && next == Some('*') {
            let end = (i + 2..s.len()).find(|&j| s[j - 1] == '*' && s[j] == '/').map_or(s.len(), |j| j + 1);
            blank(&mut out, i, end);
            i = end;
        } else if s[i] == 'r' && matches!(next, Some('"' | '#')) && (i == 0 || !is_ident(s[i - 1])) {
            // r"…" or r#"…"#
            let hashes = s[i + 1..].iter().take_while(|c| **c == '#').count();
            if s.get(i + 1 + hashes) != Some(&'"') {
                i += 1;
                continue;
            }
            let close: String = std::iter::once('"').chain(std::iter::repeat_n('#', hashes)).collect();
            let body = i + 2 + hashes;
            let rest: String = s[body..].iter().collect();
            let end = rest.find(&close).map_or(s.len(), |p| body + rest[..p].chars().count() + close.len());
            blank(&mut out, i, end);
            i = end;
        } else if s[i] == '"' {
            let mut j = i + 1;
            while j < s.len() && s[j] != '"' {
                j += if s[j] == '\\' { 2 } else { 1 };
            }
            blank(&mut out, i, j + 1);
            i = j + 1;
        } else if s[i] == '\'' {
            // A character literal ('x', '\n', '{'), not a lifetime ('a).
            let end = if next == Some('\\') {
                (i + 3..s.len()).find(|&j| s[j] == '\'').map(|j| j + 1)
            } else if s.get(i + 2) == Some(&'\'') {
                Some(i + 3)
            } else {
                None
            };
            match end {
                Some(end) => {
                    blank(&mut out, i, end);
                    i = end;
                }
                None => i += 1,
            }
        } else {
            i += 1;
        }
    }
    out
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

fn skip_space(s: &[char], i: &mut usize) {
    while *i < s.len() && s[*i].is_whitespace() {
        *i += 1;
    }
}

fn ident(s: &[char], i: &mut usize) -> String {
    let start = *i;
    while *i < s.len() && is_ident(s[*i]) {
        *i += 1;
    }
    s[start..*i].iter().collect()
}

fn starts_with(s: &[char], i: usize, word: &str) -> bool {
    word.chars().enumerate().all(|(k, c)| s.get(i + k) == Some(&c))
}

/// A path's tail from `i` (`a::b::C`, `a::{b, c::{d, self}}`, `*`), as the paths it names; a
/// group's `self` names its prefix.
fn use_tree(s: &[char], i: &mut usize) -> Vec<Module> {
    skip_space(s, i);
    if s.get(*i) == Some(&'{') {
        *i += 1;
        let mut out = Vec::new();
        loop {
            skip_space(s, i);
            match s.get(*i) {
                None => break,
                Some('}') => {
                    *i += 1;
                    break;
                }
                Some(',') => *i += 1,
                Some(_) => {
                    let before = *i;
                    out.extend(use_tree(s, i));
                    if *i == before {
                        *i += 1; // not a path: step over it
                    }
                }
            }
        }
        return out;
    }
    let name = ident(s, i);
    if name.is_empty() {
        if s.get(*i) == Some(&'*') {
            *i += 1;
        }
        return vec![Vec::new()];
    }
    if starts_with(s, *i, "::") {
        *i += 2;
        let mut out = use_tree(s, i);
        for path in &mut out {
            if name != "self" {
                path.insert(0, name.clone());
            }
        }
        return out;
    }
    vec![if name == "self" { Vec::new() } else { vec![name] }]
}

/// Where a path starts from.
#[derive(Debug, Clone, PartialEq)]
enum Anchor {
    Crate,
    /// `self::` is 0, `super::` 1, `super::super::` 2, counted from the module the text is in.
    Up(usize),
}

/// Every path a file's code names from `crate::`, `self::` or `super::`, with how many inline
/// `mod x { … }` blocks enclose it (a `super` inside `mod tests` is the file itself).
fn paths_in(text: &str) -> Vec<(Anchor, usize, Module)> {
    let s = code_only(text);
    let mut out = Vec::new();
    let (mut depth, mut inline_mods) = (0usize, Vec::<usize>::new());
    let mut i = 0;
    while i < s.len() {
        let boundary = i == 0 || !(is_ident(s[i - 1]) || s[i - 1] == ':');
        if s[i] == '{' {
            depth += 1;
        } else if s[i] == '}' {
            depth = depth.saturating_sub(1);
            if inline_mods.last() == Some(&depth) {
                inline_mods.pop();
            }
        } else if boundary && starts_with(&s, i, "mod") && s.get(i + 3).is_some_and(|c| c.is_whitespace()) {
            let mut j = i + 3;
            skip_space(&s, &mut j);
            let name = ident(&s, &mut j);
            skip_space(&s, &mut j);
            if !name.is_empty() && s.get(j) == Some(&'{') {
                inline_mods.push(depth);
                depth += 1;
                i = j + 1;
                continue;
            }
        } else if boundary
            && (starts_with(&s, i, "crate::") || starts_with(&s, i, "super::") || starts_with(&s, i, "self::"))
        {
            let mut j = i;
            let anchor = if starts_with(&s, j, "crate::") {
                j += "crate::".len();
                Anchor::Crate
            } else if starts_with(&s, j, "self::") {
                j += "self::".len();
                Anchor::Up(0)
            } else {
                let mut ups = 0;
                while starts_with(&s, j, "super::") {
                    j += "super::".len();
                    ups += 1;
                }
                Anchor::Up(ups)
            };
            for path in use_tree(&s, &mut j) {
                out.push((anchor.clone(), inline_mods.len(), path));
            }
            i = j.max(i + 1);
            continue;
        }
        i += 1;
    }
    out
}

/// The full path under the crate that a path names from a file of module `own`; None when it
/// stays inside the file (its own inline modules).
fn absolute(own: &Module, anchor: &Anchor, inline: usize, path: &Module) -> Option<Module> {
    match anchor {
        Anchor::Crate => Some(path.clone()),
        Anchor::Up(ups) if *ups <= inline => None,
        Anchor::Up(ups) => {
            let up = ups - inline;
            let mut out = own[..own.len().checked_sub(up)?].to_vec();
            out.extend(path.iter().cloned());
            Some(out)
        }
    }
}

/// The longest prefix of `path` that is a module file.
fn module_file(files: &BTreeSet<Module>, path: &Module) -> Module {
    (0..=path.len()).rev().map(|n| path[..n].to_vec()).find(|p| files.contains(p)).unwrap_or_default()
}

fn layer(name: &str) -> Option<usize> {
    LAYERS.iter().position(|l| *l == name)
}

fn join(module: &[String]) -> String {
    module.join("::")
}

/// Everything wrong with a crate given as (path under `src/`, text): imports against the layers
/// and every import cycle among the parts of one folder.
fn check(files: &[(String, String)]) -> Vec<String> {
    let modules: BTreeSet<Module> = files.iter().map(|(name, _)| module_of(name)).collect();
    let mut wrong = Vec::new();
    // A folder's part → the parts of the same folder it imports (siblings only: an import from
    // a/x/p.rs to a/y/q.rs is x → y in folder a).
    let mut graph: BTreeMap<Module, BTreeSet<Module>> = BTreeMap::new();
    for (name, text) in files {
        let own = module_of(name);
        let Some(first) = own.first() else { continue }; // lib.rs declares the layers
        let Some(own_layer) = layer(first) else {
            wrong.push(format!("{name}: `{first}` is not a layer; put the file in one of {LAYERS:?}"));
            continue;
        };
        for (anchor, inline, path) in paths_in(text) {
            let Some(target) = absolute(&own, &anchor, inline, &path) else { continue };
            match target.first().and_then(|t| layer(t)) {
                None => wrong.push(format!("{name}: `crate::{}` is not a layer path", join(&target))),
                Some(l) if l > own_layer => {
                    wrong.push(format!("{name}: imports `crate::{}` from a layer above its own", join(&target)))
                }
                Some(_) => {
                    let to = module_file(&modules, &target);
                    let common = own.iter().zip(&to).take_while(|(a, b)| a == b).count();
                    // Neither is the other's folder module (nor the file itself).
                    if own.len() > common && to.len() > common {
                        graph.entry(own[..=common].to_vec()).or_default().insert(to[..=common].to_vec());
                    }
                }
            }
        }
    }
    for cycle in cycles(&graph) {
        wrong.push(format!("import cycle: {}", cycle.iter().map(|m| join(m)).collect::<Vec<_>>().join(" → ")));
    }
    wrong
}

/// Every cycle a depth-first search closes (one per edge back onto its stack).
fn cycles(graph: &BTreeMap<Module, BTreeSet<Module>>) -> Vec<Vec<Module>> {
    fn visit(
        node: &Module,
        graph: &BTreeMap<Module, BTreeSet<Module>>,
        state: &mut BTreeMap<Module, u8>,
        stack: &mut Vec<Module>,
        found: &mut Vec<Vec<Module>>,
    ) {
        state.insert(node.clone(), 1);
        stack.push(node.clone());
        for next in graph.get(node).into_iter().flatten() {
            match state.get(next) {
                Some(1) => {
                    let from = stack.iter().position(|n| n == next).unwrap();
                    let mut cycle = stack[from..].to_vec();
                    cycle.push(next.clone());
                    found.push(cycle);
                }
                Some(_) => {}
                None => visit(next, graph, state, stack, found),
            }
        }
        stack.pop();
        state.insert(node.clone(), 2);
    }
    let (mut state, mut found) = (BTreeMap::new(), Vec::new());
    for node in graph.keys() {
        if !state.contains_key(node) {
            visit(node, graph, &mut state, &mut Vec::new(), &mut found);
        }
    }
    found
}

/// The files of one crate's `src`, as (path under `src/`, text).
fn crate_files(src: &str) -> Vec<(String, String)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join(src);
    let mut paths = Vec::new();
    sources(&root, &mut paths);
    paths.sort();
    paths
        .iter()
        .map(|p| (p.strip_prefix(&root).unwrap().display().to_string(), std::fs::read_to_string(p).unwrap()))
        .collect()
}

/// Both crates: the stage SDK (`shared/sdk`, the bottom layers) and the rest of LoopLab above it
/// (`shared/`, which names the SDK's layers through its re-exports).
#[test]
fn every_import_runs_down_or_across_and_no_module_is_in_a_cycle() {
    for (src, at_least) in [("shared/sdk/src", 50), ("shared/src", 100)] {
        let files = crate_files(src);
        assert!(files.len() > at_least, "read {} files from {src}", files.len());
        let wrong = check(&files);
        assert!(wrong.is_empty(), "{src}: imports against the layers, or in a cycle:\n{}", wrong.join("\n"));
    }
}

/// The stage SDK is the bottom four layers and names nothing above them (cargo refuses it too:
/// the SDK does not depend on the crate above it), so a stage of the user's own serves any
/// catalog and links none of LoopLab's plots, recordings or scenarios.
#[test]
fn the_stage_sdk_is_the_bottom_four_layers_and_reaches_no_scenario() {
    let folders = |src: &str| -> BTreeSet<String> {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join(src);
        std::fs::read_dir(root)
            .unwrap()
            .flatten()
            .filter(|e| e.path().is_dir())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect()
    };
    assert_eq!(folders("shared/sdk/src"), BTreeSet::from(["config", "contract", "model", "runtime"].map(String::from)));
    for layer in ["contract", "config", "model"] {
        assert!(!folders("shared/src").contains(layer), "shared/src/{layer}: the SDK's layer, in the crate above it");
    }
    for (name, text) in crate_files("shared/sdk/src") {
        for (anchor, _, path) in paths_in(&text) {
            // The scenarios, and every layer above the runtime.
            let outside = path.first().is_some_and(|first| first == "scenarios" || layer(first) > layer("runtime"));
            assert!(
                !(matches!(anchor, Anchor::Crate) && outside),
                "shared/sdk/src/{name}: names `crate::{}`",
                join(&path)
            );
        }
    }
}

fn names(text: &str) -> Vec<String> {
    paths_in(text)
        .into_iter()
        .map(|(anchor, inline, path)| {
            let from = match anchor {
                Anchor::Crate => "crate".to_string(),
                Anchor::Up(n) => format!("up{n}"),
            };
            format!("{from}/{inline}:{}", join(&path))
        })
        .collect()
}

#[test]
fn the_checker_sees_paths_in_full_in_groups_and_relative() {
    let text = "use crate::{contract::msg::X, config::{launch, faults}};\n// crate::tools in a comment\n\
                let a = crate::model::sensors::f(\"crate::runtime\");\nuse super::{layout, params::Model};\n\
                use super::dynamics::{self, rotation};\nmod tests {\n    use super::*;\n    \
                use super::super::reference::R;\n    let c = '{';\n}\nuse self::plant::P;";
    assert_eq!(
        names(text),
        [
            "crate/0:contract::msg::X",
            "crate/0:config::launch",
            "crate/0:config::faults",
            "crate/0:model::sensors::f",
            "up1/0:layout",
            "up1/0:params::Model",
            "up1/0:dynamics",
            "up1/0:dynamics::rotation",
            "up1/1:",
            "up2/1:reference::R",
            "up0/0:plant::P",
        ]
    );
}

fn crate_of(files: &[(&str, &str)]) -> Vec<(String, String)> {
    files.iter().map(|(name, text)| (name.to_string(), text.to_string())).collect()
}

/// Two files of one folder that import each other are reported, whether the import is written
/// from `super::`, in full from `crate::`, or from a test module; without the circle nothing is.
#[test]
fn a_cycle_between_two_files_of_one_folder_is_reported() {
    let folder = [
        ("lib.rs", "pub mod scenarios;"),
        ("scenarios/mod.rs", "pub mod kite;"),
        (
            "scenarios/kite/mod.rs",
            "pub mod controller;\npub mod reference;\nuse self::controller::Law;\npub mod state {}",
        ),
        ("scenarios/kite/reference.rs", "use super::controller::Law;\nuse super::state;"),
    ];
    for controller in [
        "use crate::scenarios::kite::reference::Reference;",
        "use super::{reference::Reference, state};",
        "pub enum Law {}\n#[cfg(test)]\nmod tests {\n    use super::super::reference::Reference;\n}",
    ] {
        let mut files = crate_of(&folder);
        files.push(("scenarios/kite/controller.rs".into(), controller.into()));
        let wrong = check(&files);
        assert_eq!(
            wrong,
            ["import cycle: scenarios::kite::controller → scenarios::kite::reference → scenarios::kite::controller"],
            "{controller}"
        );
    }
    // The folder's own module and an inline module of it (`state`) are no part of a cycle, and
    // a test module's `super::*` is its own file.
    let mut files = crate_of(&folder);
    files.push(("scenarios/kite/controller.rs".into(), "use super::state;\nmod tests { use super::*; }".into()));
    assert_eq!(check(&files), Vec::<String>::new());
}

/// A cycle between two folders of one layer is reported as one between the folders.
#[test]
fn a_cycle_between_two_folders_is_reported() {
    let files = crate_of(&[
        ("scenarios/mod.rs", "pub mod a;\npub mod b;"),
        ("scenarios/a/mod.rs", "pub mod plant;"),
        ("scenarios/a/plant.rs", "use crate::scenarios::b::plant::skew;"),
        ("scenarios/b/mod.rs", "pub mod plant;\npub mod estimator;"),
        ("scenarios/b/plant.rs", ""),
        ("scenarios/b/estimator.rs", "use crate::scenarios::a::plant::Model;"),
    ]);
    assert_eq!(check(&files), ["import cycle: scenarios::a → scenarios::b → scenarios::a"]);
}

#[test]
fn an_upward_import_is_reported() {
    let files = crate_of(&[
        ("model/mod.rs", "pub mod so3;"),
        ("model/so3.rs", "use crate::runtime::stage::plant::PlantCore;\nuse crate::contract::msg::Header;"),
        ("runtime/stage/plant.rs", "use crate::model::so3::skew;"),
        ("cli.rs", "use crate::nowhere::X;"),
    ]);
    assert_eq!(
        check(&files),
        [
            "model/so3.rs: imports `crate::runtime::stage::plant::PlantCore` from a layer above its own",
            "cli.rs: `crate::nowhere::X` is not a layer path",
        ]
    );
}
