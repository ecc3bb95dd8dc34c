//! Everything the [`Engine`] needs before the survey stream: `S` (from the water column or a saved image), the
//! mask of static pixels (`--mask`, `--mask-auto`) and, for `--method mean`, the mission's mean image.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::io::{decode_expecting, Entry};
use crate::method::baseline::{block_mean, Method};
use crate::method::engine::{too_few_warning, Engine, FirstPass, Found, Params, LASER_PHOTOS};
use crate::method::mask::{detect_static, DetectSettings, Mask};
use crate::method::outliers::{laser_spots, LaserPaths, SpotPath};
use crate::method::raster::{Layout, Raster};
use crate::method::scatter::Scatter;
use crate::method::steps::lasers;
use crate::method::stretch::{
    Choice, PhotoSurvey, Rule, Surveyor, MAX_AUTO_WINDOW, MEANS_CHECKED_EVERY, REFERENCE_HALF,
    STRETCH_HALF,
};
use crate::method::survey::Survey;
use crate::method::transfer::Transfer;
use crate::report::{FileError, Progress, ScatterInfo};
use crate::run::options::Options;
use crate::run::plan::Plan;
use crate::run::source::Item;

/// The engine of a run and what setting it up found.
pub struct Setup<T> {
    /// The method, ready for the survey stream.
    pub engine: Engine<T>,
    /// Where `S` came from.
    pub scatter: ScatterInfo,
    /// Water-column frames that failed.
    pub errors: Vec<FileError>,
    /// What the user should know.
    pub warnings: Vec<String>,
}

/// Collects warnings: each is shown as it happens and kept for the report.
struct Warnings<'a> {
    progress: &'a dyn Progress,
    list: Vec<String>,
}

impl Warnings<'_> {
    fn warn(&mut self, m: String) {
        self.progress.warn(&m);
        self.list.push(m);
    }
}

/// Estimate or load `S`, find the mask, and build the engine.
/// `params` are the run's, resolved ([`crate::method::params::Params::resolved`]).
pub fn prepare<T: Sync>(
    opts: &Options,
    params: &Params,
    plan: &Plan,
    progress: &dyn Progress,
) -> Result<Setup<T>> {
    let mut warnings = Warnings {
        progress,
        list: Vec::new(),
    };
    let mut errors = Vec::new();
    let (scatter, mut info) = scatter(opts, progress, &mut warnings, &mut errors)?;
    if let (Some(s), true, Some(work_dir)) = (&scatter, opts.save_scatter, &plan.work_dir) {
        let p = work_dir.join("scatter.png");
        s.save_png(&p)?;
        info.saved_to = Some(p);
    }
    let mask = mask(opts, params.curve(), plan, progress, &mut warnings)?;
    if let Some(m) = &mask {
        warn_if_most_is_hidden(m, &mut warnings);
    }
    if let (Some(m), Some(s)) = (&mask, &scatter) {
        m.check(s.layout, mask_path(opts))?;
    }
    let mut engine = Engine::new(*params, scatter.as_ref(), mask)?;
    drop(scatter);
    if plan.navigation.is_some() {
        engine.expect_altitudes()?;
    }
    // Photos as they come (`--watch`, standard input) are surveyed by the engine as it takes them; a folder is
    // surveyed first, from its JPEGs' block means where they stand for the block medians.
    if params.window_is_auto() && !plan.streaming {
        // With the paths of laser dots not left out (`--no-laser-paths`) and no mask, the survey looks for them
        // (a warning that names the fix).
        let lasers = opts.mask.is_none() && !opts.mask_auto && !params.steps.laser_paths;
        let mut first = engine.first_pass();
        let (survey, path) = survey(&first, plan, progress, lasers);
        progress.stage(&stretches_line(survey.choices()));
        first.set_survey(survey)?;
        if let Some(w) = lasers::kept_warning(&path) {
            warnings.warn(w);
        }
        // `--mask-auto` finds the paths over the whole mission itself.
        if params.steps.laser_paths && !opts.mask_auto {
            match laser_paths(&mut first, plan, progress)? {
                Found::Paths(p) => {
                    let saved = plan
                        .photo_size
                        .and_then(|size| save_laser_paths(&p, params.downsample, size, plan));
                    warnings.warn(laser_note(&p, saved));
                }
                Found::TooFew { photos } => warnings.warn(too_few_warning(photos)),
                Found::None => {}
            }
        }
    }
    if opts.method == Method::Mean {
        engine.first_pass().set_mission_mean(mission_mean(
            &plan.found.photos,
            plan.photo_size,
            opts.block(),
            params.curve(),
            progress,
        )?);
    }
    Ok(Setup {
        engine,
        scatter: info,
        errors,
        warnings: warnings.list,
    })
}

