//! `abysslight merge-shards OUT`: the mission's report and pictures from the runs of `--shard 1/N` … `N/N` into
//! one `--out`, as one run over the whole survey would have written them.
//!
//! Each shard leaves `_abysslight/report-shard-K-of-N.json` and its lock file `lock-shard-K-of-N`. The merge
//! checks that every shard `1..=N` finished (a report newer than its lock file, which no live run holds), that they ran with the same options (those
//! that decide the output pixels: [`fingerprint`]), the same version and the same survey; then it writes
//! `_abysslight/report.json` with every photo counted once (the shards' frames, in mission order), the errors and
//! warnings of every shard (those every shard saw, such as a bad water-column frame, once), the counts summed,
//! and `overview.png` and `flagged.png`. The shards' reports are read as [`Report`]s and merged field by field.
//!
//! The flagged sheet needs each flagged photo's `F·C`, which lives only in memory during a run: a shard writes
//! the ones it kept for its own sheet to `_abysslight/flagged-lit-shard-K-of-N/<index>.f32` ([`save_flagged`]).
//! The merge picks the photos one run would have picked (from the flagged photos of the whole mission) when the
//! shards kept them, which they always do when the mission has at most 24 flagged photos; otherwise the sheet
//! shows flagged photos spread over the mission from those the shards kept.

use std::collections::{BTreeMap, BTreeSet, HashSet};
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::io::WORK_DIR;
use crate::method::monitor::{Summary, Thresholds};
use crate::method::raster::Raster;
use crate::report::{FileError, FrameReport, Report};
use crate::run::guard::differing_options;
use crate::run::options::Shard;

/// The most of a shard's report.json that is read (about 4 KiB a photo: a million photos in one shard).
const REPORT_MAX_BYTES: u64 = 4 << 30;

/// What [`merge_shards`] wrote.
#[derive(Debug, Clone)]
pub struct Merged {
    /// Number of shards merged (`N`).
    pub shards: usize,
    /// Survey photos of the mission.
    pub survey_photos: usize,
    /// Photos in the merged report's frames (corrected, or found corrected by `--resume`).
    pub frames: usize,
    /// Photos corrected by the shards.
    pub corrected: usize,
    /// Failed survey photos, and failed water-column frames.
    pub failed: usize,
    /// Water-column frames that failed.
    pub water_column_failed: usize,
    /// Photos flagged.
    pub flagged: usize,
    /// `OUT/_abysslight/report.json`.
    pub report_path: PathBuf,
}

impl Merged {
    /// True when no photo or water-column frame failed.
    pub fn all_ok(&self) -> bool {
        self.failed == 0 && self.water_column_failed == 0
    }
}

/// One shard's report, read.
/// One shard's report, read.
struct ShardReport {
    shard: Shard,
    path: PathBuf,
    report: Report,
}

/// Merge the shard reports under `out` (the shards' `--out`) into `out/_abysslight/report.json`, `overview.png`
/// and `flagged.png`. Errors name the shards that are missing, unfinished or ran differently.
pub fn merge_shards(out: &Path) -> Result<Merged> {
    let work = out.join(WORK_DIR);
    if !work.is_dir() {
        return Err(Error::Usage(format!(
            "{}: no {WORK_DIR} folder: not the --out of abysslight correct --shard runs",
            out.display()
        )));
    }
    let shards = read_shards(&work)?;
    check_same(&shards)?;
    check_complete(&shards, out)?;
    let report = merged_report(&shards, &work)?;
    let report_path = work.join("report.json");
    crate::io::write_with(&report_path, |w| {
        serde_json::to_writer_pretty(w, &report).map_err(|e| Error::Encode {
            path: report_path.clone(),
            reason: e.to_string(),
        })
    })?;
    save_pictures(&work, &report.frames, &shards)?;
    Ok(Merged {
        shards: shards.len(),
        survey_photos: report.survey_photos,
        frames: report.frames.len(),
        corrected: report.corrected,
        failed: report.failed,
        water_column_failed: report.water_column_failed,
        flagged: report.monitor.flagged,
        report_path,
    })
}

