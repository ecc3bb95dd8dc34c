//! Pictures for the user to see where to distrust the output: a mission overview plot of the monitoring series
//! with flagged photos marked (`_abysslight/overview.png`), and a contact sheet of flagged photos beside their
//! lit-seafloor image `F·C` (`_abysslight/flagged.png`).

use std::path::{Path, PathBuf};

use image::RgbImage;

use crate::error::{Error, Result};
use crate::method::monitor::Thresholds;
use crate::method::raster::Raster;
use crate::report::FrameReport;
use crate::run::draw::{self, BLACK, BLUE, GREY, RED, WHITE};

/// One plotted series.
struct Series<'a> {
    title: &'a str,
    /// The value of each photo (NaN: none, e.g. a photo the navigation log does not cover).
    values: Vec<f32>,
    /// The flag threshold (none: a series for reading only, the altitude).
    threshold: Option<f32>,
    /// A second flag threshold above the values (texture kept: structure added).
    upper: Option<f32>,
    /// A flag condition that moves from photo to photo, which a value must exceed too (change of F: 4 times the
    /// median change so far); NaN where it does not apply.
    moving: Option<Vec<f32>>,
    /// The kinds of flag (`Flag::kind`) this panel's values raise: photos with one are drawn as red points.
    kinds: &'static [&'static str],
}

/// The second condition of the `factor-change` flag for each photo, as the run's monitor applies it
/// (`Monitor::observe_factor_change`): `ratio` times the median change of the photos before it (the first two
/// have none: 0, and the first photo no change at all).
fn factor_change_condition(changes: &[f32], ratio: f32) -> Vec<f32> {
    let mut seen: Vec<f32> = Vec::with_capacity(changes.len());
    changes
        .iter()
        .enumerate()
        .map(|(i, &c)| {
            if i == 0 {
                return f32::NAN;
            }
            let typical = if seen.is_empty() {
                0.0
            } else {
                let mut s = seen.clone();
                let mid = s.len() / 2;
                *s.select_nth_unstable_by(mid, f32::total_cmp).1
            };
            seen.push(c);
            ratio * typical
        })
        .collect()
}

/// The series of the overview, one panel each, with their flag thresholds; the altitude's when the photos have
/// altitudes (a navigation log).
fn overview_series(frames: &[FrameReport], t: &Thresholds) -> Vec<Series<'static>> {
    let changes: Vec<f32> = frames.iter().map(|f| f.health.factor_change).collect();
    // Under `--window auto` a low texture kept flags nothing by itself (the survey counts the views): no line there.
    let surveyed = frames.iter().any(|f| f.window_auto.is_some());
    let mut series = vec![
        Series {
            title: "contamination: share of blocks off the seafloor colour (0 to 1)",
            values: frames.iter().map(|f| f.health.contamination).collect(),
            threshold: Some(t.contamination),
            upper: None,
            moving: None,
            kinds: &["contamination"],
        },
        Series {
            title: "change of F from the previous photo (0.1 = 10 %): flagged above both red lines, dashed and \
                    dotted (4 x the median change before)",
            moving: Some(factor_change_condition(&changes, t.factor_change_ratio)),
            values: changes,
            threshold: Some(t.factor_change),
            upper: None,
            kinds: &["factor-change"],
        },
        Series {
            title: "colour shift of F against what its level predicts (relative)",
            values: frames.iter().map(|f| f.health.colour_shift).collect(),
            threshold: Some(t.colour_shift),
            upper: None,
            moving: None,
            kinds: &["colour-shift"],
        },
        Series {
            title: "roughness of F: high = scene left in F (relative)",
            values: frames.iter().map(|f| f.health.roughness).collect(),
            threshold: Some(t.roughness),
            upper: None,
            moving: None,
            kinds: &["scene-in-factor"],
        },
        Series {
            title: "texture kept by the correction: low = scene left in F, high = structure added (share, 1 = all)",
            values: frames.iter().map(|f| f.health.texture_kept).collect(),
            threshold: (!surveyed).then_some(t.texture_kept),
            upper: Some(t.structure_added),
            moving: None,
            kinds: &["scene-in-factor", "structure-added"],
        },
        Series {
            title: "lights against the window's M: about the lighting pattern left (0.05 = 5 %), plus the \
                    seafloor's texture",
            values: frames.iter().map(|f| f.health.lights_misfit).collect(),
            threshold: Some(t.lights_misfit),
            upper: None,
            moving: None,
            kinds: &["lights-misfit"],
        },
        Series {
            title: "exposure against the window's M: |level - 1| (0.1 = 10 %; flagged only without the per-photo gain)",
            values: frames
                .iter()
                .map(|f| (f.health.level - 1.0).abs())
                .collect(),
            threshold: Some(t.exposure_jump),
            upper: None,
            moving: None,
            kinds: &["exposure-jump"],
        },
    ];
    if frames.iter().any(|f| f.altitude.is_some()) {
        series.push(Series {
            title: "altitude above the seafloor from the navigation log (m; gaps: not in the log)",
            values: frames
                .iter()
                .map(|f| f.altitude.unwrap_or(f32::NAN))
                .collect(),
            threshold: None,
            upper: None,
            moving: None,
            kinds: &[],
        });
    }
    series
}

