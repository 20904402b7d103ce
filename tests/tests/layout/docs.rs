//! The documents checked against the code, so they cannot drift: `docs/DESIGN.md` §8's
//! equation table names real files and functions; §2's crate table has one row per
//! workspace member and its `uses` column lists exactly each crate's workspace-internal
//! dependencies (`[dependencies]`; after `dev:` the `[dev-dependencies]`); the README's
//! crate list is the workspace's members; and the intra-doc links of each `lib.rs` that
//! name a module or item of the crate root (`[`flow`]`) name one that exists.

use super::{crate_dirs, strip, workspace_root};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The workspace's members, from `members = [...]` of the root `Cargo.toml`.
fn workspace_members(root: &Path) -> BTreeSet<String> {
    let manifest = std::fs::read_to_string(root.join("Cargo.toml")).unwrap();
    let line = manifest
        .lines()
        .find(|l| l.trim_start().starts_with("members"))
        .expect("root Cargo.toml: no members line");
    let list = &line[line.find('[').unwrap() + 1..line.rfind(']').unwrap()];
    list.split(',')
        .map(|m| m.trim().trim_matches('"').to_string())
        .filter(|m| !m.is_empty())
        .collect()
}

/// The workspace members a manifest names in its `section` (`dependencies` or
/// `dev-dependencies`): `x.workspace = true`, `x = { workspace = true }`,
/// `degs-x = { path = "../x" }` and the like, by folder name.
fn internal_deps(manifest: &str, section: &str, members: &BTreeSet<String>) -> BTreeSet<String> {
    let header = format!("[{section}]");
    let mut inside = false;
    let mut deps = BTreeSet::new();
    for line in manifest.lines() {
        let line = line.split('#').next().unwrap().trim();
        if line.starts_with('[') {
            inside = line == header;
            continue;
        }
        let Some((key, value)) = line.split_once('=').filter(|_| inside) else {
            continue;
        };
        let key = key.trim().trim_end_matches(".workspace");
        let by_path = value
            .split_once("path")
            .and_then(|(_, p)| p.split('"').nth(1))
            .and_then(|p| Path::new(p).file_name())
            .map(|f| f.to_string_lossy().into_owned());
        let name = by_path.unwrap_or_else(|| key.trim_start_matches("degs-").to_string());
        if members.contains(&name) {
            deps.insert(name);
        }
    }
    deps
}

/// A crate's workspace-internal `[dependencies]` and `[dev-dependencies]`.
type Uses = (BTreeSet<String>, BTreeSet<String>);

/// §2's table: folder → (uses, dev uses) as written, or a line saying what could not be
/// read.
fn design_crate_table(design: &str) -> (BTreeMap<String, Uses>, Vec<String>) {
    let mut rows = BTreeMap::new();
    let mut errors = Vec::new();
    let lines = design
        .lines()
        .skip_while(|l| !l.starts_with("## 2."))
        .take_while(|l| !l.starts_with("## 3."))
        .filter(|l| l.starts_with("| `"));
    for row in lines {
        let cells: Vec<&str> = row.trim().trim_matches('|').split(" | ").collect();
        let folder = cells[0].split('`').nth(1).unwrap_or_default().to_string();
        let uses = cells.last().unwrap().trim();
        let (deps, dev) = uses.split_once("; dev:").unwrap_or((uses, ""));
        let list = |s: &str| -> BTreeSet<String> {
            s.split(',')
                .map(str::trim)
                .filter(|d| !d.is_empty() && *d != "—")
                .map(str::to_string)
                .collect()
        };
        let (deps, dev) = (list(deps), list(dev));
        for d in deps.iter().chain(&dev) {
            if !d.chars().all(|c| c.is_ascii_lowercase() || c == '_') {
                errors.push(format!(
                    "`{folder}`: cannot read `{d}` in the uses column (write crate folders \
                     separated by commas, dev-dependencies after `; dev:`)"
                ));
            }
        }
        rows.insert(folder, (deps, dev));
    }
    (rows, errors)
}

