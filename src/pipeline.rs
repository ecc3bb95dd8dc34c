//! `correct`, top to bottom: find the photos, estimate `S`, then stream the survey once in order:
//!
//! 1. decoder threads (as many as worker threads) read photos ahead, handed over in order (bounded queue);
//! 2. each photo is block-median downsampled and its low-resolution image enters the ring buffer of the window;
//! 3. once the window of the oldest waiting photo is complete, its `M` (temporal median), `F` and the corrected
//!    photo are computed (rayon over rows);
//! 4. encoder threads write outputs atomically (bounded queue).
//!
//! Memory: at most `n` low-resolution images, at most `n` full-resolution photos waiting for their window (at the
//! start of a mission; `n/2 + 1` later), plus the few in the decode and encode queues. It does not grow with the
//! number of photos.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use crossbeam_channel::bounded;

use crate::correct::{correct_in_place, CorrectStats};
use crate::error::{Error, Result};
use crate::factor::{factor, lit_seafloor};
use crate::io::{self, decode, find_photos, EncodeSettings, Entry, WORK_DIR};
use crate::mask::{block_median_masked, detect_static, fill_missing, DetectSettings, Mask};
use crate::median::{block_median, stack_median};
use crate::monitor::{Flag, Monitor, Summary, Thresholds};
use crate::options::{Method, Options};
use crate::overview;
use crate::raster::{Layout, Photo, Raster, Samples};
use crate::report::{FileError, FrameReport, Progress, Report, ScatterInfo};
use crate::scatter::{self, Prepared, Scatter};
use crate::source::{FileList, Item, Role, Sink, Source};
use crate::stream::StreamFrames;
use crate::transfer::Curve;
use crate::watch::WatchFolder;
use crate::window::window_range;

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1000.0
}

/// Absolute, normalised form of a path that may not exist yet (its existing ancestor is canonicalised).
fn absolute(p: &Path) -> PathBuf {
    let abs = std::path::absolute(p).unwrap_or_else(|_| p.to_owned());
    let mut existing = abs.as_path();
    let mut rest = Vec::new();
    loop {
        if let Ok(c) = existing.canonicalize() {
            let mut out = c;
            for r in rest.iter().rev() {
                out.push(r);
            }
            return out;
        }
        match (existing.parent(), existing.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_owned());
                existing = parent;
            }
            _ => return abs,
        }
    }
}

/// Refuse an output folder that would write into an input folder.
fn check_output_folder(out: &Path, inputs: &[(&str, &Path)]) -> Result<()> {
    let out_abs = absolute(out);
    for (what, dir) in inputs {
        let dir_abs = absolute(dir);
        if out_abs == dir_abs {
            return Err(Error::Usage(format!(
                "--out {} is the {what} folder: abysslight never writes over its inputs; choose another folder",
                out.display()
            )));
        }
        if out_abs.starts_with(&dir_abs) {
            return Err(Error::Usage(format!(
                "--out {} is inside the {what} folder {}: outputs would be read back as inputs; choose a folder \
                 outside it",
                out.display(),
                dir.display()
            )));
        }
    }
    Ok(())
}

/// Counts the full-resolution photos alive at once (decoded and not yet written or dropped).
#[derive(Default)]
struct LiveCount {
    now: AtomicUsize,
    peak: AtomicUsize,
}

impl LiveCount {
    fn enter(&self) -> Live<'_> {
        let v = self.now.fetch_add(1, Ordering::SeqCst) + 1;
        self.peak.fetch_max(v, Ordering::SeqCst);
        Live(self)
    }
}

/// Held beside each decoded photo; leaving scope marks the photo as freed.
struct Live<'a>(&'a LiveCount);

impl Drop for Live<'_> {
    fn drop(&mut self) {
        self.0.now.fetch_sub(1, Ordering::SeqCst);
    }
}

struct Decoded<'a> {
    item: Item,
    photo: Result<(Photo, Live<'a>)>,
    decode_ms: f64,
}

struct Waiting<'a> {
    seq: usize,
    item: Item,
    photo: Photo,
    _live: Live<'a>,
    decode_ms: f64,
    downsample_ms: f64,
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

