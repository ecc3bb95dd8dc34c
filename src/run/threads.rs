//! The survey stream of a run, on threads:
//!
//! 1. a source (decoder threads for a folder, as many as worker threads; a watched folder; stdin) hands photos
//!    over in order (bounded queue);
//! 2. this thread gives them to the [`Engine`], which keeps the sliding window and corrects each photo once its
//!    window is complete (rayon over rows inside);
//! 3. writer threads encode and write outputs atomically (bounded queue).
//!
//! Memory: the engine's window (at most `n` low-resolution images, at most `n` full-resolution photos waiting at
//! the start of a mission, `n/2 + 1` later), plus the few in the decode and write queues. It does not grow with
//! the number of photos.

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crossbeam_channel::{bounded, Receiver, Sender};

use crate::error::{Error, Result};
use crate::io::paths::check_no_links_below;
use crate::io::EncodeSettings;
use crate::method::correct::CorrectStats;
use crate::method::engine::{too_few_warning, Corrected, Engine, Found, Use};
use crate::method::raster::{Layout, Photo, Raster};
use crate::report::{FileError, FrameReport, Progress};
use crate::run::options::Options;
use crate::run::plan::Plan;
use crate::run::source::{FileList, Item, Role, Sink, Source};
use crate::run::stdin::StreamFrames;
use crate::run::watch::WatchFolder;

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1000.0
}

/// Counts the full-resolution photos alive at once (decoded and not yet written or dropped).
#[derive(Default)]
struct LiveCount {
    now: AtomicUsize,
    peak: AtomicUsize,
}

impl LiveCount {
    fn enter(self: &Arc<Self>) -> Live {
        let v = self.now.fetch_add(1, Ordering::SeqCst) + 1;
        self.peak.fetch_max(v, Ordering::SeqCst);
        Live(self.clone())
    }
}

/// Held beside each decoded photo; leaving scope marks the photo as freed.
struct Live(Arc<LiveCount>);

impl Drop for Live {
    fn drop(&mut self) {
        self.0.now.fetch_sub(1, Ordering::SeqCst);
    }
}

/// What the run pushes into the engine with each photo.
pub struct Tag {
    item: Item,
    decode_ms: f64,
    /// Held while the full-resolution photo exists (photos the engine only estimates are dropped at once).
    live: Option<Live>,
}

struct WriteJob {
    photo: Photo,
    frame: FrameReport,
    _live: Option<Live>,
}

/// Most `F·C` images of flagged photos kept for the contact sheet (2 MB each at 12 MP), spread over the mission.
const FLAGGED_KEPT: usize = 24;

/// Keeps `F·C` of at most [`FLAGGED_KEPT`] flagged photos, spread evenly over all flagged so far: when full, every
/// second one is dropped and from then on only every second flagged photo is taken (memory stays bounded
/// whatever the mission's length).
#[derive(Default)]
struct FlaggedSample {
    kept: Vec<(usize, Raster)>,
    seen: usize,
    stride: usize,
}

impl FlaggedSample {
    fn offer(&mut self, index: usize, lit: &Raster) {
        let stride = self.stride.max(1);
        if self.seen.is_multiple_of(stride) {
            if self.kept.len() == FLAGGED_KEPT {
                let mut i = 0;
                self.kept.retain(|_| {
                    i += 1;
                    i % 2 == 1
                });
                self.stride = stride * 2;
            }
            if self.seen.is_multiple_of(self.stride.max(1)) {
                self.kept.push((index, lit.clone()));
            }
        }
        self.seen += 1;
    }
}

/// The indices of the flagged photos whose `F·C` a run keeps for its sheet, the flagged photos' `indices` given
/// in mission order (for `abysslight merge-shards`, which picks what one run would have picked).
pub(crate) fn flagged_sample(indices: &[usize]) -> Vec<usize> {
    let none = Raster::filled(0, 0, 1, 0.0);
    let mut sample = FlaggedSample::default();
    for &i in indices {
        sample.offer(i, &none);
    }
    sample.kept.into_iter().map(|(i, _)| i).collect()
}