/// Every difference between §2's table and the manifests, each naming the crate and the
/// dependency.
fn crate_table_errors(
    design: &str,
    members: &BTreeSet<String>,
    manifests: &BTreeMap<String, String>,
) -> Vec<String> {
    let (table, mut errors) = design_crate_table(design);
    for m in members {
        if !table.contains_key(m) {
            errors.push(format!("`{m}` is a workspace member without a row"));
        }
    }
    for (folder, (deps, dev)) in &table {
        let Some(manifest) = manifests.get(folder) else {
            errors.push(format!("`{folder}` has a row but is no workspace member"));
            continue;
        };
        for (section, written) in [("dependencies", deps), ("dev-dependencies", dev)] {
            let actual = internal_deps(manifest, section, members);
            for d in actual.difference(written) {
                errors.push(format!(
                    "`{folder}`: {folder}/Cargo.toml [{section}] has `{d}`, the table does not"
                ));
            }
            for d in written.difference(&actual) {
                if !members.contains(d) {
                    errors.push(format!(
                        "`{folder}`: `{d}` in the uses column is no workspace crate"
                    ));
                    continue;
                }
                errors.push(format!(
                    "`{folder}`: the table lists `{d}`, {folder}/Cargo.toml [{section}] does not"
                ));
            }
        }
    }
    errors
}

fn manifests(root: &Path, members: &BTreeSet<String>) -> BTreeMap<String, String> {
    members
        .iter()
        .map(|m| {
            let text = std::fs::read_to_string(root.join(m).join("Cargo.toml")).unwrap();
            (m.clone(), text)
        })
        .collect()
}

#[test]
fn design_crate_table_matches_the_manifests() {
    let root = workspace_root();
    let design = std::fs::read_to_string(root.join("docs/DESIGN.md")).unwrap();
    let members = workspace_members(&root);
    assert!(members.len() >= 10, "members: {members:?}");
    let errors = crate_table_errors(&design, &members, &manifests(&root, &members));
    assert!(
        errors.is_empty(),
        "docs/DESIGN.md §2 (the uses column) disagrees with the Cargo.toml files:\n{}",
        errors.join("\n")
    );
}

#[test]
fn the_crate_table_check_finds_differences() {
    let root = workspace_root();
    let members = workspace_members(&root);
    let manifests = manifests(&root, &members);
    // A table written from the manifests passes; then gaussians loses synth, assoc
    // gains deform, deform's dev list loses evflow.
    let table = |edit: &dyn Fn(&str, String, String) -> (String, String)| -> String {
        let mut t =
            String::from("## 2. Crates\n\n| folder | binary | owns | uses |\n|---|---|---|---|\n");
        for m in &members {
            let names = |sec: &str| {
                let d: Vec<String> = internal_deps(&manifests[m], sec, &members)
                    .into_iter()
                    .collect();
                d.join(", ")
            };
            let (deps, dev) = edit(m, names("dependencies"), names("dev-dependencies"));
            let dev = if dev.is_empty() {
                String::new()
            } else {
                format!("; dev: {dev}")
            };
            t += &format!("| `{m}` | — | — | {deps}{dev} |\n");
        }
        t + "\n## 3. Files\n"
    };
    let good = table(&|_, d, v| (d, v));
    assert_eq!(
        crate_table_errors(&good, &members, &manifests),
        Vec::<String>::new()
    );
    let broken = table(&|m, d, v| match m {
        "gaussians" => (d.replace(", synth", ""), v),
        "assoc" => (d + ", deform", v),
        "deform" => (d, v.replace("evflow, ", "")),
        _ => (d, v),
    });
    let errors = crate_table_errors(&broken, &members, &manifests);
    assert_eq!(errors.len(), 3, "{errors:#?}");
    let joined = errors.join("\n");
    for want in [
        "`gaussians`: gaussians/Cargo.toml [dependencies] has `synth`",
        "`assoc`: the table lists `deform`, assoc/Cargo.toml [dependencies] does not",
        "`deform`: deform/Cargo.toml [dev-dependencies] has `evflow`",
    ] {
        assert!(joined.contains(want), "{want} not in {errors:#?}");
    }
    // A path dependency counts as well as a workspace one.
    let m: BTreeSet<String> = ["scene", "synth"].map(String::from).into();
    let toml = "[dependencies]\ndegs-scene = { path = \"../scene\" }\nglam = \"1\"\n\
                [dev-dependencies]\nsynth.workspace = true\n";
    assert_eq!(
        internal_deps(toml, "dependencies", &m),
        ["scene".to_string()].into()
    );
    assert_eq!(
        internal_deps(toml, "dev-dependencies", &m),
        ["synth".to_string()].into()
    );
}

