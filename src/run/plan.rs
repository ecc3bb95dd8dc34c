//! What a run will read and write, decided before anything is written: the options checked, the survey photos
//! listed, the shard's chunk and halo, and which outputs `--resume` finds complete.

use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::io::navigation::Navigation;
use crate::io::paths::check_no_links_below;
use crate::io::{
    self, decode_expecting, find_photos, find_photos_excluding, majority_size, Entry, Found,
    WORK_DIR,
};
use crate::method::baseline::Method;
use crate::method::params::{BlockRule, Facts, Params};
use crate::method::transfer::Transfer;
use crate::method::window::WindowChoice;
use crate::report::Progress;
use crate::run::options::Options;
use crate::run::source::{Item, Role};

pub(crate) mod checks;

/// A run's inputs and outputs, decided up front.
#[derive(Debug)]
pub struct Plan {
    /// `--survey` (`-`: frames on stdin).
    pub survey: PathBuf,
    /// `--out` (`-`: frames on stdout).
    pub out: PathBuf,
    /// Frames come from stdin.
    pub stdin: bool,
    /// Frames go to stdout.
    pub stdout: bool,
    /// No list of photos up front (stdin or `--watch`).
    pub streaming: bool,
    /// The window `n` and its breakdown probability (of photos the survey does not choose for).
    pub window: WindowChoice,
    /// Each photo's window chosen per stretch by the survey (`--window auto`).
    pub auto_window: bool,
    /// The survey photos found (empty when streaming).
    pub found: Found,
    /// The mission's photo size (width, height): the most common among the headers of the first photos, so that
    /// one odd file (a thumbnail sorting first) is the only one skipped. `None` when streaming.
    pub photo_size: Option<(usize, usize)>,
    /// The photos to read, in order, with what to do with each.
    pub items: Vec<Item>,
    /// The photos (indices into `found.photos`) this run writes.
    pub chunk: Range<usize>,
    /// The first photo read (before `chunk.start` for a shard's halo).
    pub first: usize,
    /// Photos whose output `--resume` found complete.
    pub skipped_existing: usize,
    /// `<out>/_abysslight` (`None` with `--out -`).
    pub work_dir: Option<PathBuf>,
    /// What the user should know before the run starts.
    pub warnings: Vec<String>,
    /// The navigation log (`--navigation`), read.
    pub navigation: Option<Navigation>,
    /// The survey photos' altitudes in the navigation log, joined once when the photos were listed (those the log
    /// gives an altitude).
    pub altitudes: std::collections::HashMap<PathBuf, f32>,
    /// The write gate of the run (src/io/gate.rs), open while the plan lives.
    pub _gate: crate::io::gate::Gate,
}

