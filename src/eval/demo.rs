//! `abysslight demo`: simulate a small dive, correct it with every method, score the results against the truth and
//! draw a contact sheet (raw | mean | polynomial | paper | abyss (the default) | truth) — a one-command tour with
//! no data needed.

use std::path::{Path, PathBuf};
use std::time::Instant;

use image::{Rgb, RgbImage};

use crate::error::{Error, Result};
use crate::eval::evaluate::{evaluate, EvalSettings, Evaluation};
use crate::eval::simulate::{Simulation, Truth};
use crate::io::decode;
use crate::method::baseline::Method;
use crate::method::raster::Raster;
use crate::method::transfer::Transfer;
use crate::report::Progress;
use crate::run::draw::{self, BLACK, WHITE};
use crate::run::options::Options;
use crate::run::pictures::save_png;

/// What the demo did.
#[derive(Debug, Clone)]
pub struct DemoReport {
    /// Scores of every method against the simulated truth.
    pub evaluation: Evaluation,
    /// The contact sheet written (`out/contact-sheet.png`).
    pub sheet: PathBuf,
    /// The scores as a Markdown table (`out/scores.md`).
    pub scores_md: PathBuf,
    /// Wall-clock seconds of the whole demo.
    pub seconds: f64,
}

/// What each column of `scores.md` means, written under the table (definitions as in docs/evaluation.md).
pub const SCORES_LEGEND: &str = "
Lower is better in every column. Each method corrected the same simulated dive; the scores compare its output
with the dive's true albedo (details: docs/evaluation.md in the abysslight repository).

- **method**: `raw` is the uncorrected photos; `mean` divides by the mission's mean image; `polynomial` fits a
  robust polynomial of log intensity per photo; `paper` is Köser et al. as published; `abyss` (abysslight's
  default) is the paper's window (its (1 + c)/2 quantile for a contamination c of dark nodules) plus a per-photo
  gain, a floor relative to the photo's lit level and a noise-aware blend of dim regions.
- **photos**: photos scored.
- **albedo error**: sum of |corrected - s*true albedo| / sum of s*true albedo over every sample of every photo,
  with s the least-squares scale per channel (so a white balance is not counted as error). 0 is perfect.
- **residual pattern**: lighting left in the photos. The frame is cut into 8x6 cells; per cell the median of
  corrected / (s*true albedo) over all photos; reported is the robust spread of those cell medians
  (1.4826*MAD / median). 0 means no trace of the light cones; a channel left black scores 1 (all of it lost).
- **consistency** (Köser et al.): overlapping photos should show a patch of seafloor alike. Per mosaic cell seen
  whole by two or more photos, the RMS difference of each photo's mean from the cell's mean, divided by the
  standard deviation of all pixels. 0 means overlapping photos agree exactly.
- **overlap difference**: the same RMS difference over overlaps, divided by the mean of all pixels instead of their
  standard deviation (so a correction that flattens the photos is not rewarded or punished through the divisor).
- **clipped**: the share of samples at black or white. Overlapping photos clipped at the same place agree whatever
  lies there, so a method that clips much of its output scores better overlaps than it earns.
";

/// The dive the demo renders: an abyssal dive of the kind abysslight is for (dive a05 of the dive matrix,
/// docs/evaluation.md): 30 photos of 320×240, three lights with 25° beams, clear ocean water (red attenuated
/// ~0.4/m), 5 m ± 0.4 m, 15 % nodules, ×6 red white balance, exposure from the brightest sediment, 8-bit sRGB.
/// (`Simulation::default()` is the older bright 3 m dive.)
pub fn demo_simulation() -> Simulation {
    let d = Simulation::default();
    crate::eval::matrix::dive("a05")
        .expect("a05 is in the matrix")
        .simulation(d.seed, (d.width, d.height))
}

