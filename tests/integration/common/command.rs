//! Running the `abysslight` binary and reading what it leaves behind: the helpers every command-line test uses.

use std::collections::BTreeMap;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The `abysslight` binary built for these tests.
pub const BIN: &str = env!("CARGO_BIN_EXE_abysslight");

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `abysslight ARGS` in the tests' working folder.
pub fn abysslight(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

/// `abysslight ARGS` in `cwd` (relative paths in `args` are below it).
pub fn abysslight_in(args: &[&str], cwd: &Path) -> Output {
    Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run abysslight")
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A JSON file, parsed.
pub fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap()
}

/// The run report of the output folder `out` (`out/_abysslight/report.json`).
pub fn report(out: &Path) -> serde_json::Value {
    json(&out.join("_abysslight/report.json"))
}

/// Every output photo below `dir` (not `_abysslight/`), as relative path → bytes.
pub fn outputs(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    abysslight::io::find_photos(dir)
        .unwrap()
        .photos
        .into_iter()
        .map(|e| (e.relative, std::fs::read(e.path).unwrap()))
        .collect()
}

/// Hash of every file below the given paths (links not followed), by path.
pub fn snapshot(paths: &[&Path]) -> BTreeMap<PathBuf, u64> {
    let mut m = BTreeMap::new();
    for root in paths {
        for e in walkdir::WalkDir::new(root)
            .follow_links(false)
            .into_iter()
            .flatten()
        {
            if e.file_type().is_file() {
                let mut h = std::collections::hash_map::DefaultHasher::new();
                std::fs::read(e.path()).unwrap_or_default().hash(&mut h);
                m.insert(e.path().to_owned(), h.finish());
            }
        }
    }
    m
}