/// Index of the first photo this shard must read: far enough back that `n − 1` usable photos precede its chunk
/// (a window reaches at most that far), or the start of the survey.
fn halo_start(entries: &[Entry], chunk_start: usize, n: usize) -> usize {
    let mut usable = 0;
    let mut layout = None;
    let mut i = chunk_start;
    while i > 0 && usable + 1 < n {
        i -= 1;
        if let Ok(p) = decode(&entries[i].path) {
            if *layout.get_or_insert(p.layout) == p.layout {
                usable += 1;
            }
        }
    }
    i
}

struct WriteJob<'a> {
    photo: Photo,
    frame: FrameReport,
    _live: Live<'a>,
}

/// Up to `most` entries spread evenly over `entries` (first and last included).
fn spread(entries: &[Entry], most: usize) -> Vec<Entry> {
    spread_indices(entries.len(), most)
        .into_iter()
        .map(|i| entries[i].clone())
        .collect()
}

/// Up to `most` indices spread evenly over `0..n` (first and last included).
fn spread_indices(n: usize, most: usize) -> Vec<usize> {
    if n <= most {
        return (0..n).collect();
    }
    (0..most).map(|i| i * (n - 1) / (most - 1).max(1)).collect()
}

/// Output path of a survey photo.
pub fn output_path(out: &Path, entry: &Entry) -> PathBuf {
    out.join(&entry.relative)
}

/// Run `abysslight correct` as described by `opts`.
pub fn correct_mission(opts: &Options, progress: &dyn Progress) -> Result<Report> {
    opts.validate()?;
    match opts.threads {
        Some(t) => rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .map_err(|e| Error::Usage(format!("cannot start {t} threads: {e}")))?
            .install(|| run(opts, progress)),
        None => run(opts, progress),
    }
}