impl Plan {
    /// Check the options and list the inputs; nothing is written.
    pub fn new(opts: &Options, progress: &dyn Progress) -> Result<Plan> {
        opts.validate()?;
        let required = |p: &Option<PathBuf>, flag: &str| {
            p.clone()
                .ok_or_else(|| Error::Usage(format!("{flag} is required")))
        };
        let survey = required(&opts.survey, "--survey")?;
        let out = required(&opts.out, "--out")?;
        // Live and video input (src/run/watch.rs, src/run/stdin.rs): no list of photos up front.
        let stdin = survey == Path::new("-");
        let stdout = out == Path::new("-");
        let streaming = stdin || opts.watch;
        inputs_exist(opts, streaming)?;
        // Outputs never equal, lie in or contain an input; no link inside --out (src/io/paths.rs).
        let gate = check_run_paths(opts)?;
        let window = opts.window_choice()?;
        let found = list_survey(opts, &survey, &out, streaming)?;
        let mut warnings = folder_warnings(opts, &survey, &found);
        let (navigation, altitudes) = match &opts.navigation {
            Some(p) => {
                let (nav, altitudes) = navigation(p, opts, &found, streaming, &mut warnings)?;
                (Some(nav), altitudes)
            }
            None => Default::default(),
        };
        for m in &warnings {
            progress.warn(m);
        }
        let total = found.photos.len();
        let photo_size = majority_size(&found.photos, 15);
        let mut chunk = opts.shard.map_or(0..total, |s| s.range(total));
        if let Some(limit) = opts.limit {
            chunk.end = chunk.end.min(chunk.start.saturating_add(limit));
        }
        let first = if chunk.start > 0 {
            halo_start(
                &found.photos,
                chunk.start,
                opts.longest_window()?,
                photo_size,
            )
        } else {
            0
        };
        let (items, skipped_existing) =
            roles(&found.photos[first..], first, &chunk, opts.resume, &out);
        if let Some(s) = opts.shard {
            progress.stage(&format!(
                "shard {}/{}: photos {}..{} of {} (reading {} before and up to {} after for the windows)",
                s.index,
                s.count,
                chunk.start + 1,
                chunk.end,
                total,
                chunk.start - first,
                opts.longest_window()? - 1
            ));
        }
        if skipped_existing > 0 {
            progress.stage(&format!(
                "resuming: {skipped_existing} photo(s) already have complete outputs and are read for the windows \
                 only"
            ));
        }
        // With --out - there is no output folder and no run files (the report goes to --report).
        let work_dir = (!stdout).then(|| out.join(WORK_DIR));
        Ok(Plan {
            survey,
            out,
            stdin,
            stdout,
            streaming,
            window,
            auto_window: opts.params()?.window_is_auto(),
            found,
            photo_size,
            items,
            chunk,
            first,
            skipped_existing,
            work_dir,
            warnings,
            navigation,
            altitudes,
            _gate: gate,
        })
    }

    /// The altitude of the photo at `path` in the navigation log (`--navigation`), where one is given and lists it:
    /// as joined when the photos were listed, or for a photo a watched folder gained since, joined now.
    pub fn altitude_of(&self, path: &Path) -> Option<f32> {
        let nav = self.navigation.as_ref()?;
        match self.streaming {
            false => self.altitudes.get(path).copied(),
            true => nav.photo(path).altitude,
        }
    }

    /// Create `<out>/_abysslight`: the first thing a run writes.
    pub fn create_work_dir(&self) -> Result<()> {
        if let Some(w) = &self.work_dir {
            std::fs::create_dir_all(w).map_err(|e| Error::io(w, e))?;
        }
        Ok(())
    }

    /// The survey part of [`Plan::describe`]: what is read, what is written, and the disk it takes.
    fn describe_survey(&self) -> Vec<String> {
        let mut lines = Vec::new();
        if self.streaming {
            lines.push(format!(
                "survey: {} (photos as they come)",
                if self.stdin {
                    "frames on stdin".to_string()
                } else {
                    format!("{} watched", self.survey.display())
                }
            ));
        } else {
            lines.push(format!(
                "survey: {} photos in {}{}",
                self.found.photos.len(),
                self.survey.display(),
                match self.found.ignored.len() {
                    0 => String::new(),
                    n => format!(" ({n} other files passed over)"),
                }
            ));
            let count = self.items.iter().filter(|i| i.role == Role::Write).count();
            let existing = self
                .items
                .iter()
                .filter(|i| i.role == Role::Write && self.output_path(&i.entry).exists())
                .count();
            lines.push(format!(
                "to correct: {count} photos (photos {}..{} of {}); read for the windows only: {}",
                self.chunk.start + 1,
                self.chunk.end,
                self.found.photos.len(),
                self.items.len() - count - self.skipped_existing
            ));
            if self.skipped_existing > 0 {
                lines.push(format!(
                    "--resume: {} outputs exist and are kept",
                    self.skipped_existing
                ));
            }
            if existing > 0 {
                lines.push(format!(
                    "note: {existing} of these outputs exist already and would be overwritten (--resume keeps \
                     them)"
                ));
            }
        }
        lines
    }

    /// The disk line of [`Plan::describe`]: what the outputs need, against what is free.
    fn describe_disk(&self, opts: &Options, downsample: usize) -> String {
        let (outputs, factors) = self.disk_need(opts, downsample);
        let mut line = format!(
            "disk: about {} of outputs (inputs' size; JPEG outputs can be larger)",
            checks::size_text(outputs)
        );
        if factors > 0 {
            line += &format!(
                " and up to {} for --save-factors",
                checks::size_text(factors)
            );
        }
        match self.free_space() {
            Some(free) => line + &format!("; {} free there", checks::size_text(free)),
            None => line,
        }
    }