/// What the survey stream did.
#[derive(Default)]
pub struct Outcome {
    /// Photos corrected and written, and (with `--resume`) photos whose output existed, in order.
    pub frames: Vec<FrameReport>,
    /// Survey photos that failed, with the reason.
    pub errors: Vec<FileError>,
    /// Photos the source handed over.
    pub streamed: usize,
    /// The mission's photo size.
    pub layout: Option<Layout>,
    /// Sum over the corrected photos.
    pub totals: CorrectStats,
    /// Most full-resolution photos held at once.
    pub peak_photos: usize,
    /// `F·C` of some flagged photos, by index.
    pub flagged_lit: Vec<(usize, Raster)>,
    /// What the user should know.
    pub warnings: Vec<String>,
}

/// The source of survey photos the options ask for.
fn source(opts: &Options, plan: &Plan, progress: &dyn Progress) -> Box<dyn Source> {
    if plan.stdin {
        progress.stage("reading frames from stdin (PPM, PGM or PNG, back to back)");
        Box::new(StreamFrames::new(std::io::BufReader::with_capacity(
            1 << 20,
            std::io::stdin(),
        )))
    } else if opts.watch {
        progress.stage(&format!(
            "watching {} for photos (scan every {} ms{}; stop with Ctrl-C or SIGTERM)",
            plan.survey.display(),
            opts.poll_interval,
            opts.idle_timeout
                .map(|t| format!(", stop after {t} s without new files"))
                .unwrap_or_default()
        ));
        Box::new(
            WatchFolder::new(
                &plan.survey,
                Duration::from_millis(opts.poll_interval),
                opts.idle_timeout.map(Duration::from_secs_f64),
                crate::run::watch::stop_flag(),
            )
            .excluding(&plan.out),
        )
    } else {
        // Two decoders on two cores: one alone would have to keep up with everything else on a shared core.
        Box::new(FileList::expecting(
            plan.items.clone(),
            threads(opts).clamp(1, 4),
            plan.photo_size,
        ))
    }
}

/// Worker threads: `--threads`, or all cores.
fn threads(opts: &Options) -> usize {
    opts.threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |p| p.get()))
        .max(1)
}

/// A decoded photo on its way from the reader thread: the item, the photo with its live count, the decode time.
type Decoded = (Item, Result<(Photo, Live)>, f64);

/// The engine's side of the stream: photos in, corrected photos to the writers, the rest recorded.
struct Feed<'a> {
    opts: &'a Options,
    plan: &'a Plan,
    progress: &'a dyn Progress,
    wr_tx: Sender<WriteJob>,
    /// Photos pushed that are this run's own (not halo) and not yet out of the engine.
    pending: usize,
    outcome: Outcome,
    resumed: Vec<FrameReport>,
    flagged: FlaggedSample,
    /// The paths of laser dots the engine found in the stream were said (a run over a folder says them before).
    lasers_said: bool,
}

