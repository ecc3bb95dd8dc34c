//! What a run does to its output folder before it writes: refuse a second run of the same photos at the same
//! time, refuse mixing two sets of method options in one output folder, and clear the temp files of killed runs.
//!
//! - **Lock**: `<out>/_abysslight/lock`, locked by the operating system (`flock`-style: released when the process
//!   ends, however it ends, whatever its pid namespace): exclusively by a plain run, shared by the shards of one
//!   job (each also holds `lock-shard-K-of-N` exclusively). A live holder refuses the run.
//! - **Options**: `<out>/_abysslight/options.json` holds the options that decide the output pixels (the
//!   [`fingerprint`]). A run whose fingerprint differs is refused, naming the options that differ: its photos
//!   would mix with the earlier run's (with `--resume` it would even keep them).
//! - **Stale temp files**: outputs are written to `.<name>.<random>.abysslight-tmp` and renamed into place; a
//!   killed run leaves them behind. [`remove_stale_temps`] deletes them below `--out` (not in another run's
//!   output folder nested in it), only when no other run is writing there.

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
        strict: false,
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
        // The window in effect, however it was given; `auto` (chosen per stretch by the survey) is not the fixed
        // window it starts from, and is said as the user gave it.
        let auto = opts.params().is_ok_and(|p| p.window_is_auto());
        let in_effect = match auto {
            true => serde_json::Value::from("auto"),
            false => w.n.into(),
        };
        m.insert("window-in-effect".into(), in_effect);
    }
    v
}

/// The names of the options of [`fingerprint`] whose values differ between `a` and `b`, in order (none: they
/// make the same photos).
pub fn differing_options(a: &Options, b: &Options) -> Vec<String> {
    let (a, b) = (fingerprint(a), fingerprint(b));
    let (Some(a), Some(b)) = (a.as_object(), b.as_object()) else {
        return vec!["all options".into()];
    };
    let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    keys.into_iter()
        .filter(|k| a.get(*k) != b.get(*k))
        .cloned()
        .collect()
}

/// The options whose values differ between two fingerprints (`a` the earlier run's), each as a user gave it: the
/// flag, with the earlier and this run's value (`--window 9 before, 5 now`).
fn differing(a: &serde_json::Value, b: &serde_json::Value) -> Vec<String> {
    let (Some(a), Some(b)) = (a.as_object(), b.as_object()) else {
        return vec!["all options".into()];
    };
    let mut keys: Vec<&String> = a
        .keys()
        .chain(b.keys())
        .filter(|k| a.get(*k) != b.get(*k))
        .collect();
    keys.sort();
    keys.dedup();
    // An option left out reads as the command line says it: auto, the input's, or none.
    let shown = |k: &str, v: Option<&serde_json::Value>| match v {
        None | Some(serde_json::Value::Null) => match k {
            "downsample" | "near-window" | "transfer" | "backscatter-scale" => "auto".to_string(),
            "jpeg-quality" | "jpeg-subsampling" => "the input's".to_string(),
            _ => "none".to_string(),
        },
        Some(serde_json::Value::String(s)) => s.clone(),
        Some(v) => v.to_string(),
    };
    keys.into_iter()
        .map(|k| {
            // The window in effect, however it was given (--window, --contamination or auto).
            let flag = match k.as_str() {
                "window-in-effect" => "--window".to_string(),
                // Recorded by the run: the file's content (edited, or another file of the same name).
                "navigation-sha256" => "the content (SHA-256) of --navigation".to_string(),
                "mask-sha256" => "the content (SHA-256) of --mask".to_string(),
                k => format!("--{k}"),
            };
            format!(
                "{flag} {} before, {} now",
                shown(k, a.get(k)),
                shown(k, b.get(k))
            )
        })
        .collect()
}

/// Whether `out` holds a file written by an earlier run (anything but `_abysslight` and temp files): a corrected
/// photo this run's could mix with.
fn holds_outputs(out: &Path) -> bool {
    walkdir::WalkDir::new(out)
        .follow_links(false)
        .into_iter()
        .filter_entry(|e| e.depth() != 1 || e.file_name() != crate::io::WORK_DIR)
        .flatten()
        .any(|e| !e.file_type().is_dir() && !e.file_name().to_string_lossy().ends_with(TEMP_SUFFIX))
}

