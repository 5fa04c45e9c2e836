//! Layout rules of the source tree, checked on the text of the files.
//!
//! `cargo test --test layout` runs:
//! * `kernels_do_not_depend_on_ecs_scheduling`: only `systems/` and the
//!   binary name schedules, queries or the systems module;
//! * `layers_are_respected`: a file imports only its own layer or layers
//!   of strictly lower rank (`LAYERS`);
//! * `module_imports_have_no_cycles`: no files import each other in a
//!   circle (a file naming the module folder that encloses it does not
//!   count: see `imports::Analysis::cycles`);
//! * `imports::tests::*`: the checker itself, on made-up trees.

mod imports;

use std::collections::BTreeMap;
use std::path::Path;

/// Layer ranks, low to high. A file may import its own layer and layers
/// of strictly lower rank; two layers of the same rank may not import
/// each other.
const LAYERS: &[(&str, u32)] = &[
    ("core", 0),
    ("image", 1),
    ("accel", 1),
    ("geometry", 2),
    ("scene", 3),
    ("transport", 4),
    ("io", 4),
    ("radiosity", 4),
    ("integrators", 5),
    ("lightfield", 5),
    ("systems", 6),
];

fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// Every .rs file of the library (`src/` but `src/bin/`, and `systems/`),
/// by path relative to the package root.
fn library_tree() -> BTreeMap<String, String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    rust_files(&root.join("systems"), &mut files);
    files
        .into_iter()
        .map(|f| {
            let rel = f.strip_prefix(root).unwrap();
            let rel = rel
                .components()
                .map(|c| c.as_os_str().to_str().unwrap())
                .collect::<Vec<_>>()
                .join("/");
            (rel, std::fs::read_to_string(&f).unwrap())
        })
        .filter(|(rel, _)| !rel.starts_with("src/bin/"))
        .collect()
}

#[test]
fn kernels_do_not_depend_on_ecs_scheduling() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let forbidden = [
        "systems::",
        "bevy_ecs::system",
        "Schedule",
        "Query<",
        "ResMut<",
        "Res<",
        "SystemSet",
        "&World",
        "&mut World",
        "World::new",
    ];
    let mut checked = 0;
    for f in files {
        // lib.rs declares the systems module; src/bin/ is the binary.
        let rel = f.strip_prefix(&src).unwrap();
        if rel == Path::new("lib.rs") || rel.starts_with("bin") {
            continue;
        }
        let text = std::fs::read_to_string(&f).unwrap();
        for word in forbidden {
            // A whole token: `&World` must not match `&WorldLight`.
            let found = text.match_indices(word).any(|(i, _)| {
                !text[i + word.len()..]
                    .chars()
                    .next()
                    .is_some_and(|c| c.is_alphanumeric() || c == '_')
                    || word.ends_with(['<', ':'])
            });
            assert!(
                !found,
                "{} mentions `{word}`: kernels must not depend on ECS scheduling",
                f.display()
            );
        }
        checked += 1;
    }
    assert!(checked >= 15, "only {checked} kernel files found");
}

#[test]
fn layers_are_respected() {
    let v = imports::analyse(&library_tree()).layer_violations(LAYERS);
    let list: Vec<String> = v.iter().map(|v| v.message.clone()).collect();
    assert!(
        list.is_empty(),
        "{} import(s) break the layer order (a file may import its own layer \
         and layers of strictly lower rank):\n{}",
        list.len(),
        list.join("\n")
    );
}

#[test]
fn module_imports_have_no_cycles() {
    let c = imports::analyse(&library_tree()).cycles();
    let list: Vec<String> = c.iter().map(|c| c.message.clone()).collect();
    assert!(
        list.is_empty(),
        "{} import cycle(s) between files:\n{}",
        list.len(),
        list.join("\n")
    );
}

#[test]
fn the_checker_reads_the_whole_library() {
    let a = imports::analyse(&library_tree());
    assert!(a.modules.len() >= 40, "only {} files", a.modules.len());
    assert!(a.imports.len() >= 150, "only {} imports", a.imports.len());
    assert!(!a.modules.keys().any(|f| f.starts_with("src/bin/")));
    let has = |from: &str, to: &str| a.imports.iter().any(|i| i.from == from && i.to == to);
    // A plain use, a `super::` item re-exported by systems/mod.rs, and
    // `crate::Result` (re-exported by lib.rs from core::error).
    assert!(has("systems/renderer.rs", "src/io/desc.rs"));
    assert!(has("systems/wavefront.rs", "systems/frame.rs"));
    assert!(has("systems/renderer.rs", "src/core/error.rs"));
    // Every file is in a ranked layer (or is lib.rs).
    let unranked: Vec<_> = a
        .layer_violations(LAYERS)
        .into_iter()
        .filter(|v| v.to.is_empty())
        .map(|v| v.message)
        .collect();
    assert!(unranked.is_empty(), "{unranked:?}");
}

/// The checker fails on the real tree once a bad import is added to a
/// copy of it: an upward import, and (in another copy) a cycle, both
/// reported with the file and line.
#[test]
fn a_bad_import_in_a_copy_of_the_library_fails() {
    let tree = library_tree();
    let clean = imports::analyse(&tree);
    let with = |extra: &str| {
        let mut t = tree.clone();
        let math = t.get_mut("src/core/math.rs").unwrap();
        let line = math.lines().count() + 1;
        math.push_str(extra);
        (imports::analyse(&t), line)
    };

    let (a, line) = with("use crate::systems::Frame;\n");
    let new: Vec<_> = a
        .layer_violations(LAYERS)
        .into_iter()
        .filter(|v| !clean.layer_violations(LAYERS).contains(v))
        .collect();
    assert_eq!(new.len(), 1, "{new:?}");
    assert_eq!(
        new[0].message,
        format!(
            "src/core/math.rs:{line}: core (rank 0) -> systems (rank 6), a higher layer: \
             `crate::systems::Frame` names systems/frame.rs"
        )
    );

    // sampling.rs imports math.rs: math.rs importing sampling.rs closes a
    // cycle.
    let (a, line) = with("fn disk() { crate::core::sampling::concentric_disk(); }\n");
    assert_eq!(a.layer_violations(LAYERS), clean.layer_violations(LAYERS));
    let cycle = a
        .cycles()
        .into_iter()
        .find(|c| c.files.contains(&"src/core/math.rs".to_string()))
        .expect("math <-> sampling is a cycle");
    assert_eq!(cycle.files, ["src/core/math.rs", "src/core/sampling.rs"]);
    assert!(
        cycle.message.contains(&format!(
            "src/core/math.rs:{line} `crate::core::sampling::concentric_disk` -> src/core/sampling.rs"
        )),
        "{}",
        cycle.message
    );
}