impl Feed<'_> {
    fn fail(&mut self, path: &Path, role: Role, e: Error) {
        // A halo photo belongs to another shard, which reports it.
        if role != Role::Halo {
            self.progress.file_error(&e);
            self.outcome.errors.push(FileError::from_error(path, &e));
            self.progress.photo_done(path, false);
        }
    }

    /// Push every decoded photo from the channel until the stream or the chunk ends; true if the stream ended.
    fn drain(
        &mut self,
        engine: &mut Engine<Tag>,
        dec_rx: Receiver<Decoded>,
        last_needed: usize,
        total_items: usize,
    ) -> Result<bool> {
        let mut reached_end = true;
        for (item, photo, decode_ms) in dec_rx {
            if self.progress.cancelled() {
                return Err(Error::Usage(
                    "interrupted: the photos written so far are complete; run again with resume to finish"
                        .into(),
                ));
            }
            self.outcome.streamed += 1;
            let index = item.index;
            match photo {
                Err(e) => self.fail(&item.entry.path, item.role, e),
                Ok((photo, photo_live)) => self.push(engine, item, photo, photo_live, decode_ms)?,
            }
            // A shard stops reading once every photo of its chunk has been corrected.
            if index + 1 >= last_needed && self.pending == 0 {
                reached_end = index + 1 == total_items;
                break;
            }
        }
        Ok(reached_end)
    }

    /// Flush the engine if the stream ended, warn about a short mission, and hand back the outcome.
    fn finish(mut self, engine: &mut Engine<Tag>, reached_end: bool, n: usize) -> Result<Outcome> {
        if reached_end {
            let out = engine.finish();
            self.say_lasers(engine);
            self.emit(out)?;
            let seen = engine.accepted();
            // Under auto the windows fit the mission (the photos short of samples are flagged).
            if seen > 0 && seen < n && !engine.params().window_is_auto() {
                let m = format!(
                    "only {seen} usable survey photo(s), fewer than the window n = {n}: every photo's F is the \
                     median of all of them"
                );
                self.progress.warn(&m);
                self.outcome.warnings.push(m);
            }
        }
        self.outcome.layout = engine.layout();
        let mut outcome = self.outcome;
        outcome.frames = self.resumed;
        outcome.flagged_lit = self.flagged.kept;
        Ok(outcome)
    }

    /// Give one decoded photo to the engine and pass on what comes out.
    fn push(
        &mut self,
        engine: &mut Engine<Tag>,
        item: Item,
        photo: Photo,
        live: Live,
        decode_ms: f64,
    ) -> Result<()> {
        let use_ = match item.role {
            Role::Write => Use::Correct,
            Role::Done => Use::Estimate,
            Role::Halo => Use::Context,
        };
        let (path, role) = (item.entry.path.clone(), item.role);
        let tag = Tag {
            item,
            decode_ms,
            live: (use_ == Use::Correct).then_some(live),
        };
        let altitude = self.plan.altitude_of(&path);
        match engine.push((photo, tag, use_, altitude)) {
            Ok(out) => {
                self.pending += usize::from(role != Role::Halo);
                self.say_lasers(engine);
                self.emit(out)
            }
            // The first photo does not fit S or the mask: nothing of this mission can be corrected.
            Err(Error::Usage(reason)) => {
                let o = self.opts;
                Err(Error::Mismatch {
                    path: (o.scatter.clone())
                        .or_else(|| o.water_column.clone())
                        .or_else(|| o.mask.clone())
                        .unwrap_or_default(),
                    reason: format!("{reason} ({})", path.display()),
                })
            }
            Err(e) => {
                self.fail(&path, role, e.about(&path));
                Ok(())
            }
        }
    }

    /// Photos as they come (`--watch`, `--survey -`): once the engine found the paths of laser dots in the first
    /// photos, say so, and write their mask beside the report; or say that the mission was too short to find them.
    fn say_lasers(&mut self, engine: &Engine<Tag>) {
        if self.lasers_said || !self.plan.streaming {
            return;
        }
        let m = match (engine.lasers_found(), engine.layout()) {
            (Some(Found::Paths(p)), Some(l)) => {
                let saved = crate::run::prepare::save_laser_paths(
                    p,
                    engine.params().downsample,
                    (l.width, l.height),
                    self.plan,
                );
                crate::run::prepare::laser_note(p, saved)
            }
            (Some(Found::TooFew { photos }), _) => too_few_warning(*photos),
            _ => return,
        };
        self.lasers_said = true;
        self.progress.warn(&m);
        self.outcome.warnings.push(m);
    }

    /// Hand corrected photos to the writers; record the ones `--resume` found written.
    fn emit(&mut self, out: Vec<Corrected<Tag>>) -> Result<()> {
        for c in out {
            self.pending -= 1;
            let entry = &c.tag.item.entry;
            if !c.health.flags.is_empty() {
                self.flagged.offer(c.index, &c.lit);
            }
            let frame = FrameReport {
                output: self.plan.output_path(entry),
                input: entry.path.clone(),
                index: c.index,
                window: c.window,
                altitude: c.altitude,
                decode_ms: c.tag.decode_ms,
                estimate_ms: c.estimate_ms,
                correct_ms: c.correct_ms,
                encode_ms: 0.0,
                floored_pixels: c.stats.floored_pixels,
                clipped_samples: c.stats.clipped_samples,
                resumed: c.photo.is_none(),
                health: c.health.noted(),
                backscatter_scale: c.backscatter_scale,
                noise_sigma: c.noise.as_ref().map_or(Vec::new(), |n| {
                    n.noise_var.iter().map(|v| v.sqrt()).collect()
                }),
                texture_sigma: c.noise.as_ref().map_or(Vec::new(), |n| {
                    n.texture_var.iter().map(|v| v.sqrt()).collect()
                }),
                window_auto: c.choice.map(Into::into),
            };
            let Some(photo) = c.photo else {
                self.progress.photo_done(&entry.path, true);
                self.resumed.push(frame);
                continue;
            };
            if let (true, Some(work_dir)) = (self.opts.save_factors, &self.plan.work_dir) {
                let p = work_dir
                    .join("factors")
                    .join(&entry.relative)
                    .with_extension("png");
                // An 8-bit, enlarged preview beside the 16-bit data, for people to look at. A factor image that
                // cannot be written (disk full) is that file's error, not the mission's.
                let preview = crate::run::pictures::factor_preview(
                    &c.lit,
                    crate::run::pictures::PREVIEW_MIN_WIDTH,
                );
                let pp = work_dir
                    .join("factors-preview")
                    .join(&entry.relative)
                    .with_extension("png");
                if let Err(e) = crate::io::save_raster_png16(&c.lit, &p)
                    .and_then(|()| crate::run::pictures::save_png(&preview, &pp))
                {
                    self.progress.file_error(&e);
                    self.outcome.errors.push(FileError::from_error(&p, &e));
                }
            }
            self.outcome.totals += c.stats;
            let job = WriteJob {
                photo,
                frame,
                _live: c.tag.live,
            };
            if self.wr_tx.send(job).is_err() {
                return Err(Error::Usage(if self.plan.stdout {
                    "stdout was closed (is the program reading the frames still running?)".into()
                } else {
                    "all output writers stopped".into()
                }));
            }
        }
        Ok(())
    }
}