/// Photos after the last photo of the chunk the survey reads: the longest window's half and the stretch and
/// reference around it.
const SURVEY_AFTER: usize = MAX_AUTO_WINDOW / 2 + STRETCH_HALF + REFERENCE_HALF;

/// `--window auto`: the survey of the mission's block images before the correction (one more read of each photo
/// the run reads; memory: a few dozen block images) and each photo's window, quantile and near window
/// ([`crate::method::stretch`]). Photos that do not decode, or differ in size from the first, are passed over as
/// the correction's stream passes them over, so the choices follow the engine's numbering.
///
/// Baseline JPEGs with blocks of 8 (or a multiple) are read by their DC coefficients, the blocks' means, from the
/// completeness check whose verdict the correction's decode then takes, instead of being decoded for block
/// medians; one in [`MEANS_CHECKED_EVERY`] is decoded as well, and where its means do not see the dark blocks its
/// medians see (clutter as fine as the blocks) the survey starts again, decoding every photo.
///
/// With `lasers`, it also counts the laser-coloured bright spots of up to [`PATH_PHOTOS`] of the block medians it
/// takes (of every photo it decodes, one in [`MEANS_CHECKED_EVERY`] of those it reads by their means), spread over
/// the mission ([`SpotPath`], as `--mask-auto` does on photos it decodes for the purpose).
fn survey<T: Sync>(
    engine: &FirstPass<T>,
    plan: &Plan,
    progress: &dyn Progress,
    lasers: bool,
) -> (Survey, SpotPath) {
    let end = (plan.chunk.end + SURVEY_AFTER)
        .saturating_sub(plan.first)
        .min(plan.items.len());
    let items = &plan.items[..end];
    progress.stage(&format!(
        "--window auto: surveying {} photos for their dark share and the camera's motion",
        items.len()
    ));
    let spots_every = lasers.then(|| items.len().div_ceil(PATH_PHOTOS).max(1));
    let (photos, path) = match survey_pass(
        engine,
        plan,
        items,
        engine.takes_block_means(),
        spots_every,
    ) {
        Ok(surveyed) => surveyed,
        Err(photo) => {
            progress.stage(&format!(
                "--window auto: the block means of {} (its JPEG's DC coefficients) do not see the dark blocks its \
                 block medians see (clutter as fine as the blocks); surveying again, decoding every photo",
                photo.display()
            ));
            survey_pass(engine, plan, items, false, spots_every).unwrap_or_default()
        }
    };
    (Survey::of_mission(&photos), path)
}

/// The paths of laser dots in the mission's first [`LASER_PHOTOS`] photos that the engine accepts (that decode at
/// its size, of the first one's layout), as the engine finds them when it is given the photos as they come (its
/// block images: the blocks, mask and curve it takes), so that a run over a folder, `--watch`, `--survey -` and the
/// `Engine` leave the same blocks out of `F`; given to the engine. Every shard of a mission looks at the same
/// photos. One more decode of these photos.
fn laser_paths<T: Sync>(
    first: &mut FirstPass<T>,
    plan: &Plan,
    progress: &dyn Progress,
) -> Result<Found> {
    let photos = &plan.found.photos;
    progress.stage(&format!(
        "looking for the paths of laser dots in the first {} photos",
        LASER_PHOTOS.min(photos.len())
    ));
    // A photo that does not decode is passed over as the engine passes it over.
    first.find_laser_paths(photos.len(), |first, i| {
        let p = decode_expecting(&photos[i].path, plan.photo_size).ok()?;
        let low = first.block_image(&p);
        let layout = p.layout;
        crate::io::buffers::recycle(p);
        Some((layout, low?))
    })
}