    /// Free bytes on the file system `--out` is (or would be) on; `None` with `--out -` or where unknown.
    fn free_space(&self) -> Option<u64> {
        (!self.stdout)
            .then(|| checks::free_space(&self.out))
            .flatten()
    }

    /// What would go wrong in the run, each in words (empty when nothing is found; always empty when streaming):
    /// photos of another size than the mission's or with unreadable headers, formats mixed, fewer photos than
    /// the window, signs of two dives in one folder, and outputs (with `--save-factors`) larger than the free
    /// space on the output's file system. Reads every photo's header (no photo is decoded). See [`checks`].
    pub fn checks(&self, opts: &Options, downsample: usize) -> Vec<String> {
        if self.streaming {
            return Vec::new();
        }
        let photos = &self.found.photos;
        let mut found = checks::other_sizes(photos, self.photo_size);
        let frames = match (&opts.scatter, &opts.water_column) {
            (None, Some(dir)) => find_photos(dir).map(|f| f.photos).unwrap_or_default(),
            _ => Vec::new(),
        };
        found.extend(checks::water_sizes(
            &frames,
            opts.scatter.as_deref(),
            self.photo_size,
            opts.water_column.as_deref(),
        ));
        found.extend(checks::mixed_formats(photos));
        found.extend(checks::too_few(
            photos.len(),
            self.window.n,
            self.auto_window,
        ));
        found.extend(checks::two_dives(photos));
        let (outputs, factors) = self.disk_need(opts, downsample);
        found.extend(checks::disk(outputs, factors, self.free_space(), &self.out));
        found
    }

    /// Bytes the run would write: the outputs (the inputs' size) and, with `--save-factors`, the factor images
    /// (blocks of `downsample`).
    fn disk_need(&self, opts: &Options, downsample: usize) -> (u64, u64) {
        let write = self.items.iter().filter(|i| i.role == Role::Write);
        let outputs = write
            .clone()
            .map(|i| std::fs::metadata(&i.entry.path).map_or(0, |m| m.len()))
            .sum();
        let factors = match (opts.save_factors, self.photo_size) {
            (true, Some((w, h))) => {
                write.count() as u64 * checks::factor_bytes(w, h, downsample.max(1))
            }
            _ => 0,
        };
        (outputs, factors)
    }