/// Read the survey once, in order, through `engine`, writing every photo of the plan.
pub fn stream(
    opts: &Options,
    plan: &Plan,
    mut engine: Engine<Tag>,
    progress: &dyn Progress,
) -> Result<Outcome> {
    let n = plan.window.n;
    let live = Arc::new(LiveCount::default());
    // Frames on stdout must leave in order: one writer, fed in order.
    let writers = if plan.stdout { 1 } else { threads(opts) };
    let settings: EncodeSettings = opts.encode_settings();
    let sink = if plan.stdout {
        Sink::Stdout
    } else {
        Sink::Folder {
            carry_metadata: !plan.stdin,
        }
    };
    let done: Mutex<Vec<FrameReport>> = Mutex::new(Vec::new());
    let write_errors: Mutex<Vec<FileError>> = Mutex::new(Vec::new());
    let total_items = if plan.streaming {
        usize::MAX
    } else {
        plan.items.len()
    };
    // The stream can stop once every photo of the chunk has been handled.
    let last_needed = plan.chunk.end.saturating_sub(plan.first);
    let mut source = source(opts, plan, progress);

    let mut outcome = std::thread::scope(|scope| -> Result<Outcome> {
        let (dec_tx, dec_rx) = bounded(1);
        let (wr_tx, wr_rx) = bounded::<WriteJob>(writers);
        let live = &live;
        scope.spawn(move || {
            while let Some((item, photo, decode_ms)) = source.next_photo() {
                let photo = photo.map(|p| (p, live.enter()));
                if dec_tx.send((item, photo, decode_ms)).is_err() {
                    break;
                }
            }
        });
        for _ in 0..writers {
            let rx = wr_rx.clone();
            let (done, write_errors, sink) = (&done, &write_errors, &sink);
            let out = (!plan.stdout).then_some(plan.out.as_path());
            scope.spawn(move || write_all(rx, done, write_errors, sink, out, settings, progress));
        }
        drop(wr_rx);

        let mut feed = Feed {
            opts,
            plan,
            progress,
            wr_tx,
            pending: 0,
            outcome: Outcome::default(),
            resumed: Vec::new(),
            flagged: FlaggedSample::default(),
            lasers_said: false,
        };
        let reached_end = feed.drain(&mut engine, dec_rx, last_needed, total_items)?;
        feed.finish(&mut engine, reached_end, n)
    });
    progress.finish();
    if let Ok(o) = &mut outcome {
        o.frames.extend(done.into_inner().unwrap_or_default());
        o.frames.sort_by_key(|f| f.index);
        o.errors
            .extend(write_errors.into_inner().unwrap_or_default());
        o.peak_photos = live.peak.load(Ordering::SeqCst);
    }
    outcome
}