/// `name` as `<prefix>K-of-N<suffix>`.
fn parse_shard_name(name: &str, prefix: &str, suffix: &str) -> Option<Shard> {
    let (k, n) = name
        .strip_prefix(prefix)?
        .strip_suffix(suffix)?
        .split_once("-of-")?;
    format!("{k}/{n}").parse().ok()
}

/// Every shard's report in `work`, checked complete: one shard count, every shard `1..=N` with a report and
/// without a lock. All problems are named in one error.
fn read_shards(work: &Path) -> Result<Vec<ShardReport>> {
    let mut reports = BTreeMap::new();
    let mut locks = BTreeMap::new();
    let rd = std::fs::read_dir(work).map_err(|e| Error::io(work, e))?;
    for e in rd.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if let Some(s) = parse_shard_name(&name, "report-shard-", ".json") {
            reports.insert((s.count, s.index), e.path());
        } else if let Some(s) = parse_shard_name(&name, "lock-shard-", "") {
            locks.insert((s.count, s.index), e.path());
        }
    }
    let counts: BTreeSet<usize> = reports.keys().chain(locks.keys()).map(|k| k.0).collect();
    let n = match counts.len() {
        0 => {
            return Err(Error::Usage(format!(
                "{}: no shard reports (report-shard-K-of-N.json): run abysslight correct ... --shard K/N \
                 into this --out first",
                work.display()
            )))
        }
        1 => counts.into_iter().next().unwrap_or(1),
        _ => {
            let list: Vec<String> = counts.iter().map(|n| format!("of-{n}")).collect();
            return Err(Error::Usage(format!(
                "{}: shards of different counts N ({}): remove the reports and locks of the runs that do not \
                 belong to this mission",
                work.display(),
                list.join(", ")
            )));
        }
    };
    let problems: Vec<String> = (1..=n)
        .filter_map(|k| shard_problem(k, n, reports.get(&(n, k)), locks.get(&(n, k))))
        .collect();
    if !problems.is_empty() {
        return Err(Error::Usage(format!(
            "cannot merge {} shards in {}:\n  {}",
            n,
            work.display(),
            problems.join("\n  ")
        )));
    }
    reports
        .into_iter()
        .map(|((count, index), path)| {
            let text = crate::io::whole::read_text(&path, REPORT_MAX_BYTES, "shard report")?;
            let report: Report = serde_json::from_str(&text).map_err(|e| Error::Config {
                path: path.clone(),
                reason: format!("unreadable shard report: {e}"),
            })?;
            Ok(ShardReport {
                shard: Shard { index, count },
                path,
                report,
            })
        })
        .collect()
}

/// Who holds a lock file, as [`crate::run::guard`] records it (its options are left unread).
#[derive(serde::Deserialize)]
struct Holder {
    pid: u64,
}

/// Why shard `k` of `n` cannot be merged, if it cannot.
fn shard_problem(
    k: usize,
    n: usize,
    report: Option<&PathBuf>,
    lock: Option<&PathBuf>,
) -> Option<String> {
    let rerun = format!("rerun it (abysslight correct <the same arguments> --shard {k}/{n}, or resubmit array task {k})");
    if let Some(lock) = lock.filter(|l| unfinished(l, report)) {
        let pid = crate::io::whole::read_text(lock, 1 << 20, "lock")
            .ok()
            .and_then(|t| serde_json::from_str::<Holder>(&t).ok())
            .map_or(String::new(), |h| format!(" by pid {}", h.pid));
        return Some(format!(
            "shard {k}/{n} has not finished: its lock {} is still there (taken{pid} on the machine that ran it): \
             wait for it, or, if that task was killed or timed out, {rerun}",
            lock.display()
        ));
    }
    report
        .is_none()
        .then(|| format!("shard {k}/{n} is missing: no report-shard-{k}-of-{n}.json; {rerun}"))
}

/// A shard whose lock file is held by a live run (the lock is the operating system's: [`crate::run::guard`]), or
/// was taken after its report was written (a rerun that was killed over the report of an earlier one), or that
/// has no report, has not finished. The lock file itself stays after a run.
fn unfinished(lock: &Path, report: Option<&PathBuf>) -> bool {
    let held = std::fs::File::open(lock)
        .is_ok_and(|f| matches!(f.try_lock_shared(), Err(std::fs::TryLockError::WouldBlock)));
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    held || match report {
        Some(r) => modified(lock) > modified(r),
        None => true,
    }
}

