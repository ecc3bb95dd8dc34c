//! What a run does to its output folder before it writes: refuse a second run of the same photos at the same
//! time, refuse mixing two sets of method options in one output folder, and clear the temp files of killed runs.
//!
//! - **Lock**: `<out>/_abysslight/lock` (`lock-shard-K-of-N` for a shard, so the shards of one job run side by
//!   side) is created exclusively and holds the pid and the options fingerprint. A lock whose process is gone
//!   (a killed run) is taken over; a live one refuses the run. Dropping the [`RunLock`] removes it.
//! - **Options**: `<out>/_abysslight/options.json` holds the options that decide the output pixels (the
//!   [`fingerprint`]). A run whose fingerprint differs is refused, naming the options that differ: its photos
//!   would mix with the earlier run's (with `--resume` it would even keep them).
//! - **Stale temp files**: outputs are written to `.<name>.<random>.abysslight-tmp` and renamed into place; a
//!   killed run leaves them behind. [`remove_stale_temps`] deletes them below `--out`, only when no other run
//!   holds a lock there.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::run::options::Options;

/// Suffix of abysslight's temp files (see [`crate::io::write_with`]).
pub const TEMP_SUFFIX: &str = ".abysslight-tmp";

/// The options that decide the output pixels, as a JSON object (paths resolved). Threads, shard, resume, limit,
/// watch timing, report path and what else is saved do not change a corrected photo and are left out.
pub fn fingerprint(opts: &Options) -> serde_json::Value {
    let resolve = |p: &Option<PathBuf>| {
        p.as_deref().map(|p| {
            if p == Path::new("-") {
                p.to_owned()
            } else {
                crate::io::paths::resolve(p)
            }
        })
    };
    let o = Options {
        survey: resolve(&opts.survey),
        water_column: resolve(&opts.water_column),
        scatter: resolve(&opts.scatter),
        mask: resolve(&opts.mask),
        out: None,
        threads: None,
        resume: false,
        shard: None,
        watch: false,
        idle_timeout: None,
        poll_interval: Options::default().poll_interval,
        report: None,
        // --limit N writes the first N photos exactly as a whole run would: a later run may finish the rest.
        limit: None,
        save_scatter: false,
        save_factors: false,
        scatter_memory_mib: Options::default().scatter_memory_mib,
        // The window in effect counts, however it was given (below).
        window: None,
        contamination: None,
        risk: Options::default().risk,
        ..opts.clone()
    };
    let mut v = serde_json::to_value(&o).unwrap_or(serde_json::Value::Null);
    if let (serde_json::Value::Object(m), Ok(w)) = (&mut v, opts.window_choice()) {
        // The window in effect, however it was given.
        m.insert("window-in-effect".into(), w.n.into());
    }
    v
}

/// Names of the top-level keys whose values differ between two fingerprints.
fn differing(a: &serde_json::Value, b: &serde_json::Value) -> Vec<String> {
    let (Some(a), Some(b)) = (a.as_object(), b.as_object()) else {
        return vec!["(all)".into()];
    };
    let mut keys: Vec<String> = a
        .keys()
        .chain(b.keys())
        .filter(|k| a.get(*k) != b.get(*k))
        .cloned()
        .collect();
    keys.sort();
    keys.dedup();
    keys
}

/// A held lock; removed when dropped.
#[derive(Debug)]
pub struct RunLock {
    path: PathBuf,
}

