//! The library's layout as a rule: its top-level modules (a folder of `src/` or a single file) import
//! one another without a circle, so each stage can be read, tested and replaced on its own, and the
//! CUDA backend never reaches back to the choice of backend or the entry points built on it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Top-level module → the top-level modules its files name through `crate::`.
fn imports() -> BTreeMap<String, BTreeSet<String>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut folders = vec![src.clone()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                folders.push(path);
                continue;
            }
            if path.extension().is_none_or(|e| e != "rs") || path == src.join("lib.rs") {
                continue;
            }
            let relative = path.strip_prefix(&src).unwrap();
            let first = relative.components().next().unwrap().as_os_str();
            let module = Path::new(first)
                .file_stem()
                .unwrap()
                .to_string_lossy()
                .into_owned();
            let text = std::fs::read_to_string(&path).unwrap();
            let targets = graph.entry(module.clone()).or_default();
            for line in text.lines() {
                let code = line.split("//").next().unwrap_or("");
                for (at, _) in code.match_indices("crate::") {
                    let name: String = code[at + "crate::".len()..]
                        .chars()
                        .take_while(|c| c.is_ascii_lowercase() || *c == '_')
                        .collect();
                    if !name.is_empty() && name != module {
                        targets.insert(name);
                    }
                }
            }
        }
    }
    graph
}

/// The modules reachable from `start` (itself excluded unless on a circle).
fn reachable(graph: &BTreeMap<String, BTreeSet<String>>, start: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut stack: Vec<&String> = graph.get(start).into_iter().flatten().collect();
    while let Some(next) = stack.pop() {
        if seen.insert(next.clone()) {
            stack.extend(graph.get(next.as_str()).into_iter().flatten());
        }
    }
    seen
}

#[test]
fn no_two_top_level_modules_import_each_other_even_through_others() {
    let graph = imports();
    assert!(graph.len() > 10, "the source was read: {graph:?}");
    let circles: Vec<&String> = graph
        .keys()
        .filter(|m| reachable(&graph, m).contains(*m))
        .collect();
    assert!(
        circles.is_empty(),
        "modules on an import circle: {circles:?}\n{graph:#?}"
    );
}

#[test]
fn the_cuda_backend_never_imports_the_backend_choice_or_the_entry_points() {
    let graph = imports();
    let reached = reachable(&graph, "cuda");
    for above in [
        "backend",
        "extract",
        "matcher",
        "collection",
        "prefetch",
        "colmap",
    ] {
        assert!(
            !reached.contains(above),
            "cuda reaches {above}: {:?}",
            graph["cuda"]
        );
    }
    // The algorithm stages stay below the CUDA backend and below the entry points alike.
    for stage in ["detect", "describe", "matching", "pyramid"] {
        let reached = reachable(&graph, stage);
        assert!(
            !reached.contains("cuda") && !reached.contains("backend"),
            "{stage} reaches {reached:?}"
        );
    }
}