/// The height of the overview's title and key above the first panel, in pixels.
const HEADER: i64 = 66;

/// Margins and sizes of the overview, in pixels.
struct Frame {
    left: i64,
    plot_w: i64,
    panel_h: i64,
    title_h: i64,
    gap: i64,
    photos: usize,
}

impl Frame {
    /// The x of the `i`-th photo of the plot (0-based).
    fn x_of(&self, i: usize) -> i64 {
        self.left
            + if self.photos > 1 {
                i as i64 * (self.plot_w - 1) / (self.photos as i64 - 1)
            } else {
                self.plot_w / 2
            }
    }
}

/// A panel's title in lines that fit between the value axis and the right edge (a long title on the narrowest
/// overview, 600 pixels of plot, was cut off): one line, or two in the panel's title band.
fn title_lines(title: &str, f: &Frame) -> Vec<String> {
    let chars = ((f.plot_w + 20 - 4) / 8).max(1) as usize;
    wrap(title, chars).into_iter().take(2).collect()
}

/// Positions (0-based) of the ticks of the photo axis for `photos` photos: the first, then every `step` photos,
/// `step` 1, 2 or 5 times a power of ten, at most 10 steps.
fn photo_ticks(photos: usize) -> Vec<usize> {
    let mut step = 1usize;
    let mut k = 0;
    while photos / step > 10 {
        step = [2, 5, 10][k % 3] * 10usize.pow((k / 3) as u32);
        k += 1;
    }
    let mut ticks: Vec<usize> = (photos > 0).then_some(0).into_iter().collect();
    ticks.extend(
        (step..=photos)
            .step_by(step)
            .map(|t| t - 1)
            .filter(|&t| t > 0),
    );
    ticks
}

/// Draw the mission overview: contamination, change of F, colour shift and roughness of F, texture kept and level
/// (exposure), per photo; flagged photos in red. Each panel has its value axis (0, half, top, and the flag
/// threshold in red) and the photo number below; a key under the title says what is drawn.
pub fn overview(frames: &[FrameReport], t: &Thresholds) -> RgbImage {
    let series = overview_series(frames, t);
    let f = Frame {
        left: 70,
        plot_w: (frames.len().max(1) as i64 * 3).clamp(600, 1600),
        panel_h: 130,
        title_h: 22,
        gap: 30,
        photos: frames.len().max(1),
    };
    let width = (f.left + f.plot_w + 20) as u32;
    let height = (HEADER + series.len() as i64 * (f.title_h + f.panel_h + f.gap) + 10) as u32;
    let mut img = RgbImage::from_pixel(width, height, WHITE);
    let flagged = frames.iter().filter(|f| !f.health.flags.is_empty()).count();
    let title = format!(
        "abysslight: {} photos, {flagged} flagged (red)",
        frames.len()
    );
    // Scale 2 where it fits with the right margin.
    let scale = if draw::text_width(&title, 2) as i64 + f.left + 10 <= width as i64 {
        2
    } else {
        1
    };
    draw::text(&mut img, f.left, 10, &title, scale, BLACK);
    let key = "blue: value of each photo; red points: flagged for the panel's reason; red bands: flagged for \
               any reason; red dashes: flag threshold";
    let chars = ((width as i64 - f.left - 4) / 8).max(1) as usize;
    for (k, line) in wrap(key, chars).iter().take(2).enumerate() {
        draw::text(&mut img, f.left, 34 + 10 * k as i64, line, 1, GREY);
    }
    let mut top = HEADER;
    for s in &series {
        panel(&mut img, &f, frames, s, top);
        top += f.title_h + f.panel_h + f.gap;
    }
    img
}