fn run(opts: &Options, progress: &dyn Progress) -> Result<Report> {
    let started = Instant::now();
    let survey = opts
        .survey
        .as_deref()
        .ok_or_else(|| Error::Usage("--survey is required".into()))?;
    let out = opts
        .out
        .as_deref()
        .ok_or_else(|| Error::Usage("--out is required".into()))?;
    // Live and video input (src/watch.rs, src/stream.rs): no list of photos up front.
    let stdin = survey == Path::new("-");
    let stdout = out == Path::new("-");
    let streaming = stdin || opts.watch;
    let mut inputs = Vec::new();
    if !stdin {
        inputs.push(("survey", survey));
    }
    if let Some(w) = opts.water_column.as_deref() {
        inputs.push(("water-column", w));
    }
    if !stdout {
        check_output_folder(out, &inputs)?;
    }
    let window = opts.window_choice()?;
    let n = window.n;
    let k = opts.downsample;

    let found = if streaming {
        if opts.watch && !survey.is_dir() {
            return Err(Error::Usage(format!(
                "--watch {}: not a folder",
                survey.display()
            )));
        }
        io::Found::default()
    } else {
        find_photos(survey)?
    };
    if !streaming && found.photos.is_empty() {
        return Err(Error::Usage(format!(
            "no photos ({}) found below {}",
            io::PHOTO_EXTENSIONS.join(", "),
            survey.display()
        )));
    }
    let mut warnings = Vec::new();
    let warn = |warnings: &mut Vec<String>, m: String| {
        progress.warn(&m);
        warnings.push(m);
    };
    if !found.ignored.is_empty() {
        warn(
            &mut warnings,
            format!(
                "{} file(s) in {} are not photos by name and were passed over (e.g. {})",
                found.ignored.len(),
                survey.display(),
                found.ignored[0].display()
            ),
        );
    }
    // With --out - there is no output folder and no run files (the report goes to --report).
    let work_dir: Option<PathBuf> = (!stdout).then(|| out.join(WORK_DIR));
    if let Some(w) = &work_dir {
        std::fs::create_dir_all(w).map_err(|e| Error::io(w, e))?;
    }

    // --- S -------------------------------------------------------------------------------------------------
    let mut errors: Vec<FileError> = Vec::new();
    let mut water_column_failed = 0;
    let mut scatter_info = ScatterInfo {
        source: "none".into(),
        path: None,
        frames: 0,
        passes: 0,
        saved_to: None,
    };
    let scatter: Option<Scatter> = if let Some(path) = opts.scatter.as_deref() {
        progress.stage(&format!("loading scatter image {}", path.display()));
        scatter_info.source = "file".into();
        scatter_info.path = Some(path.to_owned());
        Some(Scatter::load(path)?)
    } else if let Some(dir) = opts.water_column.as_deref() {
        let wc = find_photos(dir)?;
        progress.stage(&format!(
            "estimating scatter S from {} water-column frames in {}",
            wc.photos.len(),
            dir.display()
        ));
        scatter_info.source = "water-column".into();
        scatter_info.path = Some(dir.to_owned());
        let budget = opts.scatter_memory_mib.max(1) << 20;
        let s = scatter::estimate(&wc.photos, budget, |e| {
            progress.file_error(&e);
            water_column_failed += 1;
            errors.push(FileError::from_error(error_path(&e), &e));
        })?;
        match &s {
            Some(s) => {
                scatter_info.frames = s.frames;
                scatter_info.passes = s.passes;
                if s.frames < 3 {
                    warn(
                        &mut warnings,
                        format!(
                            "only {} usable water-column frame(s): the median cannot reject particles with fewer \
                             than 3",
                            s.frames
                        ),
                    );
                }
            }
            None => warn(
                &mut warnings,
                format!(
                    "no usable water-column frames in {}: continuing with S = 0 (no backscatter removal)",
                    dir.display()
                ),
            ),
        }
        s
    } else {
        warn(
            &mut warnings,
            "no --water-column or --scatter given: assuming no backscatter (S = 0)".into(),
        );
        None
    };
    if let (Some(s), true, Some(work_dir)) = (&scatter, opts.save_scatter, &work_dir) {
        let p = work_dir.join("scatter.png");
        io::save_raster_png16(&s.full, &p)?;
        scatter_info.saved_to = Some(p);
    }

    // --- static regions (--mask, --mask-auto) ----------------------------------------------------------------
    let mut mask: Option<Mask> = match opts.mask.as_deref() {
        Some(p) => {
            let m = Mask::load(p)?;
            progress.stage(&format!(
                "mask {}: {} pixels ignored",
                p.display(),
                m.count()
            ));
            Some(m)
        }
        None => None,
    };
    if opts.mask_auto {
        let sample: Vec<Entry> = spread(&found.photos, 45);
        // Medians of the three thirds of the mission: static content shows in all of them.
        let parts = if sample.len() >= 9 { 3 } else { 1 };
        progress.stage(&format!(
            "looking for static pixels (overlays, lasers) in {} photos spread over the mission",
            sample.len()
        ));
        if parts == 1 {
            warn(
                &mut warnings,
                format!(
                    "--mask-auto had only {} photos to compare: the mask may include coincidental dark spots",
                    sample.len()
                ),
            );
        }
        let budget = opts.scatter_memory_mib.max(1) << 20;
        let mut medians = Vec::new();
        for p in 0..parts {
            let part = &sample[p * sample.len() / parts..(p + 1) * sample.len() / parts];
            if let Some(m) = scatter::estimate(part, budget, |_| {})? {
                medians.push(m.full);
            }
        }
        if !medians.is_empty() && medians.iter().all(|m| m.layout() == medians[0].layout()) {
            let found_mask = detect_static(&medians, DetectSettings::default());
            let p = work_dir
                .as_deref()
                .unwrap_or(Path::new("."))
                .join("mask-auto.png");
            if work_dir.is_some() {
                found_mask.save(&p)?;
            }
            let share = found_mask.count() as f64 / found_mask.ignore.len().max(1) as f64;
            progress.stage(&format!(
                "static pixels found: {:.2} % of the frame, written to {}",
                100.0 * share,
                p.display()
            ));
            match &mut mask {
                Some(m) if (m.width, m.height) == (found_mask.width, found_mask.height) => {
                    m.union(&found_mask)
                }
                Some(_) => {}
                None => mask = Some(found_mask),
            }
        }
    }
    if let (Some(m), Some(s)) = (&mask, &scatter) {
        m.check(
            s.full.layout(),
            opts.mask.as_deref().unwrap_or(Path::new("mask-auto.png")),
        )?;
    }

    // --- S at block resolution in linear light, and at full resolution prepared for the correction pass -------
    let transfer = opts.transfer;
    let scatter_low_codes = scatter.as_ref().map(|s| {
        let mut low = match &mask {
            Some(m) => block_median_masked(&s.full.to_u16(), s.full.layout(), k, m),
            None => s.downsampled(k),
        };
        fill_missing(&mut low);
        low
    });
    let scatter_prepared: Option<Prepared> =
        scatter.as_ref().map(|s| match (&mask, &scatter_low_codes) {
            // Under the mask, S holds whatever is burned into the water-column frames too: use the smooth fill.
            (Some(m), Some(low)) => {
                let mut full = s.full.clone();
                let smooth = crate::factor::upsample(low, k, full.width, full.height);
                let c = full.channels;
                for (p, _) in m.ignore.iter().enumerate().filter(|(_, &i)| i) {
                    full.data[p * c..(p + 1) * c].copy_from_slice(&smooth.data[p * c..(p + 1) * c]);
                }
                Prepared::new(&full, transfer)
            }
            _ => Prepared::new(&s.full, transfer),
        });
    let scatter_low = scatter_low_codes.map(|mut low| {
        for v in &mut low.data {
            *v = transfer.to_linear(*v);
        }
        low
    });
    drop(scatter);
    let curves = (Curve::new(transfer, 256), Curve::new(transfer, 65536));
    // Baseline `--method mean` needs the whole mission's mean before the stream.
    if streaming && opts.method == Method::Mean {
        return Err(Error::Usage(
            "--method mean needs every photo of the mission before it corrects the first; it cannot be used with \
             --watch or --survey -"
                .into(),
        ));
    }
    let mission_mean = match opts.method {
        Method::Mean => Some(crate::baseline::mission_mean(
            &found.photos,
            k,
            transfer,
            progress,
        )?),
        _ => None,
    };

    // --- which photos to read and which to write ---------------------------------------------------------------
    let total_files = found.photos.len();
    let chunk = opts.shard.map_or(0..total_files, |s| s.range(total_files));
    let first = if chunk.start > 0 {
        halo_start(&found.photos, chunk.start, n)
    } else {
        0
    };
    let mut skipped_existing = 0usize;
    let items: Vec<Item> = found.photos[first..]
        .iter()
        .enumerate()
        .map(|(j, entry)| {
            let i = first + j;
            let role = if !chunk.contains(&i) {
                Role::Halo
            } else if opts.resume && output_complete(&output_path(out, entry)) {
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
    let total_items = if streaming { usize::MAX } else { items.len() };
    let source: Box<dyn Source> = if stdin {
        progress.stage("reading frames from stdin (PPM, PGM or PNG, back to back)");
        Box::new(StreamFrames::new(std::io::BufReader::with_capacity(
            1 << 20,
            std::io::stdin(),
        )))
    } else if opts.watch {
        progress.stage(&format!(
            "watching {} for photos (scan every {} ms{}; stop with Ctrl-C or SIGTERM)",
            survey.display(),
            opts.poll_interval,
            opts.idle_timeout
                .map(|t| format!(", stop after {t} s without new files"))
                .unwrap_or_default()
        ));
        Box::new(WatchFolder::new(
            survey,
            Duration::from_millis(opts.poll_interval),
            opts.idle_timeout.map(Duration::from_secs_f64),
            crate::watch::stop_flag(),
        ))
    } else {
        // Two decoders on two cores: one alone would have to keep up with everything else on a shared core.
        let decoders = opts
            .threads
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |p| p.get()))
            .clamp(1, 4);
        Box::new(FileList::parallel(items, decoders))
    };
    let sink = if stdout {
        Sink::Stdout
    } else {
        Sink::Folder {
            carry_metadata: !stdin,
        }
    };
    // The stream can stop once every photo of the chunk has been handled.
    let last_needed = chunk.end.saturating_sub(first);
    if let Some(s) = opts.shard {
        progress.stage(&format!(
            "shard {}/{}: photos {}..{} of {} (reading {} before and up to {} after for the windows)",
            s.index,
            s.count,
            chunk.start + 1,
            chunk.end,
            total_files,
            chunk.start - first,
            n - 1
        ));
    }
    if skipped_existing > 0 {
        progress.stage(&format!(
            "resuming: {skipped_existing} photo(s) already have complete outputs and are read for the windows only"
        ));
    }

    // --- the survey stream -----------------------------------------------------------------------------------
    let to_handle = chunk.len();
    if streaming {
        progress.stage(&format!(
            "correcting survey photos as they come (window n = {n}: each photo once the {} after it are in; \
             blocks {k}x{k})",
            n / 2
        ));
    } else {
        progress.stage(&format!(
            "correcting {} survey photos (window n = {n}, blocks {k}x{k})",
            to_handle - skipped_existing
        ));
    }
    progress.start(to_handle);
    // Frames on stdout must leave in order: one writer, fed in order.
    let writers = if stdout {
        1
    } else {
        opts.threads
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |p| p.get()))
            .max(1)
    };
    let settings = EncodeSettings {
        jpeg_quality: opts.jpeg_quality,
        png_compression: opts.png_compression,
    };
    let done: Mutex<Vec<FrameReport>> = Mutex::new(Vec::new());
    let write_errors: Mutex<Vec<FileError>> = Mutex::new(Vec::new());
    let mut totals = CorrectStats::default();
    let mut layout: Option<Layout> = None;
    let mut survey_failed = 0usize;
    let live = LiveCount::default();
    let mut flagged_lit: Vec<(usize, Raster)> = Vec::new();
    let mut streamed = 0usize;

    let stream_result: Result<()> = std::thread::scope(|scope| {
        let (dec_tx, dec_rx) = bounded::<Decoded<'_>>(1);
        let (wr_tx, wr_rx) = bounded::<WriteJob<'_>>(writers);
        let live = &live;
        let mut source = source;
        scope.spawn(move || {
            while let Some((item, photo, decode_ms)) = source.next_photo() {
                let d = Decoded {
                    item,
                    photo: photo.map(|p| (p, live.enter())),
                    decode_ms,
                };
                if dec_tx.send(d).is_err() {
                    break;
                }
            }
        });
        for _ in 0..writers {
            let rx = wr_rx.clone();
            let (done, write_errors, sink) = (&done, &write_errors, &sink);
            scope.spawn(move || {
                for mut job in rx {
                    let t = Instant::now();
                    // The input's EXIF, XMP and ICC go into the output; metadata problems only warn.
                    let (input, output) = (&job.frame.input, &job.frame.output);
                    let warn = |m: &str| progress.warn(m);
                    let r = sink.write(&job.photo, input, output, settings, &warn);
                    job.frame.encode_ms = ms(t);
                    progress.photo_done(&job.frame.input, r.is_ok());
                    match r {
                        Ok(()) => done.lock().unwrap().push(job.frame),
                        Err(e) => {
                            progress.file_error(&e);
                            write_errors
                                .lock()
                                .unwrap()
                                .push(FileError::from_error(&job.frame.input, &e));
                            // Nobody reads stdout any more (e.g. the downstream ffmpeg ended): stop the run
                            // instead of failing every remaining frame.
                            if matches!(sink, Sink::Stdout) && matches!(e, Error::Io { .. }) {
                                break;
                            }
                        }
                    }
                }
            });
        }
        drop(wr_rx);

        let mut ring: VecDeque<(usize, Raster)> = VecDeque::with_capacity(n + 1);
        let mut waiting: VecDeque<Waiting> = VecDeque::new();
        let mut seq = 0usize;
        let mut ctx = Ctx {
            n,
            k,
            opts,
            colour: Vec::new(),
            scatter: scatter_prepared.as_ref(),
            scatter_low: scatter_low.as_ref(),
            mask: mask.as_ref(),
            curves: &curves,
            mission_mean: mission_mean.as_ref(),
            monitor: Monitor::new(Thresholds::default()).with_window(n),
            flagged_lit: Vec::new(),
            out,
            work_dir: work_dir.as_deref(),
            progress,
        };
        let mut fail = |errors: &mut Vec<FileError>, item: &Item, e: Error| {
            // A halo photo belongs to another shard, which reports it.
            if item.role != Role::Halo {
                progress.file_error(&e);
                errors.push(FileError::from_error(&item.entry.path, &e));
                survey_failed += 1;
                progress.photo_done(&item.entry.path, false);
            }
        };
        let mut reached_end = true;
        for d in dec_rx {
            streamed += 1;
            let path = &d.item.entry.path;
            let index = d.item.index;
            match d.photo {
                Err(e) => fail(&mut errors, &d.item, e),
                Ok((photo, photo_live)) => {
                    let mismatch = match layout {
                        None => {
                            if let Some(s) = &scatter_prepared {
                                if s.layout != photo.layout {
                                    return Err(Error::Mismatch {
                                        path: scatter_info.path.clone().unwrap_or_default(),
                                        reason: format!(
                                            "scatter estimate is {}, but the survey photos are {} ({}): \
                                             water-column frames and survey photos must come from the same camera",
                                            s.layout,
                                            photo.layout,
                                            path.display()
                                        ),
                                    });
                                }
                            }
                            if let Some(m) = &mask {
                                m.check(
                                    photo.layout,
                                    opts.mask.as_deref().unwrap_or(Path::new("mask-auto.png")),
                                )?;
                            }
                            layout = Some(photo.layout);
                            ctx.colour = opts
                                .seafloor_colour
                                .for_channels(photo.layout.channels)
                                .into_iter()
                                .map(|c| transfer.to_linear(c))
                                .collect();
                            None
                        }
                        Some(l) if l != photo.layout => Some(Error::Mismatch {
                            path: path.clone(),
                            reason: format!(
                                "photo is {}, the mission's photos are {}; skipped (split mixed missions into \
                                 one folder per camera setting)",
                                photo.layout, l
                            ),
                        }),
                        _ => None,
                    };
                    if let Some(e) = mismatch {
                        fail(&mut errors, &d.item, e);
                    } else {
                        let t = Instant::now();
                        let l = photo.layout;
                        let mut low = match (&photo.samples, &mask) {
                            (Samples::U8(v), None) => {
                                block_median(v, l.width, l.height, l.channels, k)
                            }
                            (Samples::U16(v), None) => {
                                block_median(v, l.width, l.height, l.channels, k)
                            }
                            (Samples::U8(v), Some(m)) => block_median_masked(v, l, k, m),
                            (Samples::U16(v), Some(m)) => block_median_masked(v, l, k, m),
                        };
                        if !transfer.is_linear() {
                            for v in &mut low.data {
                                *v = transfer.to_linear(*v);
                            }
                        }
                        ring.push_back((seq, low));
                        if ring.len() > n {
                            ring.pop_front();
                        }
                        waiting.push_back(Waiting {
                            seq,
                            item: d.item,
                            photo,
                            _live: photo_live,
                            decode_ms: d.decode_ms,
                            downsample_ms: ms(t),
                        });
                        seq += 1;
                        ctx.flush(&mut waiting, &ring, seq, false, &wr_tx, &mut totals)?;
                    }
                }
            }
            // A shard stops reading once every photo of its chunk has been corrected.
            if index + 1 >= last_needed && waiting.iter().all(|w| w.item.role == Role::Halo) {
                reached_end = index + 1 == total_items;
                break;
            }
        }
        if reached_end {
            ctx.flush(&mut waiting, &ring, seq, true, &wr_tx, &mut totals)?;
            if seq > 0 && seq < n {
                let m = format!(
                    "only {seq} usable survey photo(s), fewer than the window n = {n}: every photo's F is the \
                     median of all of them"
                );
                progress.warn(&m);
                warnings.push(m);
            }
        }
        drop(wr_tx);
        flagged_lit = std::mem::take(&mut ctx.flagged_lit);
        Ok(())
    });
    progress.finish();
    stream_result?;

    let mut frames = done.into_inner().unwrap();
    frames.sort_by_key(|f| f.index);
    let mut monitor = Summary::default();
    for f in &frames {
        monitor.add(&f.health.flags);
    }
    if let (false, Some(work_dir)) = (frames.is_empty(), &work_dir) {
        let name = match opts.shard {
            Some(s) => format!("overview-shard-{}-of-{}.png", s.index, s.count),
            None => "overview.png".into(),
        };
        overview::save_png(
            &overview::overview(&frames, &Thresholds::default()),
            &work_dir.join(name),
        )?;
        let picks = spread_indices(flagged_lit.len(), 6);
        let rows: Vec<(&FrameReport, &Raster)> = picks
            .iter()
            .filter_map(|&j| {
                let (index, lit) = &flagged_lit[j];
                frames.iter().find(|f| f.index == *index).map(|f| (f, lit))
            })
            .collect();
        if let Some(sheet) = overview::flagged_sheet(&rows, 320) {
            let name = match opts.shard {
                Some(s) => format!("flagged-shard-{}-of-{}.png", s.index, s.count),
                None => "flagged.png".into(),
            };
            overview::save_png(&sheet, &work_dir.join(name))?;
        }
    }
    let write_errors = write_errors.into_inner().unwrap();
    survey_failed += write_errors.len();
    errors.extend(write_errors);
    let mut report = Report {
        tool: "abysslight".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        options: opts.clone(),
        window,
        layout,
        scatter: scatter_info,
        survey_photos: if streaming { streamed } else { total_files },
        corrected: frames.len(),
        skipped_existing,
        peak_photos_in_memory: live.peak.load(Ordering::SeqCst),
        failed: survey_failed,
        water_column_failed,
        ignored_files: found.ignored.len(),
        floored_pixels: totals.floored_pixels,
        clipped_samples: totals.clipped_samples,
        monitor,
        frames,
        errors,
        warnings,
        elapsed_s: started.elapsed().as_secs_f64(),
        report_path: None,
    };
    let report_path = opts.report.clone().or_else(|| {
        work_dir.as_ref().map(|w| {
            w.join(match opts.shard {
                Some(s) => format!("report-shard-{}-of-{}.json", s.index, s.count),
                None => "report.json".into(),
            })
        })
    });
    if let Some(report_path) = report_path {
        report.report_path = Some(report_path.clone());
        io::write_with(&report_path, |w| {
            serde_json::to_writer_pretty(w, &report).map_err(|e| Error::Encode {
                path: report_path.clone(),
                reason: e.to_string(),
            })
        })?;
    }
    Ok(report)
}