/// The locks a run holds (see [`acquire`]); the operating system releases them when the process ends, however it
/// ends (killed, crashed, in another pid namespace). The lock files stay: removing one would let a later run lock
/// a new file while an older one still holds the removed one.
#[derive(Debug)]
pub struct RunLock {
    _held: Vec<std::fs::File>,
}

fn lock_name(opts: &Options) -> String {
    match opts.shard {
        Some(s) => format!("lock-shard-{}-of-{}", s.index, s.count),
        None => "lock".into(),
    }
}

/// Open (creating) a lock file in the run folder; never through a link (the run folder holds none: checked
/// before, see [`crate::io::gate::check_work_dir`]).
fn open_lock(path: &Path) -> Result<std::fs::File> {
    if std::fs::symlink_metadata(path).is_ok_and(|m| !m.is_file()) {
        return Err(Error::io(
            path,
            std::io::Error::other("a lock file that is not a regular file; remove it"),
        ));
    }
    std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)
        .map_err(|e| Error::io(path, e))
}

/// Take `file`'s lock (`shared` or exclusive) without waiting; a lock held by a live run is a usage error naming
/// the folder and the run's pid as it recorded it.
fn try_take(file: &std::fs::File, path: &Path, shared: bool, out: &Path) -> Result<()> {
    let got = if shared {
        file.try_lock_shared()
    } else {
        file.try_lock()
    };
    match got {
        Ok(()) => Ok(()),
        Err(std::fs::TryLockError::WouldBlock) => {
            let who = crate::io::whole::read_text(path, RECORD_MAX_BYTES, "lock")
                .ok()
                .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
                .and_then(|v| v.get("pid").and_then(|p| p.as_u64()))
                .map_or_else(String::new, |p| format!(" (pid {p} in its own namespace)"));
            Err(Error::Usage(format!(
                "{}: another abysslight run{who} is writing into {} right now (plain runs and shards of one job do \
                 not mix); wait for it to end. The lock is the operating system's: it is released when that run \
                 ends, however it ends",
                path.display(),
                out.display()
            )))
        }
        Err(std::fs::TryLockError::Error(e)) => Err(Error::io(path, e)),
    }
}

/// Record who holds `file` (for the message another run prints); information only, the lock is the OS's.
fn record_holder(file: &std::fs::File, body: &serde_json::Value) {
    use std::io::{Seek, Write};
    let mut f = file;
    let _ = f.set_len(0);
    let _ = f.seek(std::io::SeekFrom::Start(0));
    let _ = f.write_all(body.to_string().as_bytes());
}

/// Take the locks of this run in `work_dir` (`<out>/_abysslight`, which must exist) and check the options
/// against those of earlier runs into the same folder (recorded on the first run). Locks (`flock`-style, held by
/// the operating system): `lock` exclusively for a plain run; `lock` shared and `lock-shard-K-of-N` exclusively
/// for a shard, so the shards of one job run side by side and nothing else runs with them. Errors are usage
/// errors (exit 2) that say what to do.
pub fn acquire(opts: &Options, work_dir: &Path) -> Result<RunLock> {
    let out = work_dir.parent().unwrap_or(work_dir);
    let fp = fingerprint(opts);
    let body = serde_json::json!({ "pid": std::process::id(), "options": fp });
    let main_path = work_dir.join("lock");
    let main = open_lock(&main_path)?;
    try_take(&main, &main_path, opts.shard.is_some(), out)?;
    let mut held = vec![main];
    let path = work_dir.join(lock_name(opts));
    if opts.shard.is_some() {
        let own = open_lock(&path)?;
        try_take(&own, &path, false, out)?;
        held.push(own);
    }
    // A plain run holds the folder alone; shards start together and check and record the options under a short
    // exclusive lock of their own.
    let options_lock = match opts.shard {
        Some(_) => {
            let p = work_dir.join("options.lock");
            let f = open_lock(&p)?;
            f.lock().map_err(|e| Error::io(&p, e))?;
            Some(f)
        }
        None => None,
    };
    check_options(opts, work_dir, &fp)?;
    drop(options_lock);
    record_holder(held.last().unwrap_or(&held[0]), &body);
    Ok(RunLock { _held: held })
}