    /// What the run would read and write, in words (`correct --dry-run`).
    pub fn describe(&self, opts: &Options) -> Result<String> {
        let facts = self.facts_now(opts)?;
        let given = opts.params()?;
        let params = given.resolved(&facts.facts);
        let mut s = String::new();
        let mut line = |l: String| {
            s.push_str(&l);
            s.push('\n');
        };
        for l in self.describe_survey() {
            line(l);
        }
        line(format!(
            "output: {}",
            if self.stdout {
                "frames on stdout".to_string()
            } else {
                format!("{} (run files in {WORK_DIR}/)", self.out.display())
            }
        ));
        if !self.streaming {
            line(self.describe_disk(opts, params.downsample));
        }
        line(self.describe_window(opts, &params));
        if let Some(nav) = &self.navigation {
            let listed = self.altitudes.len();
            let (lo, hi) = (self.altitudes.values())
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &a| {
                    (lo.min(a), hi.max(a))
                });
            let range = match listed {
                0 => String::new(),
                _ => format!(" ({lo:.2} to {hi:.2} m)"),
            };
            line(format!(
                "windows by altitude: {} gives the altitude of {listed} of the {} survey photos{range}; where a \
                 window's altitudes span {:.0} % or more of their mean, it is chosen among the photos lit from the \
                 nearest heights",
                nav.path.display(),
                self.found.photos.len(),
                100.0 * crate::method::altitude::ALTITUDE_SPAN
            ));
        }
        line(format!(
            "S: {}",
            match (&opts.scatter, &opts.water_column) {
                (Some(p), _) => format!("scatter image {}", p.display()),
                (None, Some(w)) => format!(
                    "median of the water-column frames in {} ({})",
                    w.display(),
                    find_photos(w)
                        .map_or_else(|e| e.to_string(), |f| format!("{} frames", f.photos.len()))
                ),
                (None, None) => "none (no --water-column or --scatter: S = 0)".into(),
            }
        ));
        // `abyss` floors F relative to each photo's lit level (--relative-floor), the others at --factor-floor.
        let floor = match opts.method {
            Method::Abyss => format!("relative floor {}", opts.relative_floor),
            _ => format!("factor floor {}", opts.factor_floor),
        };
        line(format!(
            "method: {}, blocks {}, seafloor colour {}, transfer {}, {floor}",
            opts.method,
            match (params.downsample, facts.blocks_why(&given)) {
                (k, Some(why)) if k > 0 => format!("{k}x{k} (auto: {why})"),
                (k, _) if k > 0 => format!("{k}x{k}"),
                (_, why) => format!("auto ({})", why.unwrap_or_default()),
            },
            opts.seafloor_colour,
            match &facts.transfer_why {
                Some(why) => format!("auto, {why}"),
                None => params.curve().to_string(),
            },
        ));
        for l in self.describe_checks(opts, params.downsample) {
            line(l);
        }
        Ok(s)
    }

    /// The dry run's line on the window: auto (as the photos come or before the correction, up to the longest the
    /// mission holds), or the window given with its breakdown probability, and the near window.
    fn describe_window(&self, opts: &Options, params: &crate::method::params::Params) -> String {
        let window = if params.window_is_auto() {
            let longest = match self.streaming {
                true => crate::method::stretch::MAX_AUTO_WINDOW,
                false => crate::method::stretch::longest_window(self.found.photos.len()),
            };
            format!(
                "window: auto, chosen per stretch of the mission by a survey of its photos ({}: {} and the median \
                 on sparse ground under a moving camera, up to {longest} photos and a higher quantile on dense \
                 fields or under a slow camera; the near window with it)",
                match self.streaming {
                    true => format!(
                        "as they come, each photo once the {} after it are in",
                        crate::method::survey::LOOK_AHEAD
                    ),
                    false => "before the correction".into(),
                },
                crate::method::params::BASE_WINDOW.min(longest),
            )
        } else if self.window.p_half.is_nan() {
            format!("window: n = {}", self.window.n)
        } else {
            format!(
                "window: n = {} (P_half = {:.4} at contamination {})",
                self.window.n,
                self.window.p_half,
                opts.contamination.unwrap_or_default()
            )
        };
        match params.near_window() {
            Some(k) if !params.window_is_auto() => {
                format!("{window}, near window {k} (--near-window)")
            }
            _ => window,
        }
    }

    /// The warnings of [`Plan::describe`]: the plan's own and what [`Plan::checks`] finds, and a last line saying
    /// what was checked.
    fn describe_checks(&self, opts: &Options, downsample: usize) -> Vec<String> {
        let problems = self.checks(opts, downsample);
        let mut lines: Vec<String> = (self.warnings.iter().chain(&problems))
            .map(|w| format!("warning: {w}"))
            .collect();
        if !self.streaming {
            lines.push(match lines.len() {
                0 => "checks: photo sizes, water-column size, formats, window, one dive, disk: nothing found \
                      (what only a run can check: the photos' content, the ground, the camera's motion, the \
                      independent samples in each window and the flags they raise)"
                    .to_string(),
                k => format!(
                    "checks: {k} warning(s) above (docs/guide.md, \"Before the first run\"); what only a run \
                     can check: the photos' content, the ground, the camera's motion, the independent samples in \
                     each window and the flags they raise"
                ),
            });
        }
        lines
    }

    /// What the `auto` settings of the run are resolved from ([`Params::resolved`]): the mission's photo size
    /// (the survey's; streaming runs have no photo before the run: the size of `--scatter` or of the first
    /// water-column frame, the same camera, or else none, and the engine takes it from the first photo that
    /// arrives), whether a mask is used, and with `--transfer auto` the curve the first survey photo declares
    /// ([`crate::io::transfer::assume`]; linear without a photo file to read).
    ///
    /// With `--watch` and `--transfer auto` this waits for the first photo the watch takes (as a batch run reads
    /// the first photo of its folder); [`Plan::facts_now`] does not wait.
    pub fn facts(&self, opts: &Options) -> Result<MissionFacts> {
        self.facts_waiting(opts, true)
    }

    /// [`Plan::facts`] without waiting for a watched folder's first photo (`--dry-run`): the photos there now.
    pub fn facts_now(&self, opts: &Options) -> Result<MissionFacts> {
        self.facts_waiting(opts, false)
    }

    fn facts_waiting(&self, opts: &Options, wait: bool) -> Result<MissionFacts> {
        let water = || {
            let dir = opts.water_column.as_ref()?;
            let first = find_photos(dir).ok()?.photos.into_iter().next()?;
            crate::io::header_size(&first.path).ok()
        };
        let scatter = || crate::io::header_size(opts.scatter.as_ref()?).ok();
        let (size, size_from) = match self.photo_size {
            Some(s) => (Some(s), "survey photos"),
            None => match scatter() {
                Some(s) => (Some(s), "scatter image"),
                None => (water(), "water-column frames"),
            },
        };
        // The first photo that can be read (an unreadable one is that photo's error, later); with --watch the
        // first photo the watch takes, once it is complete.
        let mut first: Vec<PathBuf> = self
            .found
            .photos
            .iter()
            .take(15)
            .map(|e| e.path.clone())
            .collect();
        if opts.watch && opts.transfer.is_none() && !wait {
            let now = find_photos(&self.survey)
                .map(|f| f.photos)
                .unwrap_or_default();
            first.extend(now.into_iter().take(15).map(|e| e.path));
        } else if opts.watch && opts.transfer.is_none() {
            first.extend(crate::run::watch::first_complete(
                &self.survey,
                &self.out,
                std::time::Duration::from_millis(opts.poll_interval),
                opts.idle_timeout.map(std::time::Duration::from_secs_f64),
                crate::run::watch::stop_flag(),
            ));
        }
        let assumed = opts.transfer.is_none().then(|| {
            crate::io::transfer::assume_first(first.iter().map(PathBuf::as_path)).unwrap_or(crate::io::transfer::Assumed {
                transfer: Transfer::Linear,
                why: "no photo file to read before the run (standard input, an empty folder or unreadable \
                      photos)"
                    .into(),
            })
        });
        Ok(MissionFacts {
            facts: Facts {
                size,
                masked: opts.mask.is_some() || opts.mask_auto,
                transfer: assumed.as_ref().map(|a| a.transfer),
            },
            size_from,
            transfer_why: assumed.map(|a| format!("{}: {}", a.transfer, a.why)),
        })
    }

    /// Where the output of a survey photo goes.
    pub fn output_path(&self, entry: &Entry) -> PathBuf {
        output_path(&self.out, entry)
    }
}

