//! The kernels in `src/` never depend on ECS scheduling: only the systems
//! module (`systems/`) and the command-line binary may name schedules,
//! queries or the systems module.

use std::path::Path;

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

#[test]
fn kernels_do_not_depend_on_ecs_scheduling() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    // lib.rs declares the systems module; the others are the binary.
    let allowed = [
        "lib.rs",
        "main.rs",
        "bench.rs",
        "compare_cmd.rs",
        "tradeoff_cmd.rs",
    ];
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
        let name = f.file_name().unwrap().to_str().unwrap();
        if allowed.contains(&name) {
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