/// One panel of the overview, its title at `top`: flagged bands, the axes with their ticks and labels (the photo
/// axis labelled with the photos' numbers in the mission), the threshold and the series.
fn panel(img: &mut RgbImage, f: &Frame, frames: &[FrameReport], s: &Series, top: i64) {
    for (k, line) in title_lines(s.title, f).iter().enumerate() {
        draw::text(img, f.left, top + 1 + 10 * k as i64, line, 1, BLACK);
    }
    let (y0, h) = (top + f.title_h, f.panel_h);
    // The moving condition counts too: a dotted line cut off at the top would say less than it is.
    let values_max = s
        .values
        .iter()
        .chain(s.moving.iter().flatten())
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0, f32::max);
    let vmax = match s.threshold.or(s.upper) {
        Some(t) => values_max.max(t.max(s.upper.unwrap_or(0.0)) * 1.5),
        None => values_max * 1.1,
    }
    .max(f32::MIN_POSITIVE);
    let y_of = |v: f32| y0 + h - 1 - ((v / vmax).clamp(0.0, 1.0) * (h - 1) as f32) as i64;
    let band = image::Rgb([255, 200, 200]);
    for (i, fr) in frames.iter().enumerate() {
        if !fr.health.flags.is_empty() {
            draw::fill_rect(img, f.x_of(i) - 1, y0, 3, h as u32, band);
        }
    }
    let right = f.left + f.plot_w - 1;
    draw::line(img, (f.left, y0), (f.left, y0 + h - 1), BLACK);
    draw::line(img, (f.left, y0 + h - 1), (right, y0 + h - 1), BLACK);
    let marks = [(0.0, BLACK), (vmax / 2.0, BLACK), (vmax, BLACK)];
    let thresholds = s.threshold.into_iter().chain(s.upper);
    // A value mark whose label a threshold's label would overwrite (within a line of text) is left out.
    let clear = |v: f32| thresholds.clone().all(|u| (y_of(u) - y_of(v)).abs() >= 10);
    for (v, colour) in marks
        .into_iter()
        .filter(|&(v, _)| clear(v))
        .chain(thresholds.clone().map(|u| (u, RED)))
    {
        let y = y_of(v);
        draw::line(img, (f.left - 4, y), (f.left, y), colour);
        let label = format!("{v:.3}");
        let x = f.left - 6 - draw::text_width(&label, 1) as i64;
        draw::text(img, x, y - 4, &label, 1, colour);
    }
    for ty in thresholds.map(y_of) {
        for x in (f.left..right).step_by(6) {
            draw::line(img, (x, ty), (x + 2, ty), RED);
        }
    }
    // The moving condition: a dotted red step at each photo's own level.
    if let Some(moving) = &s.moving {
        for (i, v) in moving.iter().enumerate() {
            if !v.is_finite() {
                continue;
            }
            let y = y_of(*v);
            let (x0, x1) = (f.x_of(i.saturating_sub(1)).max(f.left), f.x_of(i));
            for x in (x0..=x1).step_by(3) {
                draw::fill_rect(img, x, y, 1, 1, RED);
            }
        }
    }
    photo_axis(img, f, frames, y0 + h, right);
    let mut prev: Option<(i64, i64)> = None;
    for (i, v) in s.values.iter().enumerate() {
        if !v.is_finite() {
            prev = None;
            continue;
        }
        let p = (f.x_of(i), y_of(*v));
        if let Some(q) = prev {
            draw::line(img, q, p, BLUE);
        }
        draw::fill_rect(img, p.0 - 1, p.1 - 1, 3, 3, BLUE);
        prev = Some(p);
    }
    // Photos flagged for this panel's reason: red points over the line.
    for (i, (v, fr)) in s.values.iter().zip(frames).enumerate() {
        if v.is_finite() && fr.health.flags.iter().any(|k| s.kinds.contains(&k.kind())) {
            let p = (f.x_of(i), y_of(*v));
            draw::fill_rect(img, p.0 - 2, p.1 - 2, 5, 5, RED);
        }
    }
}

/// The photo axis below a panel whose plot ends at `bottom`: ticks labelled with the photos' numbers in the mission.
fn photo_axis(img: &mut RgbImage, f: &Frame, frames: &[FrameReport], bottom: i64, right: i64) {
    for t in photo_ticks(frames.len()) {
        let x = f.x_of(t);
        draw::line(img, (x, bottom - 1), (x, bottom + 3), BLACK);
        let label = (frames[t].index + 1).to_string();
        let lw = draw::text_width(&label, 1) as i64;
        draw::text(
            img,
            (x - lw / 2).min(right - lw),
            bottom + 6,
            &label,
            1,
            BLACK,
        );
    }
    let axis = "photo number";
    let aw = draw::text_width(axis, 1) as i64;
    draw::text(img, right - aw, bottom + 17, axis, 1, GREY);
}

/// A contact sheet of flagged photos: corrected photo | `F·C`, with the photo's name and first reason.
pub fn flagged_sheet(rows: &[(&FrameReport, &Raster)], tile_w: u32) -> Option<RgbImage> {
    let rows: Vec<(FrameReport, String, &Raster)> = rows
        .iter()
        .map(|(f, lit)| {
            let reason = f
                .health
                .flags
                .first()
                .map_or(String::new(), |r| r.to_string());
            ((*f).clone(), reason, *lit)
        })
        .collect();
    flagged_sheet_with(&rows, tile_w)
}