/// The shards ran with the same options, version and survey; the first difference is an error naming the shards.
fn check_same(shards: &[ShardReport]) -> Result<()> {
    let Some(first) = shards.first() else {
        return Ok(());
    };
    for s in &shards[1..] {
        let diff = differing_options(&first.report.options, &s.report.options);
        if !diff.is_empty() {
            return Err(Error::Usage(format!(
                "shard {} ran with other options than shard {} ({} differ: {} against {}): rerun it with the \
                 options of the others",
                s.shard,
                first.shard,
                diff.join(", "),
                s.path.display(),
                first.path.display()
            )));
        }
        let (a, b) = (&s.report, &first.report);
        for (key, what, differs, values) in [
            (
                "version",
                "another version of abysslight",
                a.version != b.version,
                format!("{:?} against {:?}", a.version, b.version),
            ),
            (
                "survey_photos",
                "another count of survey photos (the survey folder changed between the runs)",
                a.survey_photos != b.survey_photos,
                format!("{} against {}", a.survey_photos, b.survey_photos),
            ),
        ] {
            if differs {
                return Err(Error::Usage(format!(
                    "shard {} ran with {what} than shard {}: {key} {values} ({}); rerun it",
                    s.shard,
                    first.shard,
                    s.path.display()
                )));
            }
        }
    }
    Ok(())
}

/// Up to five names of `paths`, for a message.
fn some_names(paths: &[String]) -> String {
    let mut list = paths[..paths.len().min(5)].join(", ");
    if paths.len() > 5 {
        list.push_str(&format!(", ... ({} more)", paths.len() - 5));
    }
    list
}

/// `" (it ran with --limit N)"` for a shard run with `--limit`, else nothing.
fn limit_note(s: &ShardReport) -> String {
    s.report
        .options
        .limit
        .map_or(String::new(), |l| format!(" (it ran with --limit {l})"))
}

/// The survey's photos as the shards' run listed them (the folder its options name, read again on this machine), when
/// that list still has the mission's `total` photos; `None` where it cannot be read here.
fn survey_list(first: &ShardReport, total: usize, out: &Path) -> Option<Vec<PathBuf>> {
    (first.report.options.survey.as_deref())
        .and_then(|s| crate::io::find_photos_excluding(s, &[out]).ok())
        .map(|f| f.photos.into_iter().map(|e| e.path).collect::<Vec<_>>())
        .filter(|v| v.len() == total)
}