/// The run's words on the paths of laser dots it leaves out of `F`, with where their mask was written.
pub(crate) fn laser_note(paths: &LaserPaths, saved: Option<PathBuf>) -> String {
    format!(
        "laser dots: red or green bright spots came back to the same blocks in the first {} photos, the paths of \
         laser dots ({:.1} % of the frame{}); they are left out of F, which is filled in from the seafloor around, \
         so the dots keep their colour and leave no stain (teal beside a red laser); --no-laser-paths keeps them \
         in F, --mask-auto looks over the whole mission",
        paths.photos,
        100.0 * paths.share(),
        saved
            .map(|p| format!("; mask written to {}", p.display()))
            .unwrap_or_default()
    )
}

/// `_abysslight/laser-paths.png`: the paths as a mask of the photos' size (`k`: the blocks), to look at and to reuse
/// with `--mask`; `None` when there is no work folder or it cannot be written (the note says nothing then).
pub(crate) fn save_laser_paths(
    paths: &LaserPaths,
    k: usize,
    (w, h): (usize, usize),
    plan: &Plan,
) -> Option<PathBuf> {
    let p = plan.work_dir.as_deref()?.join("laser-paths.png");
    (k > 0 && paths.blocks.len() == w.div_ceil(k) * h.div_ceil(k))
        .then(|| paths.to_mask(k, w, h).save(&p).ok())
        .flatten()
        .map(|_| p)
}

/// One pass of [`survey`] over `items`, baseline JPEGs read by their block means when `by_means`, the laser spots
/// of every `spots_every`-th block image counted; `Err` names the photo whose means and medians disagreed (the pass
/// stops there).
fn survey_pass<T: Sync>(
    engine: &FirstPass<T>,
    plan: &Plan,
    items: &[Item],
    by_means: bool,
    spots_every: Option<usize>,
) -> std::result::Result<(Vec<PhotoSurvey>, SpotPath), PathBuf> {
    // The survey's measures run in mission order on a thread of their own while the workers read and block-median
    // the next batch: the reads are most of the pass, and the measures would otherwise leave a core idle.
    let batch = (4 * rayon::current_num_threads()).max(4);
    let mut surveyor = Surveyor::new(engine.scatter_low());
    let mut disagreed = None;
    let surveyed = std::thread::scope(|scope| {
        let (send, receive) = std::sync::mpsc::sync_channel::<Vec<SurveyRead>>(1);
        let measures = scope.spawn(move || {
            let mut layout = None;
            let mut path = SpotPath::new();
            for reads in receive {
                for (low, spots) in reads {
                    // Only the photos of the mission's layout, as the engine takes them.
                    let Some((_, low)) = low.filter(|(l, _)| *layout.get_or_insert(*l) == *l)
                    else {
                        continue;
                    };
                    if let Some(spots) = spots {
                        path.add_spots((low.width, low.height), &spots);
                    }
                    surveyor.push(&low);
                }
            }
            (surveyor.finish(), path)
        });
        for (b, chunk) in items.chunks(batch).enumerate() {
            let read: Vec<(SurveyRead, bool)> = chunk
                .par_iter()
                .enumerate()
                .map(|(k, item)| {
                    let i = b * batch + k;
                    let (low, agreed, decoded) = survey_read(
                        engine,
                        plan,
                        item,
                        by_means,
                        i.is_multiple_of(MEANS_CHECKED_EVERY),
                    );
                    // On block medians only, as `--mask-auto` looks for them: a block's mean shows a dot too
                    // small to move its median (nor `F`).
                    let spots = match (&low, spots_every) {
                        (Some((_, r)), Some(every)) if decoded && i.is_multiple_of(every) => {
                            Some(laser_spots(r))
                        }
                        _ => None,
                    };
                    ((low, spots), agreed)
                })
                .collect();
            if let Some(k) = read.iter().position(|(_, agreed)| !agreed) {
                disagreed = Some(chunk[k].entry.path.clone());
                break;
            }
            if send
                .send(read.into_iter().map(|(r, _)| r).collect())
                .is_err()
            {
                break;
            }
        }
        drop(send);
        measures.join()
    });
    let photos = match surveyed {
        Ok(photos) => photos,
        Err(panic) => std::panic::resume_unwind(panic),
    };
    match disagreed {
        Some(path) => Err(path),
        None => Ok(photos),
    }
}