impl RunLock {
    /// The lock file held.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for RunLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Whether process `pid` is alive. On Linux from `/proc`; elsewhere every lock is taken to be live (remove a
/// stale one by hand).
fn alive(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    let proc = Path::new("/proc");
    if proc.join("self").exists() {
        proc.join(pid.to_string()).exists()
    } else {
        true
    }
}

fn lock_name(opts: &Options) -> String {
    match opts.shard {
        Some(s) => format!("lock-shard-{}-of-{}", s.index, s.count),
        None => "lock".into(),
    }
}

fn read_lock(path: &Path) -> Option<(u32, serde_json::Value)> {
    let text = std::fs::read_to_string(path).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    let pid = v.get("pid")?.as_u64()? as u32;
    Some((pid, v))
}

/// Take the lock of this run in `work_dir` (`<out>/_abysslight`, which must exist) and check the options
/// against those of earlier runs into the same folder (recorded on the first run). Errors are usage errors (exit
/// 2) that say what to do.
pub fn acquire(opts: &Options, work_dir: &Path) -> Result<RunLock> {
    let fp = fingerprint(opts);
    let path = work_dir.join(lock_name(opts));
    let body = serde_json::json!({ "pid": std::process::id(), "options": fp });
    let mut attempts = 0;
    loop {
        attempts += 1;
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
        {
            Ok(f) => {
                use std::io::Write;
                let mut f = f;
                f.write_all(body.to_string().as_bytes())
                    .and_then(|()| f.sync_all())
                    .map_err(|e| Error::io(&path, e))?;
                break;
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && attempts < 3 => {
                match read_lock(&path) {
                    Some((pid, _)) if alive(pid) => {
                        return Err(Error::Usage(format!(
                            "{}: another abysslight run (pid {pid}) is writing these photos into {} right now; \
                             wait for it to end (or, if it is gone, remove the lock file)",
                            path.display(),
                            work_dir.parent().unwrap_or(work_dir).display()
                        )));
                    }
                    // A killed run's lock (or one being written this instant: retried once).
                    _ => {
                        if read_lock(&path).is_none() && attempts == 1 {
                            std::thread::sleep(std::time::Duration::from_millis(50));
                            if let Some((pid, _)) = read_lock(&path) {
                                if alive(pid) {
                                    continue;
                                }
                            }
                        }
                        let _ = std::fs::remove_file(&path);
                    }
                }
            }
            Err(e) => return Err(Error::io(&path, e)),
        }
    }
    let lock = RunLock { path };
    // The lock is held: compare the options with the recorded ones (or record them).
    let recorded = work_dir.join("options.json");
    match std::fs::read_to_string(&recorded) {
        Ok(text) => {
            let old: serde_json::Value =
                serde_json::from_str(&text).map_err(|e| Error::Config {
                    path: recorded.clone(),
                    reason: format!("unreadable record of an earlier run's options: {e}"),
                })?;
            let diff = differing(&old, &fp);
            if !diff.is_empty() {
                return Err(Error::Usage(format!(
                    "{} was written by a run with other options ({} differ; recorded in {}): its photos would \
                     mix with this run's{}. Use the same options, or another --out",
                    work_dir.parent().unwrap_or(work_dir).display(),
                    diff.join(", "),
                    recorded.display(),
                    if opts.resume {
                        " (--resume keeps the photos already there)"
                    } else {
                        ""
                    }
                )));
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let text = serde_json::to_string_pretty(&fp).unwrap_or_default();
            crate::io::write_with(&recorded, |w| {
                use std::io::Write;
                w.write_all(text.as_bytes())
                    .map_err(|e| Error::io(&recorded, e))
            })?;
        }
        Err(e) => return Err(Error::io(&recorded, e)),
    }
    Ok(lock)
}

/// Whether any lock in `work_dir` other than `mine` belongs to a live process.
pub fn other_live_locks(work_dir: &Path, mine: &Path) -> bool {
    let Ok(rd) = std::fs::read_dir(work_dir) else {
        return false;
    };
    rd.flatten().any(|e| {
        let p = e.path();
        p != mine
            && e.file_name().to_string_lossy().starts_with("lock")
            && read_lock(&p).is_some_and(|(pid, _)| alive(pid))
    })
}

/// Delete abysslight temp files (`.<name>.<random>.abysslight-tmp`) below `out`, not following links; returns
/// what was removed. Call it holding the lock, and only when [`other_live_locks`] is false (another shard's
/// temp files are in use).
pub fn remove_stale_temps(out: &Path) -> Vec<PathBuf> {
    let mut removed = Vec::new();
    for e in walkdir::WalkDir::new(out)
        .follow_links(false)
        .into_iter()
        .flatten()
    {
        let name = e.file_name().to_string_lossy();
        if e.file_type().is_file()
            && name.starts_with('.')
            && name.ends_with(TEMP_SUFFIX)
            && std::fs::remove_file(e.path()).is_ok()
        {
            removed.push(e.path().to_owned());
        }
    }
    removed
}

/// The start of a run into folder `out` (hook for the run): take the lock, check the options, remove stale temp
/// files when no other run is live. Returns the lock (hold it until the report is written) and the temp files
/// removed.
pub fn start(opts: &Options, out: &Path, work_dir: &Path) -> Result<(RunLock, Vec<PathBuf>)> {
    let lock = acquire(opts, work_dir)?;
    let removed = if other_live_locks(work_dir, lock.path()) {
        Vec::new()
    } else {
        remove_stale_temps(out)
    };
    Ok((lock, removed))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(out: &Path) -> Options {
        Options {
            survey: Some(out.join("../survey")),
            out: Some(out.to_owned()),
            ..Options::default()
        }
    }

    #[test]
    fn second_run_refused_while_the_first_holds_the_lock() {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("out");
        let work = out.join("_abysslight");
        std::fs::create_dir_all(&work).unwrap();
        let o = opts(&out);
        let first = acquire(&o, &work).unwrap();
        let e = acquire(&o, &work).unwrap_err().to_string();
        assert!(
            e.contains("another abysslight run") && e.contains(&std::process::id().to_string()),
            "{e}"
        );
        // Shards of one job each have their own lock.
        let shard = Options {
            shard: Some("2/3".parse().unwrap()),
            ..o.clone()
        };
        let s = acquire(&shard, &work).unwrap();
        assert!(other_live_locks(&work, s.path()));
        drop(first);
        drop(s);
        assert!(!work.join("lock").exists());
        // A killed run's lock (a pid that is not running) is taken over.
        std::fs::write(work.join("lock"), r#"{"pid": 4000000000, "options": {}}"#).unwrap();
        if Path::new("/proc/self").exists() {
            let again = acquire(&o, &work).unwrap();
            assert!(std::fs::read_to_string(again.path())
                .unwrap()
                .contains(&std::process::id().to_string()));
        }
    }

    #[test]
    fn other_options_into_the_same_folder_are_refused() {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("out");
        let work = out.join("_abysslight");
        std::fs::create_dir_all(&work).unwrap();
        let o = opts(&out);
        drop(acquire(&o, &work).unwrap());
        // Options that do not change the pixels are free to differ.
        let more_threads = Options {
            threads: Some(3),
            resume: true,
            limit: Some(2),
            ..o.clone()
        };
        drop(acquire(&more_threads, &work).unwrap());
        // The same window given another way is the same run.
        let same_window = Options {
            window: Some(crate::run::options::DEFAULT_WINDOW),
            ..o.clone()
        };
        drop(acquire(&same_window, &work).unwrap());
        for (other, key) in [
            (
                Options {
                    window: Some(9),
                    ..o.clone()
                },
                "window",
            ),
            (
                Options {
                    downsample: Some(4),
                    resume: true,
                    ..o.clone()
                },
                "downsample",
            ),
        ] {
            let e = acquire(&other, &work).unwrap_err().to_string();
            assert!(e.contains(key) && e.contains("other options"), "{e}");
            assert!(!work.join("lock").exists(), "a refused run leaves no lock");
        }
    }

    #[test]
    fn stale_temps_are_removed_and_nothing_else() {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("out");
        std::fs::create_dir_all(out.join("a/_abysslight")).unwrap();
        let stale = [
            out.join("a/.IMG_1.jpg.x1Y2z3.abysslight-tmp"),
            out.join("a/_abysslight/.report.json.q.abysslight-tmp"),
        ];
        let kept = [
            out.join("a/IMG_1.jpg"),
            out.join("a/abysslight-tmp.jpg"),
            out.join("a/.keep"),
        ];
        for p in stale.iter().chain(&kept) {
            std::fs::write(p, b"x").unwrap();
        }
        let mut removed = remove_stale_temps(&out);
        removed.sort();
        let mut want = stale.to_vec();
        want.sort();
        assert_eq!(removed, want);
        assert!(kept.iter().all(|p| p.exists()));
    }
}