/// [`flagged_sheet`] with each photo's first reason given as text (`abysslight merge-shards` reads it from the
/// shards' reports).
pub fn flagged_sheet_with(
    rows: &[(FrameReport, String, &Raster)],
    tile_w: u32,
) -> Option<RgbImage> {
    if rows.is_empty() {
        return None;
    }
    let gap = 6u32;
    let label_h = 40u32;
    let mut tiles = Vec::new();
    for (frame, reason, lit) in rows {
        let corrected = image::open(&frame.output).ok()?.to_rgb8();
        let a = draw::tile(&corrected, tile_w, true);
        let f = draw::tile(&raster_rgb(lit), tile_w, false);
        tiles.push((frame, reason, a, f));
    }
    let h: u32 = tiles
        .iter()
        .map(|(_, _, a, f)| a.height().max(f.height()) + label_h + gap)
        .sum::<u32>()
        + gap;
    // Column titles: what each tile is.
    let titles_h = 32u32;
    let mut img = RgbImage::from_pixel(2 * tile_w + 3 * gap, h + titles_h, WHITE);
    let columns = [
        ("corrected photo", "flagged: its first reason in red"),
        (
            "F·C: the light it was divided by",
            "brightened to show its shape",
        ),
    ];
    for (c, (title, note)) in columns.iter().enumerate() {
        let x = (gap + c as u32 * (tile_w + gap)) as i64;
        draw::text(&mut img, x, gap as i64, title, 1, BLACK);
        draw::text(&mut img, x, gap as i64 + 11, note, 1, GREY);
    }
    let rule = (gap + titles_h - 6) as i64;
    draw::line(
        &mut img,
        (gap as i64, rule),
        ((2 * tile_w + 2 * gap) as i64, rule),
        GREY,
    );
    let mut y = (gap + titles_h) as i64;
    for (frame, reason, a, f) in &tiles {
        let name = frame
            .input
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        draw::text(
            &mut img,
            gap as i64,
            y,
            &format!("#{} {name}", frame.index + 1),
            1,
            BLACK,
        );
        let max_chars = ((2 * tile_w + gap) / 8) as usize;
        for (line, text) in wrap(reason, max_chars).iter().take(2).enumerate() {
            draw::text(
                &mut img,
                gap as i64,
                y + 12 + 11 * line as i64,
                text,
                1,
                RED,
            );
        }
        y += label_h as i64;
        image::imageops::replace(&mut img, a, gap as i64, y);
        image::imageops::replace(&mut img, f, (2 * gap + tile_w) as i64, y);
        y += (a.height().max(f.height()) + gap) as i64;
    }
    Some(img)
}

/// A before/after contact sheet of a corrected folder: `rows` photos spread evenly over the mission, each as
/// input | corrected | `F·C` (the last only where `--save-factors` wrote it; without any, no `F·C` column),
/// `width` pixels wide per tile; and whether it has the `F·C` column.
/// For looking at a run; `examples/before_after.rs` and `examples/real_sheets.rs` use it.
pub fn before_after_sheet(
    input: &Path,
    output: &Path,
    rows: usize,
    width: u32,
) -> Result<(RgbImage, bool)> {
    let found = crate::io::find_photos(input)?;
    let n = found.photos.len();
    if n == 0 || rows == 0 {
        return Err(Error::Usage(format!("no photos in {}", input.display())));
    }
    let rows = rows.min(n);
    let report = read_report(output);
    let mut tiles = Vec::new();
    for r in 0..rows {
        let e = &found.photos[r * (n - 1) / (rows - 1).max(1)];
        let factor = output
            .join(crate::io::WORK_DIR)
            .join("factors")
            .join(&e.relative)
            .with_extension("png");
        let Ok(before) = image::open(&e.path) else {
            continue;
        };
        let before = draw::tile(&before.to_rgb8(), width, true);
        // A photo the run skipped (another size, damaged) gets a labelled tile, not a gap that shifts the columns.
        let after = match image::open(output.join(&e.relative)) {
            Ok(c) => draw::tile(&c.to_rgb8(), width, true),
            Err(_) => skipped_tile(&before, &e.relative, &skipped_reason(&report, &e.relative)),
        };
        let mut row = vec![before, after];
        // F·C is dim (it is the light on a grey seafloor): stretched like the flagged sheet's.
        if let Ok(f) = crate::io::load_raster(&factor) {
            row.push(draw::tile(&raster_rgb(&f), width, true));
        }
        tiles.push(row);
    }
    // No empty, captioned F·C column when the run did not save its factors.
    let with_factors = tiles.iter().any(|r| r.len() > 2);
    let captions: &[&str] = if with_factors {
        &["input", "corrected", "F·C: the light divided out"]
    } else {
        &["input", "corrected"]
    };
    Ok((draw::grid(captions, &tiles, 4), with_factors))
}

/// The `report.json` of the run that wrote `output`, if there is one.
fn read_report(output: &Path) -> Option<serde_json::Value> {
    let text =
        std::fs::read_to_string(output.join(crate::io::WORK_DIR).join("report.json")).ok()?;
    serde_json::from_str(&text).ok()
}

/// Why the run with `report` wrote no output for the photo at `relative` (below its survey folder): the message
/// of its error in the report, or why there may be none.
fn skipped_reason(report: &Option<serde_json::Value>, relative: &Path) -> String {
    let errors = report.as_ref().and_then(|r| r.get("errors")?.as_array());
    let message = errors.into_iter().flatten().find_map(|e| {
        let full = e.get("path")?.as_str()?;
        // The message names the photo by the run's path (often absolute, of the machine that ran it): by its
        // name in the survey instead.
        Path::new(full)
            .ends_with(relative)
            .then(|| {
                e.get("message")?
                    .as_str()
                    .map(|m| m.replace(full, &relative.display().to_string()))
            })
            .flatten()
    });
    message.unwrap_or_else(|| match report {
        Some(_) => {
            "no output: not in the run's photos (--limit, --shard) or not corrected yet".into()
        }
        None => "no output, and no report of a run in this folder".into(),
    })
}