/// What the survey read of one photo: its block image (`None`: it does not decode) and, where they were looked for,
/// that image's [`laser_spots`].
type SurveyRead = (Option<(Layout, Raster)>, Option<Vec<bool>>);

/// One photo's block image for the survey (`None`: it does not decode), whether it is not a disagreement, and
/// whether the image is the decoded photo's block medians: a baseline JPEG by its block means when `by_means`
/// (decoded as well when `check`, its block medians then taken and compared with the means), any other photo
/// decoded.
fn survey_read<T: Sync>(
    engine: &FirstPass<T>,
    plan: &Plan,
    item: &Item,
    by_means: bool,
    check: bool,
) -> (Option<(Layout, Raster)>, bool, bool) {
    let path = &item.entry.path;
    let means = match by_means {
        true => match crate::io::survey_block_means(path, plan.photo_size) {
            Ok(means) => means,
            Err(_) => return (None, true, false),
        },
        false => None,
    };
    let means = means.and_then(|b| {
        let layout = Layout {
            width: b.width,
            height: b.height,
            channels: b.channels,
        };
        Some((
            layout,
            engine.block_image_from_means(&b.means, b.blocks, b.channels)?,
        ))
    });
    let means = match (means, check) {
        (Some(low), false) => return (Some(low), true, false),
        (means, _) => means,
    };
    let Ok(p) = decode_expecting(path, plan.photo_size) else {
        return (None, true, false);
    };
    let (layout, medians) = (p.layout, engine.block_image(&p));
    crate::io::buffers::recycle(p);
    let Some(medians) = medians else {
        return (None, true, false);
    };
    let agreed = means
        .as_ref()
        .is_none_or(|(_, m)| engine.means_stand_for_medians(m, &medians));
    (Some((layout, medians)), agreed, true)
}

/// The console's line on the windows chosen.
fn stretches_line(choices: &[Choice]) -> String {
    let span = |f: &dyn Fn(&Choice) -> f64| {
        let v = choices.iter().map(f).filter(|v| v.is_finite());
        let lo = v.clone().fold(f64::INFINITY, f64::min);
        let hi = v.fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    };
    let (w0, w1) = span(&|c| c.window as f64);
    let (c0, c1) = span(&|c| c.coverage as f64);
    let (p0, p1) = span(&|c| c.photos_per_sample as f64);
    let acted = choices
        .iter()
        .filter(|c| !matches!(c.rule, Rule::Sparse | Rule::Unsteady))
        .count();
    let unsteady = choices.iter().filter(|c| c.rule == Rule::Unsteady).count();
    let kept = match unsteady {
        0 => String::new(),
        n => format!(
            "; {n} photo(s) keep the window 7 and its median, as the lights' shape changed along the longer window"
        ),
    };
    format!(
        "--window auto: {acted} of {} photos on stretches that need more than the window 7 and its median{kept}; \
         windows {w0}..{w1} photos, dark share {:.0}..{:.0} %, {p0:.1}..{p1:.1} photo(s) per independent sample",
        choices.len(),
        100.0 * c0,
        100.0 * c1
    )
}

/// The path a mask error names: `--mask`, or the mask `--mask-auto` found.
pub fn mask_path(opts: &Options) -> &Path {
    opts.mask.as_deref().unwrap_or(Path::new("mask-auto.png"))
}