/// The most of a run's own small files (its record of options, its lock) that is read.
const RECORD_MAX_BYTES: u64 = 1 << 20;

/// Compare the options with those recorded in `work_dir/options.json` (or record them).
fn check_options(opts: &Options, work_dir: &Path, fp: &serde_json::Value) -> Result<()> {
    let recorded = work_dir.join("options.json");
    // Read bounded, as every file read whole (io::whole): a record of options is a few KiB.
    let read = match std::fs::metadata(&recorded) {
        Ok(_) => Ok(crate::io::whole::read_text(
            &recorded,
            RECORD_MAX_BYTES,
            "record of an earlier run's options",
        )?),
        Err(e) => Err(e),
    };
    match read {
        Ok(text) => {
            let old: serde_json::Value =
                serde_json::from_str(&text).map_err(|e| Error::Config {
                    path: recorded.clone(),
                    reason: format!("unreadable record of an earlier run's options: {e}"),
                })?;
            let diff = differing(&old, fp);
            if diff.is_empty() {
                return Ok(());
            }
            let out = work_dir.parent().unwrap_or(work_dir);
            // A plain run holds the folder alone: where the earlier run wrote no photo (it stopped at a bad
            // option or folder), nothing would mix, and this run's options replace the record.
            if opts.shard.is_none() && !holds_outputs(out) {
                return record(&recorded, fp);
            }
            Err(Error::Usage(format!(
                "{} holds photos of a run with other options ({}; recorded in {}): its photos would mix with \
                 this run's{}. Use the same options, or another --out",
                out.display(),
                diff.join("; "),
                recorded.display(),
                if opts.resume {
                    " (--resume keeps the photos already there)"
                } else {
                    ""
                }
            )))
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => record(&recorded, fp),
        Err(e) => Err(Error::io(&recorded, e)),
    }
}

/// Write the fingerprint `fp` to `recorded` (atomically).
fn record(recorded: &Path, fp: &serde_json::Value) -> Result<()> {
    let text = serde_json::to_string_pretty(fp).unwrap_or_default();
    crate::io::write_with(recorded, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes())
            .map_err(|e| Error::io(recorded, e))
    })
}