/// A grey tile the size of `like` saying that `name` was skipped, and why (wrapped over up to 8 lines).
fn skipped_tile(like: &RgbImage, name: &Path, reason: &str) -> RgbImage {
    let mut t = RgbImage::from_pixel(like.width(), like.height(), image::Rgb([225, 225, 225]));
    draw::text(&mut t, 6, 6, "SKIPPED", 2, RED);
    let per_line = (like.width().saturating_sub(12) / 8).max(1) as usize;
    // The report's message names the file already (by the run's path).
    let file = name
        .file_name()
        .map_or(String::new(), |f| f.to_string_lossy().into_owned());
    let text = if reason.contains(&file) {
        reason.to_string()
    } else {
        format!("{}: {reason}", name.display())
    };
    for (i, line) in wrap(&text, per_line).iter().take(8).enumerate() {
        draw::text(&mut t, 6, 30 + 11 * i as i64, line, 1, BLACK);
    }
    t
}

/// `text` in lines of at most `width` characters, broken at spaces where a line has one (else mid-word).
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut rest: Vec<char> = text.chars().collect();
    while rest.len() > width {
        let cut = rest[..=width]
            .iter()
            .rposition(|c| *c == ' ')
            .filter(|&i| i > 0)
            .unwrap_or(width);
        lines.push(
            rest[..cut]
                .iter()
                .collect::<String>()
                .trim_end()
                .to_string(),
        );
        rest = rest[cut..]
            .iter()
            .copied()
            .skip_while(|c| *c == ' ')
            .collect();
    }
    if !rest.is_empty() {
        lines.push(rest.into_iter().collect());
    }
    lines
}

/// The folders of `abysslight sheet SURVEY CORRECTED` the right way round, and a warning when they were not:
/// when `survey` holds a run's report and `corrected` does not, the two were given the other way round and are
/// swapped back; when `corrected`'s report names another survey folder than `survey`, the sheet would pair photos
/// of two dives by name.
pub fn sheet_folders(survey: &Path, corrected: &Path) -> (PathBuf, PathBuf, Option<String>) {
    let (s, c) = (survey.to_owned(), corrected.to_owned());
    let (rs, rc) = (read_report(survey), read_report(corrected));
    if rs.is_some() && rc.is_none() {
        let m = format!(
            "{} holds a correct run's report and {} does not: taken the other way round (SURVEY first, then \
             CORRECTED)",
            survey.display(),
            corrected.display()
        );
        return (c, s, Some(m));
    }
    let real = |p: &Path| std::fs::canonicalize(p).ok();
    let from = rc
        .as_ref()
        .and_then(|r| r.get("options")?.get("survey")?.as_str().map(PathBuf::from));
    let warning = from
        // A relative path is the run's own current folder's: only an absolute one can be compared here.
        .filter(|f| f.is_absolute() && real(f).is_some_and(|f| Some(f) != real(survey)))
        .map(|f| {
            format!(
                "{} was corrected from {} (its report), not from {}: the sheet pairs photos by name",
                corrected.display(),
                f.display(),
                survey.display()
            )
        });
    (s, c, warning)
}

/// Smallest width of a factor preview: a 4000-pixel photo's `F·C` is 500 blocks wide, a 1920-pixel video frame's
/// 240; enlarged to this, the light cones and any scene left in `F` can be seen without zooming.
pub const PREVIEW_MIN_WIDTH: u32 = 640;

/// An 8-bit preview of a photo's lit seafloor `F·C` (one pixel per block, linear values in `[0, 1]`), for people:
/// scaled so its 99.5th percentile sample is white, with one scale for all channels, and enlarged smoothly to at
/// least `min_width` pixels wide (never shrunk).
///
/// Why per photo and one scale for the channels: the 16-bit data is dim (a grey seafloor of 0.4 under lights that
/// fall off to the corners) and a mission's brightness swings with altitude, so a scale fixed per mission would
/// leave the photos taken high up near black; how `F` changes from photo to photo is plotted in `overview.png`.
/// Scaling the channels together keeps `F`'s colour, where a seafloor colour change shows up (per-channel
/// scaling would white-balance it away). The 99.5th percentile rather than the maximum keeps a few bright
/// blocks (a shell, a lens flare) from darkening the rest. Non-finite samples are drawn black.
pub fn factor_preview(lit: &Raster, min_width: u32) -> RgbImage {
    let img = scaled_rgb(lit, 0.995);
    let width = min_width.max(img.width());
    if width == img.width() {
        img
    } else {
        draw::tile(&img, width, true)
    }
}