fn scatter(
    opts: &Options,
    progress: &dyn Progress,
    warnings: &mut Warnings,
    errors: &mut Vec<FileError>,
) -> Result<(Option<Scatter>, ScatterInfo)> {
    let mut info = ScatterInfo {
        source: "none".into(),
        path: None,
        frames: 0,
        passes: 0,
        saved_to: None,
    };
    if let Some(path) = opts.scatter.as_deref() {
        progress.stage(&format!("loading scatter image {}", path.display()));
        info.source = "file".into();
        info.path = Some(path.to_owned());
        return Ok((Some(Scatter::load(path)?), info));
    }
    let Some(dir) = opts.water_column.as_deref() else {
        warnings
            .warn("no --water-column or --scatter given: assuming no backscatter (S = 0)".into());
        return Ok((None, info));
    };
    let wc = crate::io::find_photos(dir)?;
    for s in &wc.skipped {
        let e = s.to_error();
        progress.file_error(&e);
        errors.push(FileError::from_error(&s.path, &e));
    }
    progress.stage(&format!(
        "estimating scatter S from {} water-column frames in {}",
        wc.photos.len(),
        dir.display()
    ));
    info.source = "water-column".into();
    info.path = Some(dir.to_owned());
    let budget = opts.scatter_memory_mib.max(1) << 20;
    let s = Scatter::from_files(&wc.photos, budget, |e| {
        progress.file_error(&e);
        errors.push(FileError::from_error(e.path().unwrap_or(Path::new("")), &e));
    })?;
    match &s {
        Some(s) => {
            info.frames = s.frames;
            info.passes = s.passes;
            if s.frames < 3 {
                warnings.warn(format!(
                    "only {} usable water-column frame(s): the median cannot reject particles with fewer than 3",
                    s.frames
                ));
            }
        }
        None => warnings.warn(format!(
            "no usable water-column frames in {}: continuing with S = 0 (no backscatter removal)",
            dir.display()
        )),
    }
    Ok((s, info))
}

/// Share of the frame a mask may hide before the run warns that it hides most of it.
const MASK_WARN_SHARE: f64 = 0.5;

/// A mask that hides most of the frame (an inverted `--mask`: white where black was meant) leaves little seafloor
/// to estimate the lighting from: warned about, and the warning goes into the report.
fn warn_if_most_is_hidden(mask: &Mask, warnings: &mut Warnings) {
    let share = mask.count() as f64 / mask.ignore.len().max(1) as f64;
    if share > MASK_WARN_SHARE {
        warnings.warn(format!(
            "the mask hides {:.0} % of the frame ({} of {} pixels): the lighting is estimated from the rest only; \
             white marks what is not seafloor (is the mask inverted?)",
            100.0 * share,
            mask.count(),
            mask.ignore.len()
        ));
    }
}

