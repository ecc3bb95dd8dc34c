//! A whole mission from folders (or pipes) to folders, as `abysslight correct` runs it. [`correct_mission`] is a
//! short recipe over the modules here:
//!
//! 1. [`plan`]: check the options and list the inputs, before anything is written;
//! 2. [`prepare`](mod@prepare): `S`, the mask and the mission mean, into an [`Engine`](crate::method::engine::Engine);
//! 3. [`threads`]: stream the survey once, in order, through the engine, decoding and writing on threads;
//! 4. [`report`] and [`pictures`]: the run report and the pictures to check it by.
//!
//! Sources of photos: a folder ([`source`]), a folder watched during a dive ([`watch`]) or frames on stdin
//! ([`stdin`]). [`options`] holds every setting, shared by the library, the TOML config file and the CLI.

pub mod draw;
pub mod guard;
pub mod options;
pub mod pictures;
pub mod plan;
pub mod prepare;
pub mod report;
pub mod source;
pub mod stdin;
pub mod threads;
pub mod watch;

use std::path::Path;
use std::time::Instant;

use crate::error::{Error, Result};
use crate::io::find_photos;
use crate::method::monitor::{Summary, Thresholds};
use crate::method::scatter::Scatter;
use crate::run::options::Options;
use crate::run::plan::Plan;
use crate::run::prepare::{prepare, spread_indices, Setup};
use crate::run::report::{FileError, FrameReport, Progress, Report};
use crate::run::threads::{stream, Outcome};

/// Run `abysslight correct` as described by `opts`.
pub fn correct_mission(opts: &Options, progress: &dyn Progress) -> Result<Report> {
    match opts.threads {
        Some(t) => rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .map_err(|e| Error::Usage(format!("cannot start {t} threads: {e}")))?
            .install(|| run(opts, progress)),
        None => run(opts, progress),
    }
}

/// Plan, prepare the engine, stream the survey, report.
fn run(opts: &Options, progress: &dyn Progress) -> Result<Report> {
    let started = Instant::now();
    let plan = Plan::new(opts, progress)?;
    // --transfer auto: the curve the first survey photo declares, for the whole mission.
    let (resolved, transfer_assumed) = resolve_transfer(opts, &plan)?;
    // --downsample auto: blocks from the mission's photo size.
    let (k, blocks_why) = plan.downsample(&resolved);
    // --near-window auto: resolved from the window (0: off), so the report and the lock record what ran.
    let resolved = Options {
        downsample: k,
        near_window: Some(resolved.near_window_for(plan.window.n).unwrap_or(0)),
        ..resolved
    };
    let blocks = k.map_or_else(|| "auto".to_string(), |k| format!("{k}x{k}"));
    let opts = &resolved;
    if let Some(why) = &transfer_assumed {
        progress.stage(&format!("camera curve {why}; --transfer sets it"));
    }
    if let Some(why) = &blocks_why {
        progress.stage(&format!("blocks {blocks} ({why}); --downsample sets them"));
    }
    plan.create_work_dir()?;
    // One run per --out (per shard), the same options as earlier runs there, stale temp files removed
    // (src/run/guard.rs). Held until the report is written.
    let (_lock, removed) = match &plan.work_dir {
        Some(w) => {
            let (lock, removed) = guard::start(opts, &plan.out, w)?;
            (Some(lock), removed)
        }
        None => (None, Vec::new()),
    };
    let setup = prepare(opts, &plan, progress)?;
    let Setup {
        engine,
        scatter,
        errors,
        mut warnings,
    } = setup;
    warnings.splice(0..0, plan.warnings.iter().cloned());
    if let Some(first) = removed.first() {
        let m = format!(
            "removed {} temp file(s) left by an interrupted run (e.g. {})",
            removed.len(),
            first.display()
        );
        progress.warn(&m);
        warnings.push(m);
    }
    // Entries of the survey that could not be taken are failed files (exit 1), named in the report.
    let survey_skipped: Vec<FileError> = plan
        .found
        .skipped
        .iter()
        .map(|s| {
            let e = s.to_error();
            progress.file_error(&e);
            FileError::from_error(&s.path, &e)
        })
        .collect();
    let n = plan.window.n;
    let near = match opts.near_window_for(n) {
        Some(k) => format!(", near window {k}"),
        None => String::new(),
    };
    if plan.streaming {
        progress.stage(&format!(
            "correcting survey photos as they come (window n = {n}: each photo once the {} after it are in{near}; \
             blocks {blocks})",
            n / 2
        ));
    } else {
        progress.stage(&format!(
            "correcting {} survey photos (window n = {n}{near}, blocks {blocks})",
            plan.chunk.len() - plan.skipped_existing
        ));
    }
    progress.start(plan.chunk.len());
    let outcome = stream(opts, &plan, engine, progress)?;
    // The pictures are for people to look at: one that cannot be written (disk full) is a warning.
    if let Err(e) = save_pictures(opts, &plan, &outcome) {
        let m = format!("the run's pictures were not written: {e}");
        progress.warn(&m);
        warnings.push(m);
    }
    let water_column_failed = errors.len();
    let mut all_errors = errors;
    all_errors.extend(survey_skipped);
    all_errors.extend(outcome.errors);
    warnings.extend(outcome.warnings);
    let mut monitor = Summary::default();
    for f in &outcome.frames {
        monitor.add(&f.health.flags);
    }
    let mut report = Report {
        tool: "abysslight".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        options: opts.clone(),
        transfer_assumed,
        window: plan.window,
        layout: outcome.layout,
        scatter,
        survey_photos: if plan.streaming {
            outcome.streamed
        } else {
            plan.found.photos.len()
        },
        corrected: outcome.frames.iter().filter(|f| !f.resumed).count(),
        skipped_existing: plan.skipped_existing,
        peak_photos_in_memory: outcome.peak_photos,
        failed: all_errors.len() - water_column_failed,
        water_column_failed,
        ignored_files: plan.found.ignored.len(),
        floored_pixels: outcome.totals.floored_pixels,
        clipped_samples: outcome.totals.clipped_samples,
        monitor,
        frames: outcome.frames,
        errors: all_errors,
        warnings,
        elapsed_s: started.elapsed().as_secs_f64(),
        report_path: None,
    };
    report.write(opts, plan.work_dir.as_deref())?;
    Ok(report)
}