/// `r` as 8-bit RGB, the sample at quantile `q` of all finite samples mapped to 255 (grey rasters replicated).
fn scaled_rgb(r: &Raster, q: f64) -> RgbImage {
    let mut v: Vec<f32> = r.data.iter().copied().filter(|x| x.is_finite()).collect();
    let top = if v.is_empty() {
        1.0
    } else {
        let k = ((v.len() - 1) as f64 * q).round() as usize;
        *v.select_nth_unstable_by(k, f32::total_cmp).1
    }
    .max(1e-6);
    RgbImage::from_fn(r.width as u32, r.height as u32, |x, y| {
        let px = |c: usize| {
            let ch = if r.channels >= 3 { c } else { 0 };
            let v = r.get(x as usize, y as usize, ch) / top;
            if v.is_finite() {
                (v.clamp(0.0, 1.0) * 255.0).round() as u8
            } else {
                0
            }
        };
        image::Rgb([px(0), px(1), px(2)])
    })
}

/// A raster in `[0, 1]` as an 8-bit RGB image (grey rasters replicated), scaled so its 99th percentile is white.
fn raster_rgb(r: &Raster) -> RgbImage {
    let mut v: Vec<f32> = r.data.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f32::total_cmp);
    let top = v.get(v.len() * 99 / 100).copied().unwrap_or(1.0).max(1e-6);
    RgbImage::from_fn(r.width as u32, r.height as u32, |x, y| {
        let px = |c: usize| {
            let ch = if r.channels == 3 { c } else { 0 };
            ((r.get(x as usize, y as usize, ch) / top).clamp(0.0, 1.0) * 255.0) as u8
        };
        image::Rgb([px(0), px(1), px(2)])
    })
}