/// What [`estimate_scatter_file`] did.
#[derive(Debug, Clone, Copy)]
pub struct ScatterRun {
    pub frames: usize,
    pub failed: usize,
}

/// `abysslight scatter`: estimate `S` from a folder of water-column frames and write it as a 16-bit PNG.
pub fn estimate_scatter_file(
    water_column: &Path,
    out: &Path,
    memory_mib: usize,
    progress: &dyn Progress,
) -> Result<ScatterRun> {
    check_output_folder(out, &[("water-column", water_column)])?;
    let wc = find_photos(water_column)?;
    progress.stage(&format!(
        "estimating scatter S from {} water-column frames in {}",
        wc.photos.len(),
        water_column.display()
    ));
    let mut failed = 0;
    let s = scatter::estimate(&wc.photos, memory_mib.max(1) << 20, |e| {
        progress.file_error(&e);
        failed += 1;
    })?
    .ok_or_else(|| {
        Error::Usage(format!(
            "no usable water-column frames in {}",
            water_column.display()
        ))
    })?;
    io::save_raster_png16(&s.full, out)?;
    Ok(ScatterRun {
        frames: s.frames,
        failed,
    })
}

fn error_path(e: &Error) -> &Path {
    match e {
        Error::Io { path, .. }
        | Error::Decode { path, .. }
        | Error::Mismatch { path, .. }
        | Error::Encode { path, .. }
        | Error::Config { path, .. } => path,
        Error::Usage(_) => Path::new(""),
    }
}