/// Every photo of the survey is accounted for by the shard it belongs to: in its frames (corrected, or found
/// corrected by `--resume`) or in its errors (failed); and each shard's counts agree with its lists. The photos
/// of a shard are those [`Shard::range`] gives in the survey as listed now (when the survey can be listed from here
/// and still holds as many photos as the shards found), else only their number is compared. A photo accounted
/// for by no shard (a shard run with `--limit`, a report that lost entries or whose counts were edited) is an
/// error naming the photos and the shard.
fn check_complete(shards: &[ShardReport], out: &Path) -> Result<()> {
    let Some(first) = shards.first() else {
        return Ok(());
    };
    let total = first.report.survey_photos;
    let survey = survey_list(first, total, out);
    let mut problems = Vec::new();
    for s in shards {
        let r = &s.report;
        let rerun = format!("rerun it (--shard {})", s.shard);
        let limit = limit_note(s);
        let resumed = r.frames.iter().filter(|f| f.resumed).count();
        let photo_errors = r.errors.len().saturating_sub(r.water_column_failed);
        if r.corrected != r.frames.len() - resumed || r.failed != photo_errors {
            problems.push(format!(
                "shard {}: its counts ({} corrected, {} failed) disagree with its lists ({} photos corrected, {} \
                 failed) in {}: the report was edited or damaged; {rerun}",
                s.shard,
                r.corrected,
                r.failed,
                r.frames.len() - resumed,
                photo_errors,
                s.path.display()
            ));
            continue;
        }
        let range = s.shard.range(total);
        match &survey {
            Some(list) => {
                let seen: HashSet<&Path> = (r.frames.iter().map(|f| f.input.as_path()))
                    .chain(r.errors.iter().map(|e| e.path.as_path()))
                    .collect();
                let missing: Vec<String> = list[range.clone()]
                    .iter()
                    .filter(|p| !seen.contains(p.as_path()))
                    .map(|p| p.to_string_lossy().into_owned())
                    .collect();
                if !missing.is_empty() {
                    problems.push(format!(
                        "shard {}: {} of its {} photos are neither corrected nor failed in {}{limit}: {}; {rerun}",
                        s.shard,
                        missing.len(),
                        range.len(),
                        s.path.display(),
                        some_names(&missing)
                    ));
                }
            }
            None => {
                let accounted = r.frames.len() + photo_errors;
                if accounted < range.len() {
                    problems.push(format!(
                        "shard {}: {} of its {} photos are neither corrected nor failed in {}{limit}; {rerun}",
                        s.shard,
                        range.len() - accounted,
                        range.len(),
                        s.path.display()
                    ));
                }
            }
        }
    }
    if problems.is_empty() {
        return Ok(());
    }
    Err(Error::Usage(format!(
        "cannot merge: photos of the survey are missing from the shards' reports (a mission is merged only when \
         every photo is corrected or failed):\n  {}",
        problems.join("\n  ")
    )))
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// The entries of every shard's list `of`, in shard order, once each (a file every shard saw, such as a bad
/// water-column frame, is reported by each).
fn union<T: Clone + Eq + std::hash::Hash>(
    shards: &[ShardReport],
    of: impl Fn(&Report) -> &Vec<T>,
) -> Vec<T> {
    let mut seen = HashSet::new();
    (shards.iter().flat_map(|s| of(&s.report)))
        .filter(|v| seen.insert(*v))
        .cloned()
        .collect()
}

/// The merged report: shard 1's, with every list and count over all shards, and the summaries of the run
/// ([`Summary::of`], [`WindowSummary::count`](crate::report::WindowSummary::count)) over the mission's frames.
fn merged_report(shards: &[ShardReport], work: &Path) -> Result<Report> {
    let mut frames = Vec::new();
    let mut inputs = HashSet::new();
    for s in shards {
        for f in &s.report.frames {
            if !inputs.insert(&f.input) {
                return Err(Error::Usage(format!(
                    "{:?} is in the report of shard {} and of an earlier shard ({}): the shards overlap",
                    f.input,
                    s.shard,
                    s.path.display()
                )));
            }
            frames.push(mission_numbered(f, frames.len(), s)?);
        }
    }
    let sum = |of: fn(&Report) -> u64| -> u64 { shards.iter().map(|s| of(&s.report)).sum() };
    let most = |of: fn(&Report) -> usize| -> usize {
        shards.iter().map(|s| of(&s.report)).max().unwrap_or(0)
    };
    let errors: Vec<FileError> = union(shards, |r| &r.errors);
    let water_column_failed = most(|r| r.water_column_failed);
    let mut r = shards[0].report.clone();
    r.options.shard = None;
    r.corrected = sum(|r| r.corrected as u64) as usize;
    r.skipped_existing = sum(|r| r.skipped_existing as u64) as usize;
    r.floored_pixels = sum(|r| r.floored_pixels);
    r.clipped_samples = sum(|r| r.clipped_samples);
    r.peak_photos_in_memory = most(|r| r.peak_photos_in_memory);
    r.water_column_failed = water_column_failed;
    r.failed = errors.len().saturating_sub(water_column_failed);
    r.layout = shards.iter().find_map(|s| s.report.layout).or(r.layout);
    r.monitor = Summary::of(frames.iter().map(|f| &f.health));
    r.window.count(&frames, r.options.navigation.is_some());
    r.frames = frames;
    r.errors = errors;
    r.warnings = union(shards, |r| &r.warnings);
    r.elapsed_s = shards.iter().map(|s| s.report.elapsed_s).sum();
    r.report_path = Some(work.join("report.json"));
    Ok(r)
}

/// A shard's frame with its `index` (and window) counted from the mission's first photo, the frame being the
/// `position`-th of the mission: a shard counts from the first photo it read.
fn mission_numbered(f: &FrameReport, position: usize, s: &ShardReport) -> Result<FrameReport> {
    let window = f.window.renumbered(f.index, position).ok_or_else(|| Error::Config {
        path: s.path.clone(),
        reason: format!(
            "the window of photo {} ({:?}) starts before the first photo its shard read: the report was edited \
             or damaged",
            f.index,
            f.window.photos()
        ),
    })?;
    Ok(FrameReport {
        index: position,
        window,
        ..f.clone()
    })
}

/// Folder of a shard's kept `F·C` images of flagged photos.
fn flagged_dir(work: &Path, shard: Shard) -> PathBuf {
    work.join(format!(
        "flagged-lit-shard-{}-of-{}",
        shard.index, shard.count
    ))
}

/// Save the `F·C` images a shard kept for its flagged sheet (exactly, as `f32`), for [`merge_shards`]; the
/// folder of an earlier run of the shard is replaced.
pub fn save_flagged(work: &Path, shard: Shard, kept: &[(usize, Raster)]) -> Result<()> {
    let dir = flagged_dir(work, shard);
    if dir.exists() {
        std::fs::remove_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    }
    for (index, lit) in kept {
        let path = dir.join(format!("{index}.f32"));
        crate::io::write_with(&path, |w| {
            use std::io::Write;
            let mut bytes = Vec::with_capacity(16 + 4 * lit.data.len());
            bytes.extend_from_slice(b"ABLF");
            for d in [lit.width, lit.height, lit.channels] {
                bytes.extend_from_slice(&(d as u32).to_le_bytes());
            }
            for v in &lit.data {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
            w.write_all(&bytes).map_err(|e| Error::io(&path, e))
        })?;
    }
    Ok(())
}

/// Read one `F·C` image written by [`save_flagged`].
fn load_flagged(path: &Path) -> Result<Raster> {
    // Header, then at most the largest photo's block image as f32 RGB.
    let bytes = crate::io::whole::read_whole(path, 16 + 12 * crate::io::MAX_PIXELS, "F·C image")?;
    let bad = || Error::Decode {
        path: path.to_owned(),
        reason: "not an F·C image written by abysslight correct --shard".into(),
    };
    if bytes.len() < 16 || &bytes[..4] != b"ABLF" {
        return Err(bad());
    }
    let word = |i: usize| {
        u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]) as usize
    };
    let (width, height, channels) = (word(4), word(8), word(12));
    let n = width
        .checked_mul(height)
        .and_then(|p| p.checked_mul(channels))
        .ok_or_else(bad)?;
    if bytes.len() != 16 + 4 * n {
        return Err(bad());
    }
    let data = (0..n)
        .map(|i| {
            f32::from_le_bytes([
                bytes[16 + 4 * i],
                bytes[17 + 4 * i],
                bytes[18 + 4 * i],
                bytes[19 + 4 * i],
            ])
        })
        .collect();
    Ok(Raster {
        width,
        height,
        channels,
        data,
    })
}