/// The navigation log at `path`, read (as `opts` says: columns, clock offset), and joined to the survey's photos
/// (in parallel: a log by time reads each photo's EXIF time), with a warning for what reading it found and for the
/// photos it gives no altitude, and what that costs; none given an altitude is an error that says why (the wrong
/// log, names that do not match, or clocks apart). Photos still to come (`--watch`) are not counted.
fn navigation(
    path: &Path,
    opts: &Options,
    found: &Found,
    streaming: bool,
    warnings: &mut Vec<String>,
) -> Result<(Navigation, std::collections::HashMap<PathBuf, f32>)> {
    let how = crate::io::navigation::ReadAs {
        columns: opts.navigation_columns.clone(),
        clock_offset: opts.navigation_clock_offset,
    };
    let nav = Navigation::read(path, &how)?;
    for note in nav.notes() {
        warnings.push(format!("{}: {note}", path.display()));
    }
    let photos = &found.photos;
    let paths: Vec<&Path> = photos.iter().map(|e| e.path.as_path()).collect();
    let joined = nav.join(&paths);
    let altitudes = (photos.iter().zip(&joined))
        .filter_map(|(e, j)| Some((e.path.clone(), j.altitude?)))
        .collect::<std::collections::HashMap<_, _>>();
    let unlisted: Vec<usize> = (0..photos.len())
        .filter(|&i| joined[i].altitude.is_none())
        .collect();
    let (none, some) = match nav.by_time() {
        true => (
            "gives no altitude at the time of any",
            "gives no altitude at the time of",
        ),
        false => ("lists none of the", "does not list"),
    };
    if !streaming && !photos.is_empty() && unlisted.len() == photos.len() {
        let how = match nav.by_time() {
            true => clocks_apart(&nav, opts.navigation_clock_offset, &joined, &photos[0].path),
            false => format!(
                "photos are matched by file name, e.g. {}",
                photos[0]
                    .path
                    .file_name()
                    .unwrap_or_default()
                    .to_string_lossy()
            ),
        };
        return Err(Error::Config {
            path: path.to_path_buf(),
            reason: format!("{none} {} survey photos ({how})", photos.len()),
        });
    }
    if let Some(&first) = unlisted.first() {
        let n = opts
            .window_choice()
            .map_or(crate::method::params::BASE_WINDOW, |w| w.n);
        warnings.push(format!(
            "{}: {some} {} of the {} survey photos (e.g. {}); windows over time that hold one are not chosen by \
             altitude: {} photos lose windows by altitude (windows of {n} photos)",
            path.display(),
            unlisted.len(),
            photos.len(),
            photos[first].relative.display(),
            windows_holding(&unlisted, photos.len(), n),
        ));
    }
    Ok((nav, altitudes))
}