/// The `--mask` file, if one is given.
fn user_mask(opts: &Options, progress: &dyn Progress) -> Result<Option<Mask>> {
    let mask = match opts.mask.as_deref() {
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
    Ok(mask)
}

/// Per-pixel medians of up to three thirds of a sample of the mission's photos, for `--mask-auto`.
fn static_medians(
    opts: &Options,
    plan: &Plan,
    progress: &dyn Progress,
    warnings: &mut Warnings,
) -> Result<Vec<Raster>> {
    let sample: Vec<Entry> = spread_indices(plan.found.photos.len(), 45)
        .into_iter()
        .map(|i| plan.found.photos[i].clone())
        .collect();
    // Medians of the three thirds of the mission: static content shows in all of them.
    let parts = if sample.len() >= 9 { 3 } else { 1 };
    progress.stage(&format!(
        "looking for static pixels (overlays, lasers) in {} photos spread over the mission",
        sample.len()
    ));
    if parts == 1 {
        warnings.warn(format!(
            "--mask-auto had only {} photos to compare: the mask may include coincidental dark spots",
            sample.len()
        ));
    }
    let budget = opts.scatter_memory_mib.max(1) << 20;
    let mut medians = Vec::new();
    for p in 0..parts {
        let part = &sample[p * sample.len() / parts..(p + 1) * sample.len() / parts];
        if let Some(m) = Scatter::from_files_sized(part, plan.photo_size, budget, |_| {})? {
            medians.push(m.to_raster());
        }
    }
    Ok(medians)
}

/// `--mask`, united with what `--mask-auto` finds.
fn mask(
    opts: &Options,
    transfer: Transfer,
    plan: &Plan,
    progress: &dyn Progress,
    warnings: &mut Warnings,
) -> Result<Option<Mask>> {
    let mut mask = user_mask(opts, progress)?;
    if !opts.mask_auto {
        return Ok(mask);
    }
    let medians = static_medians(opts, plan, progress, warnings)?;
    if medians.is_empty() || medians.iter().any(|m| m.layout() != medians[0].layout()) {
        warnings.warn(
            "--mask-auto found no photos of the mission's size that decode: no mask found"
                .to_string(),
        );
        return Ok(mask);
    }
    let mut found = detect_static(&medians, DetectSettings::default());
    let fixed = found.count();
    let many: Vec<Entry> = spread_indices(plan.found.photos.len(), PATH_PHOTOS)
        .into_iter()
        .map(|i| plan.found.photos[i].clone())
        .collect();
    progress.stage(&format!(
        "looking for the paths of laser dots in {} photos spread over the mission",
        many.len()
    ));
    let path = spot_path(&many, &found, opts.block(), transfer);
    if let Some(p) = &path {
        found.union(p);
    }
    let p = plan
        .work_dir
        .as_deref()
        .unwrap_or(Path::new("."))
        .join("mask-auto.png");
    if plan.work_dir.is_some() {
        found.save(&p)?;
    }
    let share = |n: usize| 100.0 * n as f64 / found.ignore.len().max(1) as f64;
    progress.stage(&format!(
        "static pixels found: {:.2} % of the frame, laser dots' paths {:.2} %; mask written to {}",
        share(fixed),
        share(found.count() - fixed),
        p.display()
    ));
    match &mut mask {
        Some(m) if (m.width, m.height) == (found.width, found.height) => m.union(&found),
        Some(_) => {}
        None => mask = Some(found),
    }
    Ok(mask)
}

/// Photos (spread over the mission) in which [`spot_path`] looks for laser dots: every photo of a mission up to this
/// length. On the 71-photo Nephrops run, all of them found the dots in 1.72 % of the frame where 45 found 1.38 %,
/// and the stains left went down by another 2–7 %. The cost is one more decode of these photos (the Nephrops runs:
/// +25 % of the run's time; a long mission of 12 MP photos: 400 decodes, well under 1 % of its time).
const PATH_PHOTOS: usize = 400;

/// The blocks where laser-coloured bright spots came back to over the photos of `sample`, as a pixel mask
/// ([`lasers::paths_over_the_mission`]); `None` when there are none. Photos that do not decode or differ in size from
/// `fixed` (the static pixels) are passed over (the correction stream reports them).
fn spot_path(sample: &[Entry], fixed: &Mask, k: usize, transfer: Transfer) -> Option<Mask> {
    let size = Some((fixed.width, fixed.height));
    // Of another size: never decoded (a small file may declare a huge photo).
    let photos = sample
        .par_iter()
        .filter_map(|e| decode_expecting(&e.path, size).ok());
    lasers::paths_over_the_mission(photos, fixed, k, transfer)
}

/// Up to `most` indices spread evenly over `0..n` (first and last included).
pub fn spread_indices(n: usize, most: usize) -> Vec<usize> {
    if n <= most {
        return (0..n).collect();
    }
    (0..most).map(|i| i * (n - 1) / (most - 1).max(1)).collect()
}

/// The mission's mean image at block resolution, in linear light, over every photo that decodes with the layout of
/// the first one (others are skipped here and reported by the correction stream). Photos whose header is not
/// `size` (the mission's, when known) are never decoded.
pub fn mission_mean(
    photos: &[Entry],
    size: Option<(usize, usize)>,
    k: usize,
    transfer: Transfer,
    progress: &dyn Progress,
) -> Result<Raster> {
    progress.stage(&format!(
        "method mean: averaging all {} survey photos",
        photos.len()
    ));
    let lows: Vec<Option<(Layout, Raster)>> = photos
        .par_iter()
        .map(|e| {
            let p = decode_expecting(&e.path, size).ok()?;
            let r = Raster::from_photo_linear(&p, transfer);
            Some((p.layout, block_mean(&r, k)))
        })
        .collect();
    let first = lows.iter().flatten().next().map(|(l, _)| *l);
    let Some(layout) = first else {
        return Err(Error::Usage(
            "method mean: no survey photo could be decoded".into(),
        ));
    };
    let mut n = 0usize;
    let mut sum: Option<Raster> = None;
    for (l, r) in lows.into_iter().flatten() {
        if l != layout {
            continue;
        }
        n += 1;
        match &mut sum {
            None => sum = Some(r),
            Some(s) => s.data.iter_mut().zip(&r.data).for_each(|(a, b)| *a += b),
        }
    }
    let mut mean = sum.expect("at least one photo");
    mean.data.iter_mut().for_each(|v| *v /= n as f32);
    Ok(mean)
}
