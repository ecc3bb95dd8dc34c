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
pub mod merge;
pub(crate) use crate::options;
pub mod pictures;
pub mod plan;
pub mod prepare;
pub mod source;
pub mod stdin;
pub mod summary;
pub mod threads;
pub mod watch;

use std::path::Path;
use std::time::Instant;

use crate::error::{Error, Result};
use crate::io::find_photos;
use crate::method::monitor::{Summary, Thresholds};
use crate::method::scatter::Scatter;
use crate::report::{FileError, FrameReport, Progress, Report, ScatterInfo, WindowSummary};
use crate::run::options::Options;
use crate::run::plan::Plan;
use crate::run::prepare::{prepare, spread_indices, Setup};
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

/// The mask's and the navigation log's paths resolved and their contents' SHA-256 in the options the run records
/// (report.json, the lock): a shard or a resumed run that reads another file, or the same file edited, is refused
/// by the options check instead of mixed, and `./nav.csv` is `nav.csv`.
fn record_inputs(opts: &mut Options, plan: &Plan) -> Result<()> {
    if let Some(m) = &opts.mask {
        opts.mask_sha256 = Some(crate::io::whole::sha256_of(
            m,
            crate::io::navigation::MAX_BYTES,
            "--mask file",
        )?);
        opts.mask = Some(crate::io::paths::resolve(m));
    }
    opts.navigation_sha256 = plan.navigation.as_ref().map(|n| n.sha256.clone());
    if let Some(n) = &opts.navigation {
        opts.navigation = Some(crate::io::paths::resolve(n));
    }
    Ok(())
}

/// Plan, prepare the engine, stream the survey, report.
fn run(opts: &Options, progress: &dyn Progress) -> Result<Report> {
    let started = Instant::now();
    // Photos are read more than once (the plan's samples, the survey, the correction): each JPEG's completeness
    // is checked on its first read only.
    let _checks = crate::io::jpeg_check::RememberChecks::start();
    let plan = Plan::new(opts, progress)?;
    let (params, transfer_assumed) = resolve(opts, &plan, progress)?;
    // The options with every `auto` resolved, so the report and the lock record what ran.
    let mut resolved = opts.with_resolved(&params);
    record_inputs(&mut resolved, &plan)?;
    let opts = &resolved;
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
    let Setup {
        engine,
        scatter,
        errors,
        mut warnings,
    } = prepare(opts, &params, &plan, progress)?;
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
    say_what_runs(&plan, &params, progress);
    progress.start(plan.chunk.len());
    let outcome = stream(opts, &plan, engine, progress)?;
    // The pictures are for people to look at: one that cannot be written (disk full) is a warning.
    if let Err(e) = save_pictures(opts, &plan, &outcome) {
        let m = format!("the run's pictures were not written: {e}");
        progress.warn(&m);
        warnings.push(m);
    }
    let before = BeforeStream {
        scatter,
        transfer_assumed,
        water_column_errors: errors,
        survey_skipped,
        warnings,
    };
    let mut report = report_of(opts, &params, &plan, before, outcome);
    report.elapsed_s = started.elapsed().as_secs_f64();
    report.write(opts, plan.work_dir.as_deref())?;
    Ok(report)
}

/// The method's parameters of the run, every `auto` resolved from the mission's facts ([`Plan::facts`],
/// [`crate::method::params::Params::resolved`]), each resolution said; with `--transfer auto` the curve taken and
/// why.
fn resolve(
    opts: &Options,
    plan: &Plan,
    progress: &dyn Progress,
) -> Result<(crate::method::params::Params, Option<String>)> {
    let facts = plan.facts(opts)?;
    let given = opts.params()?;
    let params = given.resolved(&facts.facts);
    if let Some(why) = &facts.transfer_why {
        progress.stage(&format!("camera curve {why}; --transfer sets it"));
    }
    if let Some(why) = facts.blocks_why(&given) {
        progress.stage(&format!(
            "blocks {} ({why}); --downsample sets them",
            blocks(&params)
        ));
    }
    Ok((params, facts.transfer_why))
}

/// `8x8`, or `auto` while the photos' size is not known.
fn blocks(params: &crate::method::params::Params) -> String {
    match params.downsample {
        0 => "auto".to_string(),
        k => format!("{k}x{k}"),
    }
}

/// The line that says what is corrected, with which window.
fn say_what_runs(plan: &Plan, params: &crate::method::params::Params, progress: &dyn Progress) {
    if params.window_is_auto() {
        let blocks = blocks(params);
        progress.stage(&if plan.streaming {
            format!(
                "correcting survey photos as they come (windows chosen per stretch by the survey as the photos \
                 come: each photo once the {} after it are in; blocks {blocks})",
                crate::method::survey::LOOK_AHEAD
            )
        } else {
            format!(
                "correcting {} survey photos (windows chosen per stretch, blocks {blocks})",
                plan.chunk.len() - plan.skipped_existing
            )
        });
        return;
    }
    let n = params.window_length();
    let near = match params.near_window() {
        Some(k) => format!(", near window {k}"),
        None => String::new(),
    };
    let blocks = blocks(params);
    progress.stage(&if plan.streaming {
        format!(
            "correcting survey photos as they come (window n = {n}: each photo once the {} after it are in{near}; \
             blocks {blocks})",
            n / 2
        )
    } else {
        format!(
            "correcting {} survey photos (window n = {n}{near}, blocks {blocks})",
            plan.chunk.len() - plan.skipped_existing
        )
    });
}

/// What a run knew before the survey stream, for its report.
struct BeforeStream {
    scatter: ScatterInfo,
    transfer_assumed: Option<String>,
    water_column_errors: Vec<FileError>,
    survey_skipped: Vec<FileError>,
    warnings: Vec<String>,
}

/// The report of a run (its time is filled in by the caller).
fn report_of(
    opts: &Options,
    params: &crate::method::params::Params,
    plan: &Plan,
    before: BeforeStream,
    outcome: Outcome,
) -> Report {
    let water_column_failed = before.water_column_errors.len();
    let mut errors = before.water_column_errors;
    errors.extend(before.survey_skipped);
    errors.extend(outcome.errors);
    let mut warnings = before.warnings;
    warnings.extend(outcome.warnings);
    Report {
        tool: "abysslight".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        options: opts.clone(),
        transfer_assumed: before.transfer_assumed,
        window: WindowSummary::of(params, opts, &outcome.frames),
        layout: outcome.layout,
        scatter: before.scatter,
        survey_photos: if plan.streaming {
            outcome.streamed
        } else {
            plan.found.photos.len()
        },
        corrected: outcome.frames.iter().filter(|f| !f.resumed).count(),
        skipped_existing: plan.skipped_existing,
        peak_photos_in_memory: outcome.peak_photos,
        failed: errors.len() - water_column_failed,
        water_column_failed,
        ignored_files: plan.found.ignored.len(),
        floored_pixels: outcome.totals.floored_pixels,
        clipped_samples: outcome.totals.clipped_samples,
        monitor: Summary::of(outcome.frames.iter().map(|f| &f.health)),
        frames: outcome.frames,
        errors,
        warnings,
        elapsed_s: 0.0,
        report_path: None,
    }
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
    if let Some(shard) = opts.shard {
        merge::save_flagged(work_dir, shard, &outcome.flagged_lit)?;
    }
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