#[test]
fn readme_crate_list_is_the_workspace_members() {
    let root = workspace_root();
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let listed: BTreeSet<String> = readme
        .lines()
        .skip_while(|l| !l.starts_with("| crate | binary |"))
        .skip(2)
        .take_while(|l| l.starts_with("| `"))
        .filter_map(|l| l.split('`').nth(1).map(str::to_string))
        .collect();
    let members = workspace_members(&root);
    assert_eq!(
        listed, members,
        "README.md's crate table (left) is not the workspace's members (right)"
    );
}

/// A `lib.rs` doc link to a lower-case name (`[`flow`]`) names a module the file
/// declares or an item it brings into the crate root.
#[test]
fn lib_rs_docs_name_modules_that_exist() {
    let mut missing = Vec::new();
    for dir in crate_dirs() {
        let lib = dir.join("src/lib.rs");
        let Ok(text) = std::fs::read_to_string(&lib) else {
            continue;
        };
        let code = strip(&text);
        let declared = |name: &str| {
            code.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .any(|w| w == name)
        };
        for line in text.lines().filter(|l| l.starts_with("//!")) {
            for name in line.split("[`").skip(1).filter_map(|s| s.split_once("`]")) {
                let name = name.0;
                let lower = name.chars().all(|c| c.is_ascii_lowercase() || c == '_');
                if lower && !declared(name) {
                    let folder = dir.file_name().unwrap().to_string_lossy().into_owned();
                    missing.push(format!("{folder}/src/lib.rs: [`{name}`]"));
                }
            }
        }
    }
    assert!(
        missing.is_empty(),
        "lib.rs docs name what the crate root does not have:\n{}",
        missing.join("\n")
    );
}

/// `docs/DESIGN.md`'s equation table names files that exist and functions they define.
#[test]
fn design_equation_table_names_real_files_and_functions() {
    let root = workspace_root();
    let design = std::fs::read_to_string(root.join("docs/DESIGN.md")).unwrap();
    let table: Vec<&str> = design
        .lines()
        .skip_while(|l| !l.starts_with("## 8."))
        .take_while(|l| !l.starts_with("## 9."))
        .filter(|l| l.starts_with("| ") && !l.starts_with("| Eq."))
        .collect();
    assert_eq!(table.len(), 15, "one row per equation (Eq. 1–15)");
    let mut missing = Vec::new();
    for row in table {
        let ticked: Vec<&str> = row.split('`').skip(1).step_by(2).collect();
        let files: Vec<&str> = ticked
            .iter()
            .copied()
            .filter(|t| t.ends_with(".rs"))
            .collect();
        assert!(!files.is_empty(), "no file in row {row}");
        let sources: String = files
            .iter()
            .map(|f| {
                std::fs::read_to_string(root.join(f)).unwrap_or_else(|_| {
                    missing.push(format!("{f} (file)"));
                    String::new()
                })
            })
            .collect();
        for name in ticked.iter().filter(|t| !t.ends_with(".rs")) {
            let f = name.rsplit("::").next().unwrap();
            if !sources.contains(&format!("fn {f}")) {
                missing.push(format!("{name} (function) in {files:?}"));
            }
        }
    }
    assert!(
        missing.is_empty(),
        "docs/DESIGN.md §8 names what does not exist:\n{}",
        missing.join("\n")
    );
}