/// What the per-photo step needs besides the photo.
struct Ctx<'a> {
    n: usize,
    k: usize,
    opts: &'a Options,
    colour: Vec<f32>,
    scatter: Option<&'a Prepared>,
    scatter_low: Option<&'a Raster>,
    out: &'a Path,
    /// `None` with `--out -`.
    work_dir: Option<&'a Path>,
    progress: &'a dyn Progress,
    mask: Option<&'a Mask>,
    /// Transfer tables for 8- and 16-bit photos.
    curves: &'a (Curve, Curve),
    /// `M` of `--method mean` (block resolution, linear light).
    mission_mean: Option<&'a Raster>,
    monitor: Monitor,
    /// `F·C` of flagged photos (at most [`FLAGGED_KEPT`]), for the contact sheet.
    flagged_lit: Vec<(usize, Raster)>,
}

/// Flagged photos whose `F·C` is kept for the contact sheet (a few KB each).
const FLAGGED_KEPT: usize = 200;

impl Ctx<'_> {
    /// Correct every waiting photo whose window is complete (all of them at the end of the stream).
    fn flush<'l>(
        &mut self,
        waiting: &mut VecDeque<Waiting<'l>>,
        ring: &VecDeque<(usize, Raster)>,
        decoded: usize,
        eof: bool,
        wr_tx: &crossbeam_channel::Sender<WriteJob<'l>>,
        totals: &mut CorrectStats,
    ) -> Result<()> {
        while let Some(front) = waiting.front() {
            let i = front.seq;
            let range = if eof {
                window_range(i, self.n, decoded)
            } else {
                let s = i.saturating_sub(self.n / 2);
                s..s + self.n
            };
            if !eof && decoded < range.end {
                break;
            }
            let mut w = waiting.pop_front().unwrap();
            let entry = &w.item.entry;
            match w.item.role {
                Role::Write => {}
                Role::Halo => continue,
                Role::Done => {
                    self.progress.photo_done(&entry.path, true);
                    continue;
                }
            }
            let t = Instant::now();
            let stack: Vec<&Raster> = ring
                .iter()
                .filter(|(s, _)| range.contains(s))
                .map(|(_, r)| r)
                .collect();
            debug_assert_eq!(
                stack.len(),
                range.len(),
                "ring buffer lost a frame of the window"
            );
            let own = ring
                .iter()
                .find(|(s, _)| *s == i)
                .map(|(_, r)| r)
                .expect("a photo's own low-resolution image is in its window");
            let m = match (self.opts.method, self.mission_mean) {
                (Method::Mean, Some(mean)) if mean.layout() == own.layout() => mean.clone(),
                (Method::Polynomial, _) => {
                    crate::baseline::polynomial_m(own, self.scatter_low, self.opts.degree)
                }
                _ => stack_median(&stack),
            };
            let mut f = factor(&m, self.scatter_low, &self.colour);
            if self.mask.is_some() {
                fill_missing(&mut f);
            }
            let lit = lit_seafloor(&f, &self.colour);
            let mut health = self.monitor.observe_photo(own, &lit, self.scatter_low, &f);
            if eof && decoded < self.n {
                health.flags.push(Flag::ShortMission {
                    photos: decoded,
                    window: self.n,
                });
            }
            if !health.flags.is_empty() && self.flagged_lit.len() < FLAGGED_KEPT {
                self.flagged_lit.push((i, lit.clone()));
            }
            let estimate_ms = w.downsample_ms + ms(t);
            if let (true, Some(work_dir)) = (self.opts.save_factors, self.work_dir) {
                let p = work_dir
                    .join("factors")
                    .join(&entry.relative)
                    .with_extension("png");
                io::save_raster_png16(&lit, &p)?;
            }
            let t = Instant::now();
            let l = w.photo.layout;
            let floor = self.opts.factor_floor;
            let (c8, c16) = self.curves;
            let stats = match &mut w.photo.samples {
                Samples::U8(v) => correct_in_place(v, l, self.scatter, &f, self.k, floor, c8),
                Samples::U16(v) => correct_in_place(v, l, self.scatter, &f, self.k, floor, c16),
            };
            *totals += stats;
            let frame = FrameReport {
                output: output_path(self.out, entry),
                input: entry.path.clone(),
                index: i,
                window: [range.start, range.end - 1],
                decode_ms: w.decode_ms,
                estimate_ms,
                correct_ms: ms(t),
                encode_ms: 0.0,
                floored_pixels: stats.floored_pixels,
                clipped_samples: stats.clipped_samples,
                health,
            };
            if wr_tx
                .send(WriteJob {
                    photo: w.photo,
                    frame,
                    _live: w._live,
                })
                .is_err()
            {
                return Err(Error::Usage(if self.out == Path::new("-") {
                    "stdout was closed (is the program reading the frames still running?)".into()
                } else {
                    "all output writers stopped".into()
                }));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_inside_input_is_refused() {
        let d = tempfile::tempdir().unwrap();
        let survey = d.path().join("survey");
        std::fs::create_dir_all(&survey).unwrap();
        assert!(check_output_folder(&survey, &[("survey", &survey)]).is_err());
        assert!(check_output_folder(&survey.join("out"), &[("survey", &survey)]).is_err());
        assert!(check_output_folder(&survey.join("./x/../"), &[("survey", &survey)]).is_err());
        assert!(check_output_folder(&d.path().join("out"), &[("survey", &survey)]).is_ok());
        assert!(check_output_folder(&d.path().join("survey2"), &[("survey", &survey)]).is_ok());
    }
}