/// The `F·C` images every shard kept, by the photo's index in the mission (a shard names them by its own).
fn kept_lit(work: &Path, shards: &[ShardReport]) -> Result<BTreeMap<usize, Raster>> {
    let mut all = BTreeMap::new();
    let mut offset = 0;
    for s in shards {
        let frames = &s.report.frames;
        let position: BTreeMap<usize, usize> = (frames.iter().enumerate())
            .map(|(j, f)| (f.index, offset + j))
            .collect();
        offset += frames.len();
        let Ok(rd) = std::fs::read_dir(flagged_dir(work, s.shard)) else {
            continue;
        };
        for e in rd.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let local = name
                .strip_suffix(".f32")
                .and_then(|i| i.parse::<usize>().ok());
            if let Some(&p) = local.and_then(|i| position.get(&i)) {
                all.insert(p, load_flagged(&e.path())?);
            }
        }
    }
    Ok(all)
}

/// `overview.png` and `flagged.png` of the merged mission, as one run draws them.
fn save_pictures(work: &Path, frames: &[FrameReport], shards: &[ShardReport]) -> Result<()> {
    if frames.is_empty() {
        return Ok(());
    }
    let overview = crate::run::pictures::overview(frames, &Thresholds::default());
    crate::run::pictures::save_png(&overview, &work.join("overview.png"))?;
    let lit = kept_lit(work, shards)?;
    let flagged: Vec<usize> = frames
        .iter()
        .filter(|f| !f.health.flags.is_empty())
        .map(|f| f.index)
        .collect();
    // The photos one run keeps (crate::run::threads), if the shards kept them all; else those the shards kept.
    let one_run = crate::run::threads::flagged_sample(&flagged);
    let pool: Vec<usize> = if one_run.iter().all(|i| lit.contains_key(i)) {
        one_run
    } else {
        crate::run::threads::flagged_sample(&lit.keys().copied().collect::<Vec<_>>())
    };
    let rows: Vec<(FrameReport, String, &Raster)> =
        crate::run::prepare::spread_indices(pool.len(), 6)
            .into_iter()
            .filter_map(|j| {
                let index = pool[j];
                let frame = frames.iter().find(|f| f.index == index)?.clone();
                let reason = frame
                    .health
                    .flags
                    .first()
                    .map_or(String::new(), |f| f.message.clone());
                Some((frame, reason, lit.get(&index)?))
            })
            .collect();
    let sheet_path = work.join("flagged.png");
    match crate::run::pictures::flagged_sheet_with(&rows, 320) {
        Some(sheet) => crate::run::pictures::save_png(&sheet, &sheet_path),
        None => match std::fs::remove_file(&sheet_path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(Error::io(&sheet_path, e)),
            _ => Ok(()),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_file_names() {
        let s = parse_shard_name("report-shard-3-of-16.json", "report-shard-", ".json").unwrap();
        assert_eq!((s.index, s.count), (3, 16));
        let l = parse_shard_name("lock-shard-16-of-16", "lock-shard-", "").unwrap();
        assert_eq!((l.index, l.count), (16, 16));
        for bad in [
            "report-shard-0-of-4.json",
            "report-shard-5-of-4.json",
            "report-shard-1-4.json",
            "report.json",
        ] {
            assert!(
                parse_shard_name(bad, "report-shard-", ".json").is_none(),
                "{bad}"
            );
        }
        assert!(parse_shard_name(
            "report-shard-1-of-4.json.abysslight-tmp",
            "report-shard-",
            ".json"
        )
        .is_none());
    }

    #[test]
    fn flagged_images_round_trip_exactly() {
        let d = tempfile::tempdir().unwrap();
        let shard = Shard { index: 2, count: 5 };
        let a = Raster::from_fn(5, 3, 3, |x, y, c| (x * 7 + y * 3 + c) as f32 / 11.0 + 1e-7);
        let b = Raster::from_fn(2, 2, 1, |x, _, _| if x == 0 { f32::NAN } else { -0.0 });
        save_flagged(d.path(), shard, &[(4, a.clone()), (9, b.clone())]).unwrap();
        let dir = flagged_dir(d.path(), shard);
        assert_eq!(load_flagged(&dir.join("4.f32")).unwrap(), a);
        let got = load_flagged(&dir.join("9.f32")).unwrap();
        assert!(got.data[0].is_nan() && got.data[1].to_bits() == (-0.0f32).to_bits());
        // A rerun of the shard replaces what the earlier run kept.
        save_flagged(d.path(), shard, &[(5, b)]).unwrap();
        assert!(!dir.join("4.f32").exists() && dir.join("5.f32").exists());
        // A truncated file is an error naming it.
        std::fs::write(
            dir.join("6.f32"),
            &std::fs::read(dir.join("5.f32")).unwrap()[..20],
        )
        .unwrap();
        let e = load_flagged(&dir.join("6.f32")).unwrap_err().to_string();
        assert!(e.contains("6.f32"), "{e}");
    }

    #[test]
    fn the_one_run_sample_is_spread_over_the_flagged_photos() {
        // Up to 24 flagged photos are all kept; beyond, every second one, then every fourth, ...
        let few: Vec<usize> = (0..24).map(|i| 3 * i).collect();
        assert_eq!(crate::run::threads::flagged_sample(&few), few);
        let many: Vec<usize> = (0..100).collect();
        let kept = crate::run::threads::flagged_sample(&many);
        assert!(kept.len() <= 24 && kept.len() >= 12, "{kept:?}");
        let step = kept[1] - kept[0];
        assert!(
            step.is_power_of_two() && kept.windows(2).all(|w| w[1] - w[0] == step),
            "{kept:?}"
        );
        assert_eq!(kept[0], 0);
    }
}