/// A writer thread: encode and write each job atomically, carrying the input's metadata.
fn write_all(
    rx: crossbeam_channel::Receiver<WriteJob>,
    done: &Mutex<Vec<FrameReport>>,
    write_errors: &Mutex<Vec<FileError>>,
    sink: &Sink,
    out: Option<&Path>,
    settings: EncodeSettings,
    progress: &dyn Progress,
) {
    for job in rx {
        let t = Instant::now();
        // The input's EXIF, XMP and ICC go into the output; metadata problems only warn.
        let (input, output) = (&job.frame.input, &job.frame.output);
        let warn = |m: &str| progress.warn(m);
        // Never through a link inside --out (src/io/paths.rs).
        let r = out
            .map_or(Ok(()), |out| check_no_links_below(out, output))
            .and_then(|()| sink.write(&job.photo, input, output, settings, &warn));
        let WriteJob {
            photo,
            mut frame,
            _live: live,
        } = job;
        // The samples go to the next decode (src/io/buffers.rs), and the photo leaves the live count.
        crate::io::buffers::recycle(photo);
        drop(live);
        frame.encode_ms = ms(t);
        progress.photo_done(&frame.input, r.is_ok());
        match r {
            Ok(()) => lock(done).push(frame),
            Err(e) => {
                progress.file_error(&e);
                lock(write_errors).push(FileError::from_error(&frame.input, &e));
                // Nobody reads stdout any more (e.g. the downstream ffmpeg ended): stop the run instead of
                // failing every remaining frame.
                if matches!(sink, Sink::Stdout) && matches!(e, Error::Io { .. }) {
                    break;
                }
            }
        }
    }
}

/// A mutex's contents, also after a writer thread panicked while holding it.
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flagged_sample_stays_bounded_and_spread() {
        let lit = Raster::filled(2, 2, 1, 0.5);
        for n in [1usize, 10, 24, 25, 100, 1000] {
            let mut f = FlaggedSample::default();
            for i in 0..n {
                f.offer(i, &lit);
            }
            let idx: Vec<usize> = f.kept.iter().map(|(i, _)| *i).collect();
            assert!(idx.len() <= FLAGGED_KEPT, "{n}: {}", idx.len());
            assert!(idx.len() >= n.min(FLAGGED_KEPT / 2), "{n}: {idx:?}");
            assert_eq!(idx[0], 0);
            // Evenly spread: one stride between neighbours, the last within a stride of the end.
            let stride = idx.get(1).map_or(1, |b| b - idx[0]);
            assert!(
                idx.windows(2).all(|w| w[1] - w[0] == stride),
                "{n}: {idx:?}"
            );
            assert!(
                n - 1 - idx[idx.len() - 1] < stride.max(1) * 2,
                "{n}: {idx:?}"
            );
        }
    }
}