/// Run the demo into `out` (`out/dive/` the simulated dive, `out/<method>/` the corrected photos,
/// `out/contact-sheet.png`, `out/scores.md`, `out/scores.json`).
pub fn run_demo(out: &Path, sim: &Simulation, progress: &dyn Progress) -> Result<DemoReport> {
    let started = Instant::now();
    let dive = out.join("dive");
    progress.stage(&format!(
        "simulating a dive of {} photos ({}x{}, {:.0} % nodules) into {}",
        sim.frames,
        sim.width,
        sim.height,
        100.0 * sim.contamination,
        dive.display()
    ));
    let truth = sim.write(&dive)?;
    let sets = correct_all(out, &dive, sim, progress)?;
    progress.stage("scoring against the true albedo");
    let evaluation = evaluate(&sets, Some(&dive), None, &EvalSettings::default())?;
    let scores_md = save_scores(out, &evaluation)?;
    let sheet = contact_sheet(out, &dive, &truth, &sets, &evaluation, sim)?;
    Ok(DemoReport {
        evaluation,
        sheet,
        scores_md,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// Correct the simulated dive in `dive` with every method into `out/<method>/`: the sets to score, labelled,
/// the raw photos first.
fn correct_all(
    out: &Path,
    dive: &Path,
    sim: &Simulation,
    progress: &dyn Progress,
) -> Result<Vec<(String, PathBuf)>> {
    let methods = [
        Method::Mean,
        Method::Polynomial,
        Method::Paper,
        Method::Abyss,
    ];
    let mut sets = vec![("raw".to_string(), dive.join("survey"))];
    for m in methods {
        progress.stage(&format!("correcting with --method {m}"));
        let opts = Options {
            water_column: Some(dive.join("water")),
            survey: Some(dive.join("survey")),
            out: Some(out.join(m.to_string())),
            contamination: Some(sim.contamination.max(0.01)),
            transfer: Some(sim.encode),
            method: m,
            ..Options::default()
        };
        crate::correct_mission(&opts, &crate::Silent)?;
        sets.push((m.to_string(), out.join(m.to_string())));
    }
    Ok(sets)
}

/// Write the scores to `out/scores.json` and, as a table with its legend, `out/scores.md`; returns the latter.
fn save_scores(out: &Path, evaluation: &Evaluation) -> Result<PathBuf> {
    let scores_json = out.join("scores.json");
    evaluation.save_json(&scores_json)?;
    let scores_md = out.join("scores.md");
    crate::io::write_with(&scores_md, |w| {
        use std::io::Write;
        w.write_all(format!("{}{SCORES_LEGEND}", evaluation.table()).as_bytes())
            .map_err(|e| Error::io(&scores_md, e))
    })?;
    Ok(scores_md)
}

/// Draw the contact sheet into `out/contact-sheet.png`: three photos spread over the dive in `dive`, one row each,
/// in every set and the true albedo, each column captioned with its set's scores.
fn contact_sheet(
    out: &Path,
    dive: &Path,
    truth: &Truth,
    sets: &[(String, PathBuf)],
    evaluation: &Evaluation,
    sim: &Simulation,
) -> Result<PathBuf> {
    let n = truth.poses.len();
    let picks: Vec<usize> = if n >= 3 {
        vec![n / 6, n / 2, n - 1 - n / 6]
    } else {
        (0..n).collect()
    };
    let mut rows = Vec::new();
    for &i in &picks {
        let name = &truth.poses[i].file;
        let mut row = Vec::new();
        for (_, folder) in sets {
            row.push(display(&decode(&folder.join(name))?, sim.encode, None));
        }
        let albedo = decode(&dive.join("truth").join("albedo").join(name))?;
        row.push(display(&albedo, Transfer::Linear, Some(0.4)));
        rows.push((name.clone(), row));
    }
    let mut labels: Vec<String> = sets.iter().map(|(l, _)| l.clone()).collect();
    labels.push("truth".into());
    let scores: Vec<String> = evaluation
        .sets
        .iter()
        .map(|s| {
            format!(
                "err {:.3}  pattern {:.3}",
                s.albedo_error.unwrap_or(f64::NAN),
                s.residual_pattern.unwrap_or(f64::NAN)
            )
        })
        .chain(std::iter::once("true albedo".to_string()))
        .collect();
    let sheet_img = sheet(&labels, &scores, &rows, sim);
    let sheet = out.join("contact-sheet.png");
    save_png(&sheet_img, &sheet)?;
    Ok(sheet)
}

/// An RGB picture for people: linearised with `transfer`, optionally scaled so each channel's median is `level`,
/// then sRGB-encoded.
fn display(p: &crate::method::raster::Photo, transfer: Transfer, level: Option<f32>) -> RgbImage {
    let mut r = Raster::from_photo(p);
    for v in &mut r.data {
        *v = transfer.to_linear(*v);
    }
    let c = r.channels;
    let gains: Vec<f32> = (0..c)
        .map(|ch| match level {
            Some(l) => {
                let mut v: Vec<f32> = r.data.iter().skip(ch).step_by(c).copied().collect();
                v.sort_by(f32::total_cmp);
                l / v[v.len() / 2].max(1e-6)
            }
            None => 1.0,
        })
        .collect();
    RgbImage::from_fn(r.width as u32, r.height as u32, |x, y| {
        let px = |ch: usize| {
            let src = if c == 3 { ch } else { 0 };
            let v = r.get(x as usize, y as usize, src) * gains[src];
            (Transfer::Srgb.from_linear(v) * 255.0 + 0.5) as u8
        };
        Rgb([px(0), px(1), px(2)])
    })
}

fn sheet(
    labels: &[String],
    scores: &[String],
    rows: &[(String, Vec<RgbImage>)],
    sim: &Simulation,
) -> RgbImage {
    let tile_w = 240u32;
    let tile_h = (sim.height as u32 * tile_w) / sim.width as u32;
    let (margin, gap, head, title_h) = (12i64, 6i64, 40i64, 34i64);
    let cols = labels.len() as i64;
    let width = (2 * margin + cols * tile_w as i64 + (cols - 1) * gap) as u32;
    let height = (title_h + head + rows.len() as i64 * (tile_h as i64 + gap) + margin + 16) as u32;
    let mut img = RgbImage::from_pixel(width, height, Rgb([245, 245, 242]));
    let title = format!(
        "abysslight demo: simulated dive, {} photos, {:.0} % nodules - lower scores are better",
        sim.frames,
        100.0 * sim.contamination
    );
    draw::text(
        &mut img,
        margin,
        10,
        &title,
        2.min(fit_scale(&title, width - 24)),
        BLACK,
    );
    for (j, (label, score)) in labels.iter().zip(scores).enumerate() {
        let x = margin + j as i64 * (tile_w as i64 + gap);
        draw::text(&mut img, x, title_h, label, 2, BLACK);
        draw::text(&mut img, x, title_h + 20, score, 1, Rgb([70, 70, 70]));
    }
    for (i, (name, tiles)) in rows.iter().enumerate() {
        let y = title_h + head + i as i64 * (tile_h as i64 + gap);
        for (j, t) in tiles.iter().enumerate() {
            let x = margin + j as i64 * (tile_w as i64 + gap);
            let small = draw::tile(t, tile_w, true);
            image::imageops::replace(&mut img, &small, x, y);
        }
        draw::fill_rect(
            &mut img,
            margin + 2,
            y + 2,
            draw::text_width(name, 1) + 4,
            12,
            BLACK,
        );
        draw::text(&mut img, margin + 4, y + 4, name, 1, WHITE);
    }
    let foot = "raw: as recorded; mean / polynomial: baselines; paper: Koser et al. as published; abyss: the default; \
                truth: simulated albedo";
    draw::text(
        &mut img,
        margin,
        height as i64 - 14,
        foot,
        1,
        Rgb([70, 70, 70]),
    );
    img
}

fn fit_scale(s: &str, width: u32) -> u32 {
    if draw::text_width(s, 2) <= width {
        2
    } else {
        1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small demo end to end: scores.md holds the table and, under it, a legend entry for every column of
    /// that table and every method in it.
    #[test]
    fn scores_md_explains_every_column_and_method() {
        let d = tempfile::tempdir().unwrap();
        let sim = Simulation {
            frames: 9,
            water_column: 5,
            width: 64,
            height: 48,
            ..demo_simulation()
        };
        let r = run_demo(d.path(), &sim, &crate::Silent).unwrap();
        let md = std::fs::read_to_string(&r.scores_md).unwrap();
        let (table, legend) = md.split_at(md.find("Lower is better").expect("a legend"));
        let header = table.lines().next().unwrap();
        let columns: Vec<&str> = header
            .split('|')
            .map(str::trim)
            .filter(|c| !c.is_empty())
            .collect();
        assert!(columns.len() >= 4, "{header}");
        for c in &columns {
            assert!(legend.contains(&format!("**{c}**")), "no legend for {c:?}");
        }
        let methods: Vec<&str> = table
            .lines()
            .skip(2)
            .filter_map(|l| l.split('|').nth(1).map(str::trim))
            .collect();
        assert_eq!(methods.len(), 5, "{table}");
        for m in methods {
            assert!(
                legend.contains(&format!("`{m}`")),
                "no legend for method {m:?}"
            );
        }
    }
}