/// How many of `total` photos have a window over time of `n` (centred, shifted at the mission's ends) that holds
/// one of `unlisted` (sorted photo numbers): the photos whose window stays the window over time.
fn windows_holding(unlisted: &[usize], total: usize, n: usize) -> usize {
    let n = n.clamp(1, total.max(1));
    (0..total)
        .filter(|&i| {
            let start = i.saturating_sub(n / 2).min(total - n);
            let k = unlisted.partition_point(|&u| u < start);
            unlisted.get(k).is_some_and(|&u| u < start + n)
        })
        .count()
}

/// Why a log by time gives no photo an altitude: both spans as times, and the clock offset that would align them;
/// or that the photos have no EXIF time.
fn clocks_apart(
    nav: &Navigation,
    offset: f64,
    joined: &[crate::io::navigation::Joined],
    first: &Path,
) -> String {
    use crate::io::navigation::iso;
    let times = joined.iter().filter_map(|j| j.time);
    let (lo, hi) = times.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
        (lo.min(t), hi.max(t))
    });
    let Some((a, b)) = nav.time_span().filter(|_| lo.is_finite()) else {
        return format!(
            "photos are matched by the time in their EXIF (DateTimeOriginal), and {} has none",
            first.display()
        );
    };
    if lo <= b && hi >= a {
        return format!(
            "photos are matched by the time in their EXIF: log {} to {}, photos {} to {}: the photos fall in its \
             gaps (rows more than {} s apart)",
            iso(a),
            iso(b),
            iso(lo),
            iso(hi),
            crate::io::navigation::MAX_GAP_S
        );
    }
    // Midpoint to midpoint: the offset that lays the photos' span in the middle of the log's.
    let apart = (lo + hi) / 2.0 - (a + b) / 2.0;
    let words = match apart.abs() {
        d if d >= 3600.0 => format!("{:.1} h", d / 3600.0),
        d if d >= 60.0 => format!("{:.0} min", d / 60.0),
        d => format!("{d:.0} s"),
    };
    format!(
        "photos are matched by the time in their EXIF: log {} to {}, photos {} to {}: {words} apart? If the \
         camera's clock is off, --navigation-clock-offset {} puts the log on it",
        iso(a),
        iso(b),
        iso(lo),
        iso(hi),
        (offset + apart).round()
    )
}