/// `opts` with `--transfer auto` resolved from the first survey photo ([`crate::io::transfer::assume`]), and what
/// was assumed and why; `opts` unchanged (and `None`) without it.
fn resolve_transfer(opts: &Options, plan: &Plan) -> Result<(Options, Option<String>)> {
    if !opts.transfer_auto {
        return Ok((opts.clone(), None));
    }
    // The first photo that can be read (an unreadable one is that photo's error, later).
    let first = plan.found.photos.iter().take(15).map(|e| e.path.as_path());
    let assumed = crate::io::transfer::assume_first(first).unwrap_or(crate::io::transfer::Assumed {
        transfer: crate::method::transfer::Transfer::Linear,
        why: "no photo file to read before the run (standard input, an empty folder or unreadable photos)".into(),
    });
    let why = format!("{}: {}", assumed.transfer, assumed.why);
    Ok((
        Options {
            transfer: assumed.transfer,
            transfer_auto: false,
            ..opts.clone()
        },
        Some(why),
    ))
}

/// `overview.png` (the health series over the mission) and `flagged.png` (a few flagged photos beside their
/// `F·C`) in `_abysslight/`.
fn save_pictures(opts: &Options, plan: &Plan, outcome: &Outcome) -> Result<()> {
    let (false, Some(work_dir)) = (outcome.frames.is_empty(), &plan.work_dir) else {
        return Ok(());
    };
    let name = |what: &str| match opts.shard {
        Some(s) => format!("{what}-shard-{}-of-{}.png", s.index, s.count),
        None => format!("{what}.png"),
    };
    pictures::save_png(
        &pictures::overview(&outcome.frames, &Thresholds::default()),
        &work_dir.join(name("overview")),
    )?;
    let flagged = &outcome.flagged_lit;
    let rows: Vec<(&FrameReport, &crate::method::raster::Raster)> =
        spread_indices(flagged.len(), 6)
            .into_iter()
            .filter_map(|j| {
                let (index, lit) = &flagged[j];
                outcome
                    .frames
                    .iter()
                    .find(|f| f.index == *index)
                    .map(|f| (f, lit))
            })
            .collect();
    if let Some(sheet) = pictures::flagged_sheet(&rows, 320) {
        pictures::save_png(&sheet, &work_dir.join(name("flagged")))?;
    }
    Ok(())
}

/// What [`estimate_scatter_file`] did.
#[derive(Debug, Clone, Copy)]
pub struct ScatterRun {
    /// Frames that entered the median.
    pub frames: usize,
    /// Frames that could not be used.
    pub failed: usize,
}

/// `abysslight scatter`: estimate `S` from a folder of water-column frames and write it as a 16-bit PNG.
pub fn estimate_scatter_file(
    water_column: &Path,
    out: &Path,
    memory_mib: usize,
    progress: &dyn Progress,
) -> Result<ScatterRun> {
    let _gate = crate::io::gate::Gate::open(
        &[crate::io::gate::Output::File("--out", out)],
        &[("water-column folder", water_column)],
    )?;
    let wc = find_photos(water_column)?;
    progress.stage(&format!(
        "estimating scatter S from {} water-column frames in {}",
        wc.photos.len(),
        water_column.display()
    ));
    let mut failed = 0;
    let s = Scatter::from_files(&wc.photos, memory_mib.max(1) << 20, |e| {
        progress.file_error(&e);
        failed += 1;
    })?
    .ok_or_else(|| {
        Error::Usage(format!(
            "no usable water-column frames in {}",
            water_column.display()
        ))
    })?;
    s.save_png(out)?;
    Ok(ScatterRun {
        frames: s.frames,
        failed,
    })
}