/// Delete abysslight temp files (`.<name>.<random>.abysslight-tmp`) below `out`, not following links and not
/// descending into another run's output folder (a folder below `out` with its own `_abysslight`); returns what was
/// removed. Call it only while no other run writes into `out` ([`start`] makes sure).
pub fn remove_stale_temps(out: &Path) -> Vec<PathBuf> {
    let mut removed = Vec::new();
    let walk = walkdir::WalkDir::new(out)
        .follow_links(false)
        .into_iter()
        .filter_entry(|e| {
            e.depth() == 0
                || !e.file_type().is_dir()
                || !e.path().join(crate::io::WORK_DIR).is_dir()
        });
    for e in walk.flatten() {
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
/// removed. Every run holds `<work_dir>/active` shared while it writes; the sweep runs only when that lock can be
/// taken exclusively (no other run of this folder is writing), before this run's own shared hold.
pub fn start(opts: &Options, out: &Path, work_dir: &Path) -> Result<(RunLock, Vec<PathBuf>)> {
    let mut lock = acquire(opts, work_dir)?;
    let active_path = work_dir.join("active");
    let active = open_lock(&active_path)?;
    let removed = if active.try_lock().is_ok() {
        let removed = remove_stale_temps(out);
        active.unlock().map_err(|e| Error::io(&active_path, e))?;
        removed
    } else {
        Vec::new()
    };
    active
        .lock_shared()
        .map_err(|e| Error::io(&active_path, e))?;
    lock._held.push(active);
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
        // A shard does not run beside a plain run, nor a plain run beside a shard.
        let shard = |k: &str| Options {
            shard: Some(k.parse().unwrap()),
            ..o.clone()
        };
        assert!(acquire(&shard("2/3"), &work).is_err());
        drop(first);
        let s2 = acquire(&shard("2/3"), &work).unwrap();
        let s3 = acquire(&shard("3/3"), &work).unwrap();
        assert!(
            acquire(&shard("2/3"), &work).is_err(),
            "one copy of a shard"
        );
        assert!(acquire(&o, &work).is_err());
        drop((s2, s3));
        // Whatever a lock file says (a killed run's pid 1 from a container), only a held lock refuses.
        std::fs::write(work.join("lock"), r#"{"pid": 1, "options": {}}"#).unwrap();
        let _again = acquire(&o, &work).unwrap();
        assert!(std::fs::read_to_string(work.join("lock"))
            .unwrap()
            .contains(&std::process::id().to_string()));
    }

    #[test]
    fn other_options_into_the_same_folder_are_refused() {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("out");
        let work = out.join("_abysslight");
        std::fs::create_dir_all(&work).unwrap();
        let o = opts(&out);
        drop(acquire(&o, &work).unwrap());
        // The first run wrote a photo.
        std::fs::write(out.join("IMG_1.png"), b"x").unwrap();
        // Options that do not change the pixels are free to differ.
        let more_threads = Options {
            threads: Some(3),
            resume: true,
            limit: Some(2),
            ..o.clone()
        };
        drop(acquire(&more_threads, &work).unwrap());
        // The fixed window 7 is not `auto`, which chooses each stretch's window from the survey of the photos
        // (it once read "--window 7 before" for a run that used auto).
        let seven = Options {
            window: Some(crate::method::params::BASE_WINDOW),
            ..o.clone()
        };
        let e = acquire(&seven, &work).unwrap_err().to_string();
        assert!(e.contains("--window auto before, 7 now"), "{e}");
        // The same window given another way is the same run.
        let paper = |window| Options {
            method: crate::Method::Paper,
            window,
            ..o.clone()
        };
        assert_eq!(
            fingerprint(&paper(None)),
            fingerprint(&paper(Some(crate::method::params::BASE_WINDOW)))
        );
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
            drop(acquire(&o, &work).expect("a refused run leaves no lock held"));
        }
        // Named as flags, with both values.
        let e = acquire(
            &Options {
                window: Some(9),
                ..o.clone()
            },
            &work,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("--window auto before, 9 now"), "{e}");
        assert!(!e.contains("window-in-effect"), "{e}");
    }

    /// A run that wrote no photo (it stopped at a bad folder) leaves nothing that blocks the next: a plain run
    /// with other options replaces its record. A shard, which runs beside others, still may not.
    #[test]
    fn a_run_that_wrote_no_photo_does_not_block_the_next() {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("out");
        let work = out.join("_abysslight");
        std::fs::create_dir_all(&work).unwrap();
        let o = opts(&out);
        drop(acquire(&o, &work).unwrap());
        // Its own files and a temp file of a killed write are not photos.
        std::fs::write(work.join("report.json"), b"{}").unwrap();
        std::fs::write(out.join(".IMG_1.png.a1.abysslight-tmp"), b"x").unwrap();
        let other = Options {
            window: Some(9),
            ..o.clone()
        };
        let shard = Options {
            shard: Some("1/2".parse().unwrap()),
            ..other.clone()
        };
        assert!(acquire(&shard, &work).is_err(), "a shard is refused");
        drop(acquire(&other, &work).expect("nothing written, nothing to mix"));
        let recorded = std::fs::read_to_string(work.join("options.json")).unwrap();
        assert!(recorded.contains("\"window-in-effect\": 9"), "{recorded}");
        // Once a photo is there, other options are refused again.
        std::fs::create_dir_all(out.join("leg1")).unwrap();
        std::fs::write(out.join("leg1/IMG_2.png"), b"x").unwrap();
        assert!(acquire(&o, &work).is_err());
    }

    #[test]
    fn stale_temps_are_removed_and_nothing_else() {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("out");
        std::fs::create_dir_all(out.join("_abysslight")).unwrap();
        std::fs::create_dir_all(out.join("a")).unwrap();
        // Another run's output folder nested in this one: its temp files are its own.
        std::fs::create_dir_all(out.join("a/quick/_abysslight")).unwrap();
        let stale = [
            out.join("a/.IMG_1.jpg.x1Y2z3.abysslight-tmp"),
            out.join("_abysslight/.report.json.q.abysslight-tmp"),
        ];
        let kept = [
            out.join("a/IMG_1.jpg"),
            out.join("a/abysslight-tmp.jpg"),
            out.join("a/.keep"),
            out.join("a/quick/.IMG_2.jpg.r4S5t6.abysslight-tmp"),
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