/// The input folders and files of a run are there, each named by its flag where not (the path checks after it
/// name only the path); the scatter image, the mask and the navigation log are regular files, not a FIFO that
/// would block the run or a device that never ends.
fn inputs_exist(opts: &Options, streaming: bool) -> Result<()> {
    let inputs = [
        ("--survey", opts.survey.as_deref().filter(|_| !streaming)),
        ("--water-column", opts.water_column.as_deref()),
        ("--scatter", opts.scatter.as_deref()),
        ("--mask", opts.mask.as_deref()),
        ("--navigation", opts.navigation.as_deref()),
    ];
    for (flag, path) in inputs {
        if let Some(p) = path.filter(|p| !p.exists()) {
            // A file-system error (Python: FileNotFoundError) whose "path" names the flag too.
            return Err(Error::io(
                format!("{flag} {}", p.display()),
                std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or folder"),
            ));
        }
    }
    for (what, path) in [
        ("--scatter image", &opts.scatter),
        ("--mask file", &opts.mask),
        ("--navigation log", &opts.navigation),
    ] {
        if let Some(p) = path {
            crate::io::whole::check_regular(p, what)?;
        }
    }
    Ok(())
}

/// The survey photos found (none when streaming), or why there are none to correct.
fn list_survey(opts: &Options, survey: &Path, out: &Path, streaming: bool) -> Result<Found> {
    // Baseline `--method mean` needs the whole mission's mean before the stream.
    if streaming && opts.method == Method::Mean {
        return Err(Error::Usage(
            "--method mean needs every photo of the mission before it corrects the first; it cannot be used with \
             --watch or --survey -"
                .into(),
        ));
    }
    if streaming {
        if opts.watch && !survey.is_dir() {
            return Err(Error::Usage(format!(
                "--watch {}: not a folder",
                survey.display()
            )));
        }
        return Ok(Found::default());
    }
    // A survey link pointing at --out is not read back.
    let found = find_photos_excluding(survey, &[out])?;
    if found.photos.is_empty() {
        return Err(Error::Usage(format!(
            "--survey {}: no photos ({}) found below it",
            survey.display(),
            io::PHOTO_EXTENSIONS.join(", "),
        )));
    }
    Ok(found)
}

/// Warnings about the input folders, before the run: files passed over, and a water-column folder that is the
/// survey's ([`checks::water_is_survey`]).
fn folder_warnings(opts: &Options, survey: &Path, found: &Found) -> Vec<String> {
    let mut warnings = Vec::new();
    if !found.ignored.is_empty() {
        warnings.push(format!(
            "{} file(s) in {} are not photos by name and were passed over (e.g. {})",
            found.ignored.len(),
            survey.display(),
            found.ignored[0].display()
        ));
    }
    if let Some(water) = opts.water_column.as_deref() {
        warnings.extend(checks::water_is_survey(water, survey, &found.photos));
    }
    warnings
}

/// What the `auto` settings of a run are resolved from ([`Plan::facts`]), and where each fact came from.
#[derive(Debug, Clone)]
pub struct MissionFacts {
    /// The facts.
    pub facts: Facts,
    /// Where the photo size came from: the survey photos, the scatter image or the water-column frames.
    pub size_from: &'static str,
    /// `--transfer auto`: the curve taken and why (`None` when the curve was given).
    pub transfer_why: Option<String>,
}

impl MissionFacts {
    /// Why `auto` blocks of `params` (before [`Params::resolved`]) are the size they are, in words; `None` when
    /// `--downsample` gave them.
    pub fn blocks_why(&self, params: &Params) -> Option<String> {
        let (k, rule) = params.auto_block(&self.facts);
        Some(match rule {
            BlockRule::Given => return None,
            BlockRule::Paper => format!("the paper's 8 for --method {}", params.method),
            BlockRule::Masked => {
                "the paper's 8 with a mask: overlays need the larger blocks".into()
            }
            BlockRule::Size => {
                let (w, h) = self.facts.size.unwrap_or_default();
                format!(
                    "{} {w}x{h}, about {} blocks across",
                    self.size_from,
                    w.max(h) / k
                )
            }
            BlockRule::Unknown => "from the first photo's size, about 160 blocks across".into(),
        })
    }
}