/// Save an RGB picture atomically as PNG.
pub fn save_png(img: &RgbImage, path: &Path) -> Result<()> {
    crate::io::write_with(path, |w| {
        img.write_to(w, image::ImageFormat::Png)
            .map_err(|e| Error::Encode {
                path: path.to_owned(),
                reason: e.to_string(),
            })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every panel title of the narrowest overview fits inside the picture, whole.
    #[test]
    fn overview_titles_fit_the_narrowest_overview() {
        let f = Frame {
            left: 70,
            plot_w: 600,
            panel_h: 130,
            title_h: 22,
            gap: 30,
            photos: 20,
        };
        let width = f.left + f.plot_w + 20;
        for s in overview_series(&[], &Thresholds::default()) {
            let lines = title_lines(s.title, &f);
            assert!(lines.len() <= 2, "{lines:?}");
            assert_eq!(lines.join(" "), s.title, "nothing cut off");
            for l in &lines {
                assert!(f.left + draw::text_width(l, 1) as i64 <= width - 4, "{l}");
            }
        }
    }

    /// A skipped photo's tile names it by its place in the survey, not by the absolute path of the machine that
    /// ran (which the report's message carries).
    #[test]
    fn a_skipped_photo_is_named_by_its_place_in_the_survey() {
        let report = serde_json::json!({"errors": [
            {"path": "/home/someone/dive042/survey/leg1/IMG_0003.png",
             "message": "/home/someone/dive042/survey/leg1/IMG_0003.png: truncated (1200 of 40000 bytes)"}
        ]});
        let why = skipped_reason(&Some(report), Path::new("leg1/IMG_0003.png"));
        assert_eq!(why, "leg1/IMG_0003.png: truncated (1200 of 40000 bytes)");
    }

    #[test]
    fn factor_preview_maps_the_995th_percentile_to_white_and_enlarges() {
        // 20×10 blocks, RGB; red ramps over 200 distinct values, green is half of red, blue is constant.
        let (w, h) = (20usize, 10usize);
        let r = Raster::from_fn(w, h, 3, |x, y, c| {
            let v = (y * w + x + 1) as f32 / 1000.0; // 0.001 ..= 0.200
            [v, v / 2.0, 0.05][c]
        });
        // The 99.5th percentile of all 600 samples, by a full sort (independent of select_nth).
        let mut all = r.data.clone();
        all.sort_by(f32::total_cmp);
        let top = all[((all.len() - 1) as f64 * 0.995).round() as usize];
        let small = scaled_rgb(&r, 0.995);
        for (x, y) in [(0usize, 0usize), (7, 3), (19, 9), (10, 9)] {
            let want = |v: f32| ((v / top).clamp(0.0, 1.0) * 255.0).round() as u8;
            let p = small.get_pixel(x as u32, y as u32).0;
            assert_eq!(p[0], want(r.get(x, y, 0)), "red at ({x},{y})");
            assert_eq!(p[1], want(r.get(x, y, 1)), "green at ({x},{y})");
            assert_eq!(p[2], want(0.05), "blue at ({x},{y})");
        }
        assert_eq!(
            small.get_pixel(19, 9).0[0],
            255,
            "the brightest block is white"
        );
        // Enlarged to at least 640 wide, aspect kept; never shrunk.
        let big = factor_preview(&r, 640);
        assert_eq!(big.dimensions(), (640, 320));
        assert_eq!(factor_preview(&r, 8).dimensions(), (20, 10));
        // Smooth: the corners keep their values, and down a column (red rises by 0.02, about 26 levels, per
        // block) neighbouring pixels differ by a few levels, not by a block's 26 at each block edge.
        assert!(big.get_pixel(0, 0).0[0] < 10);
        assert!(big.get_pixel(639, 319).0[0] > 240);
        let col: Vec<i32> = (0..320)
            .map(|y| big.get_pixel(320, y).0[0] as i32)
            .collect();
        let jump = col.windows(2).map(|p| (p[1] - p[0]).abs()).max().unwrap();
        assert!(jump <= 4, "largest step down a column: {jump}");
        assert!(col[319] - col[0] > 150, "the column still spans the ramp");
    }

    #[test]
    fn wrap_breaks_at_spaces_and_keeps_every_word() {
        let text =
            "mix/a_very_long_name.jpg: size 614x345 differs from the mission's 1229x691; skipped";
        for width in [5usize, 12, 23, 40, 200] {
            let lines = wrap(text, width);
            assert!(
                lines.iter().all(|l| l.chars().count() <= width),
                "{width}: {lines:?}"
            );
            let joined: Vec<&str> = lines.iter().flat_map(|l| l.split(' ')).collect();
            let words: Vec<&str> = text.split(' ').collect();
            if width >= 24 {
                assert_eq!(joined, words, "{width}: whole words");
            } else {
                assert_eq!(lines.concat().replace(' ', ""), text.replace(' ', ""));
            }
        }
        assert_eq!(wrap("ab cd", 2), ["ab", "cd"]);
        assert!(wrap("", 5).is_empty());
    }

    /// The ticks of the photo axis against a search over the allowed steps: the smallest of 1, 2, 5, 10, 20, …
    /// that gives at most 10 steps, ticks at the first photo and at every multiple of the step.
    #[test]
    fn photo_ticks_are_round_steps_at_most_ten() {
        let steps: Vec<usize> = (0..6)
            .flat_map(|e| [1, 2, 5].map(|m| m * 10usize.pow(e)))
            .collect();
        for photos in 0..3000 {
            let step = *steps.iter().find(|&&s| photos / s <= 10).unwrap();
            let mut want: Vec<usize> = if photos > 0 { vec![0] } else { vec![] };
            want.extend(
                (1..=photos)
                    .filter(|p| p % step == 0 && *p > 1)
                    .map(|p| p - 1),
            );
            assert_eq!(photo_ticks(photos), want, "{photos} photos");
        }
    }

    fn frames(n: usize, dir: &Path) -> Vec<FrameReport> {
        (0..n)
            .map(|i| {
                FrameReport::pictured(
                    dir.join(format!("in{i}.png")),
                    dir.join(format!("out{i}.png")),
                    i,
                    Default::default(),
                )
            })
            .collect()
    }

    /// Dark pixels of `img` in the rectangle `x0..x1`, `y0..y1`.
    fn ink(img: &RgbImage, (x0, x1): (i64, i64), (y0, y1): (i64, i64)) -> usize {
        let (w, h) = (img.width() as i64, img.height() as i64);
        (y0.max(0)..y1.min(h))
            .flat_map(|y| (x0.max(0)..x1.min(w)).map(move |x| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x as u32, y as u32).0[0] < 100)
            .count()
    }

    /// The texture panel draws the low line (`scene-in-factor` from the texture kept alone) only where it flags:
    /// with a window given, not under `--window auto`; the structure-added line always.
    #[test]
    fn the_texture_panel_draws_only_the_lines_that_flag() {
        let t = Thresholds::default();
        let texture = |fr: &[FrameReport]| {
            overview_series(fr, &t)
                .into_iter()
                .find(|s| s.title.starts_with("texture kept"))
                .map(|s| (s.threshold, s.upper))
                .unwrap()
        };
        let mut fr = frames(3, Path::new("/nowhere"));
        assert_eq!(
            texture(&fr),
            (Some(t.texture_kept), Some(t.structure_added))
        );
        fr[1].window_auto = Some(crate::report::WindowAuto::from(
            crate::method::stretch::Choice {
                window: 7,
                quantile: 0.5,
                near: None,
                coverage: 0.0,
                photos_per_sample: 2.0,
                samples: 3,
                needed: 3,
                rule: crate::method::stretch::Rule::Sparse,
                misfit: None,
            },
        ));
        assert_eq!(texture(&fr), (None, Some(t.structure_added)));
        // A panel with only its upper line is drawn (its scale from that line) without failing.
        overview(&fr, &t);
    }

    /// Under every panel of the overview, the photo numbers of the ticks (photo 20, 40, … of 151), where the
    /// overview had only "photo 1" and "photo 151" under the last panel.
    #[test]
    fn the_overview_numbers_the_photo_axis_of_every_panel() {
        let fr = frames(151, Path::new("/nowhere"));
        let img = overview(&fr, &Thresholds::default());
        let f = Frame {
            left: 70,
            plot_w: 600,
            panel_h: 130,
            title_h: 22,
            gap: 30,
            photos: 151,
        };
        assert_eq!(img.width() as i64, 70 + 600 + 20);
        for p in 0..6 {
            let below = HEADER + p * (22 + 130 + 30) + 22 + 130 + 6;
            for t in [19usize, 79, 139] {
                let x = f.x_of(t);
                assert!(
                    ink(&img, (x - 12, x + 12), (below, below + 8)) > 5,
                    "panel {p}, photo {}",
                    t + 1
                );
            }
            // Between ticks, no label.
            let x = f.x_of(29);
            assert_eq!(
                ink(&img, (x - 3, x + 3), (below, below + 8)),
                0,
                "panel {p}"
            );
        }
    }

    /// The second condition of `factor-change`, by hand: 4 times the median (the upper one of an even count) of
    /// the changes of the photos before, the first photo's left out (it has no change).
    #[test]
    fn the_moving_condition_of_a_change_of_f_is_the_monitors() {
        let m = factor_change_condition(&[0.0, 0.3, 0.1, 0.2, 0.05], 4.0);
        assert!(m[0].is_nan());
        for (got, want) in m[1..].iter().zip([0.0, 1.2, 1.2, 0.8]) {
            assert!((got - want).abs() < 1e-6, "{m:?}");
        }
    }

    /// A photo flagged `factor-change` is a red point in the change-of-F panel, an unflagged one is not; with
    /// altitudes the overview has a seventh panel, the altitude.
    #[test]
    fn flagged_points_are_red_and_altitudes_get_a_panel() {
        let mut fr = frames(20, Path::new("/nowhere"));
        fr[10].health.factor_change = 0.5;
        fr[10].health.flags.push(
            (&crate::method::monitor::Flag::FactorChange {
                change: 0.5,
                altitude: None,
            })
                .into(),
        );
        fr[14].health.factor_change = 0.5;
        let t = Thresholds::default();
        let img = overview(&fr, &t);
        let f = Frame {
            left: 70,
            plot_w: 600,
            panel_h: 130,
            title_h: 22,
            gap: 30,
            photos: 20,
        };
        let red = |x: i64, y: i64| {
            (y - 1..=y + 1)
                .flat_map(|y| (x - 1..=x + 1).map(move |x| (x, y)))
                .filter(|&(x, y)| img.get_pixel(x as u32, y as u32).0 == RED.0)
                .count()
        };
        // Panel 1 (change of F): the largest value, 0.5, is the top of its value axis (above 1.5 x 0.15 and the
        // moving condition, 0 here: the median change before photo 10 and 14 is 0).
        let y = HEADER + (22 + 130 + 30) + 22;
        assert_eq!(red(f.x_of(10), y), 9, "the flagged photo's point");
        assert_eq!(red(f.x_of(14), y), 0, "an unflagged photo's point");
        let seven = img.height();
        for (i, f) in fr.iter_mut().enumerate() {
            f.altitude = (i > 2).then_some(3.0 + i as f32 / 10.0);
        }
        assert_eq!(overview_series(&fr, &t).len(), 8);
        assert_eq!(overview(&fr, &t).height(), seven + 22 + 130 + 30);
    }

    /// The flagged sheet has a title over each column, above the first photo's name.
    #[test]
    fn the_flagged_sheet_has_column_titles() {
        let d = tempfile::tempdir().unwrap();
        let fr = frames(1, d.path());
        RgbImage::from_pixel(64, 48, image::Rgb([120, 110, 100]))
            .save(&fr[0].output)
            .unwrap();
        let lit = Raster::filled(8, 6, 3, 0.3);
        let rows = vec![(fr[0].clone(), "a reason".to_string(), &lit)];
        let img = flagged_sheet_with(&rows, 100).unwrap();
        // Gap 6, two 100-pixel columns; the titles' line at y 6..14, the photo's name 32 pixels lower.
        assert!(
            ink(&img, (6, 106), (6, 14)) > 20,
            "title of the corrected column"
        );
        assert!(
            ink(&img, (112, 212), (6, 14)) > 20,
            "title of the F·C column"
        );
        assert!(
            ink(&img, (6, 106), (38, 46)) > 5,
            "the photo's name below the titles"
        );
        assert_eq!(img.height(), 6 + 32 + 40 + 75 + 6);
    }

    #[test]
    fn factor_preview_of_grey_and_broken_rasters() {
        let g = Raster::from_fn(4, 2, 1, |x, y, _| if x + y == 0 { f32::NAN } else { 0.2 });
        let p = scaled_rgb(&g, 0.995);
        assert_eq!(p.get_pixel(0, 0).0, [0, 0, 0], "NaN is drawn black");
        assert_eq!(
            p.get_pixel(1, 0).0,
            [255, 255, 255],
            "grey replicated, scaled to white"
        );
        let dark = scaled_rgb(&Raster::filled(3, 3, 3, 0.0), 0.995);
        assert_eq!(
            dark.get_pixel(1, 1).0,
            [0, 0, 0],
            "an all-black F stays black"
        );
    }
}