/// The photos to read from `entries` (the survey from photo `first` on), each with what to do with it: write it
/// (in `chunk`), only read it for the windows (a shard's halo), or only read it because `--resume` found its output
/// complete. Also returns how many outputs were found complete.
fn roles(
    entries: &[Entry],
    first: usize,
    chunk: &Range<usize>,
    resume: bool,
    out: &Path,
) -> (Vec<Item>, usize) {
    let mut skipped_existing = 0usize;
    let items = entries
        .iter()
        .enumerate()
        .map(|(j, entry)| {
            let i = first + j;
            let role = if !chunk.contains(&i) {
                Role::Halo
            } else if resume && output_complete(&output_path(out, entry)) {
                skipped_existing += 1;
                Role::Done
            } else {
                Role::Write
            };
            Item {
                index: j,
                entry: entry.clone(),
                role,
            }
        })
        .collect();
    (items, skipped_existing)
}

/// The path checks of a correction run, before anything is written: `--out` (unless `-`) and `--report` against
/// every input (survey unless `-`, water column, scatter image, mask), `<out>/_abysslight` not a link, `--report`
/// a writable regular file; then the write gate of the run (src/io/gate.rs) is open.
pub fn check_run_paths(opts: &Options) -> Result<crate::io::gate::Gate> {
    use crate::io::gate::{Gate, Output};
    let dash = |p: &&Path| *p != Path::new("-");
    let inputs: Vec<(&str, &Path)> = [
        ("survey folder", opts.survey.as_deref().filter(dash)),
        ("water-column folder", opts.water_column.as_deref()),
        ("scatter image", opts.scatter.as_deref()),
        ("mask", opts.mask.as_deref()),
        ("navigation file", opts.navigation.as_deref()),
    ]
    .into_iter()
    .filter_map(|(what, p)| p.map(|p| (what, p)))
    .collect();
    let mut outputs = Vec::new();
    if let Some(out) = opts.out.as_deref().filter(dash) {
        outputs.push(Output::Folder("--out", out));
    }
    if let Some(r) = opts.report.as_deref() {
        outputs.push(Output::File("--report", r));
    }
    let gate = Gate::open(&outputs, &inputs)?;
    if let Some(out) = opts.out.as_deref().filter(dash) {
        check_no_links_below(out, &out.join(crate::io::WORK_DIR).join("report.json"))?;
        crate::io::gate::check_work_dir(&out.join(crate::io::WORK_DIR))?;
    }
    Ok(gate)
}

/// True when `path` holds an output of an earlier run. Outputs are only ever renamed into place once complete,
/// so existence means complete; the header is read as a cheap check against foreign or damaged files.
pub fn output_complete(path: &Path) -> bool {
    image::ImageReader::open(path)
        .and_then(|r| r.with_guessed_format())
        .ok()
        .and_then(|r| r.into_dimensions().ok())
        .is_some_and(|(w, h)| w > 0 && h > 0)
}

/// Output path of a survey photo.
pub fn output_path(out: &Path, entry: &Entry) -> PathBuf {
    out.join(&entry.relative)
}

/// Index of the first photo this shard must read: far enough back that `n − 1` usable photos precede its chunk
/// (a window reaches at most that far), or the start of the survey.
fn halo_start(
    entries: &[Entry],
    chunk_start: usize,
    n: usize,
    size: Option<(usize, usize)>,
) -> usize {
    let mut usable = 0;
    let mut layout = None;
    let mut i = chunk_start;
    while i > 0 && usable + 1 < n {
        i -= 1;
        if let Ok(p) = decode_expecting(&entries[i].path, size) {
            if *layout.get_or_insert(p.layout) == p.layout {
                usable += 1;
            }
        }
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::paths::check_outputs;

    #[test]
    fn output_inside_input_is_refused() {
        let d = tempfile::tempdir().unwrap();
        let survey = d.path().join("survey");
        std::fs::create_dir_all(&survey).unwrap();
        let check = |out: &Path| check_outputs(&[("--out", out)], &[("survey", &survey)]);
        assert!(check(&survey).is_err());
        assert!(check(&survey.join("out")).is_err());
        assert!(check(&survey.join("./x/../")).is_err());
        assert!(check(&d.path().join("out")).is_ok());
        assert!(check(&d.path().join("survey2")).is_ok());
    }
}
