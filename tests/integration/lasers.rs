//! Laser dots at default options: where red dots come back to the same blocks in the first photos, the default
//! leaves their paths out of `F` (the dots stay red, no teal stain where they are not), says so, and the in-memory
//! `Engine` finds the same paths and writes the batch command's pixels; dives without lasers get no paths.

use crate::common::*;

use std::path::Path;

use abysslight::eval::matrix;
use abysslight::io::{decode, find_photos};
use abysslight::{correct_mission, Engine, Options, Params, Photo, Samples, Silent, Transfer};

const W: usize = 160;
const H: usize = 120;
const FRAMES: usize = 45;

/// Photo `i`'s three dots: their place drifts with a slowly swinging altitude (up to 12 pixels), so over a window of
/// 7 photos a dot sits on nearly the same blocks, and photos a quarter swing apart have it elsewhere.
fn dots(i: usize) -> [(f32, f32); 3] {
    let drift = 12.0 * (i as f32 * 0.3).sin();
    [
        (40.0 - drift, 60.0),
        (80.0, 35.0 + 0.5 * drift),
        (120.0 + drift, 60.0),
    ]
}

/// Within `r` pixels of one of the dots of photo `i`.
fn near_dot(i: usize, x: usize, y: usize, r: f32) -> bool {
    dots(i)
        .iter()
        .any(|&(dx, dy)| (x as f32 - dx).powi(2) + (y as f32 - dy).powi(2) <= r * r)
}

/// A sparse dive (8-bit, linear) with red laser dots painted on its survey photos.
fn laser_dive() -> Dive {
    let mut d = dive(W, H, FRAMES, 0, 0.05, false, 11);
    for (i, p) in d.photos.iter_mut().enumerate() {
        let Samples::U8(v) = &mut p.samples else {
            panic!("an 8-bit dive")
        };
        for y in 0..H {
            for x in 0..W {
                let px = &mut v[(y * W + x) * 3..(y * W + x) * 3 + 3];
                // Three times the red of the ground beneath, its glow 1.6 times.
                if near_dot(i, x, y, 2.5) {
                    px[0] = (f32::from(px[0]) * 3.0).min(255.0) as u8;
                } else if near_dot(i, x, y, 4.5) {
                    px[0] = (f32::from(px[0]) * 1.6).min(255.0) as u8;
                }
            }
        }
    }
    d
}

/// The mean of `(G + B)/2 − R` of photo `i`'s output where the dots of the photos within 3 of it were and its own
/// are not (grown by 8 pixels): the teal stain a dot taken into `F` leaves.
fn stain(i: usize, out: &Photo) -> f64 {
    let Samples::U8(v) = &out.samples else {
        panic!("8-bit outputs")
    };
    let (mut sum, mut n) = (0.0, 0usize);
    for y in 0..H {
        for x in 0..W {
            let others = (i.saturating_sub(3)..(i + 4).min(FRAMES))
                .any(|j| j != i && near_dot(j, x, y, 3.0));
            if others && !near_dot(i, x, y, 8.0) {
                let p = &v[(y * W + x) * 3..(y * W + x) * 3 + 3];
                sum += (f64::from(p[1]) + f64::from(p[2])) / 2.0 - f64::from(p[0]);
                n += 1;
            }
        }
    }
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

/// The outputs of a run, in the survey's order.
fn outputs_of(dir: &Path) -> Vec<Photo> {
    find_photos(dir)
        .unwrap()
        .photos
        .into_iter()
        .map(|e| decode(&e.path).unwrap())
        .collect()
}

/// The worst photo's stain, and how red the photos' own dots came out (the median over photos of the mean
/// `R − (G + B)/2` within 2 pixels of the dots).
fn stains_and_red(outs: &[Photo]) -> (f64, f64) {
    // The worst photo's: a stain shows where a dot left the blocks it held in most of the window.
    let worst = (0..FRAMES)
        .map(|i| stain(i, &outs[i]))
        .fold(f64::NEG_INFINITY, f64::max);
    let reds: Vec<f64> = (0..FRAMES)
        .map(|i| {
            let Samples::U8(v) = &outs[i].samples else {
                panic!("8-bit outputs")
            };
            let (mut sum, mut n) = (0.0, 0usize);
            for y in 0..H {
                for x in 0..W {
                    if near_dot(i, x, y, 2.0) {
                        let p = &v[(y * W + x) * 3..(y * W + x) * 3 + 3];
                        sum += f64::from(p[0]) - (f64::from(p[1]) + f64::from(p[2])) / 2.0;
                        n += 1;
                    }
                }
            }
            sum / n as f64
        })
        .collect();
    // The median photo's: a dot on a dark patch of ground stays dark.
    let mut reds = reds;
    reds.sort_by(f64::total_cmp);
    let red = reds[FRAMES / 2];
    (worst, red)
}

#[test]
fn at_default_options_laser_dots_stay_red_leave_no_stain_and_are_reported() {
    let d = tempfile::tempdir().unwrap();
    let dive = laser_dive();
    let survey = d.path().join("survey");
    write_all(&dive.photos, &survey, "img", "png");
    let run = |out: &str, laser_paths: bool| {
        let opts = Options {
            survey: Some(survey.clone()),
            out: Some(d.path().join(out)),
            laser_paths,
            // The curve the dive was made in, given so that the engine takes the same.
            transfer: Some(Transfer::Linear),
            ..Options::default()
        };
        let report = correct_mission(&opts, &Silent).unwrap();
        assert_eq!(report.corrected, FRAMES);
        (opts, report)
    };
    let (opts, report) = run("default", true);
    let (_, off) = run("off", false);

    // Said, with the share of the frame and the way to turn it off; the mask written beside the report.
    let said: Vec<&String> = report
        .warnings
        .iter()
        .filter(|w| w.starts_with("laser dots"))
        .collect();
    assert_eq!(said.len(), 1, "{:?}", report.warnings);
    assert!(
        said[0].contains("% of the frame") && said[0].contains("--no-laser-paths"),
        "{}",
        said[0]
    );
    assert!(d
        .path()
        .join("default/_abysslight/laser-paths.png")
        .is_file());
    // Without the paths the survey warns of them instead, naming the fix.
    assert!(
        off.warnings
            .iter()
            .any(|w| w.starts_with("laser dots") && w.contains("--no-laser-paths")),
        "{:?}",
        off.warnings
    );

    let default_outs = outputs_of(&d.path().join("default"));
    let (stain_on, red_on) = stains_and_red(&default_outs);
    let (stain_off, red_off) = stains_and_red(&outputs_of(&d.path().join("off")));
    assert!(
        stain_off > 4.0,
        "without the paths the dots stain the photos where they are not: {stain_off:.2} ({stain_on:.2} with)"
    );
    assert!(
        stain_on < 0.4 * stain_off,
        "the paths left out of F take the stain away: {stain_on:.2} against {stain_off:.2}"
    );
    assert!(
        red_on > 100.0 && red_on > red_off + 40.0,
        "the dots stay red: {red_on:.1} ({red_off:.1} with the dots in F)"
    );

    // The engine, pushed the photos one by one at the same options, finds the same paths in the same first photos
    // and writes the same pixels.
    let mut engine = Engine::new(opts.params().unwrap(), None, None).unwrap();
    let mut out = Vec::new();
    for e in find_photos(&survey).unwrap().photos {
        out.extend(engine.push((decode(&e.path).unwrap(), e.relative)).unwrap());
        if engine.accepted() <= abysslight::Engine::<u8>::FIRST_DECIDED {
            assert!(
                !engine.laser_paths_decided(),
                "decided from the first photos only"
            );
        }
    }
    out.extend(engine.finish());
    let share = engine
        .laser_paths_share()
        .expect("the engine finds the paths");
    assert!(share > 0.005 && share < 0.1, "{share}");
    assert_eq!(out.len(), FRAMES);
    for (c, batch) in out.iter().zip(&default_outs) {
        assert_eq!(
            c.photo.as_ref().unwrap().samples,
            batch.samples,
            "{}",
            c.tag.display()
        );
    }
}

/// Dives without lasers get no paths: the simple dive above without its dots, sparse and dense; the matrix's
/// nodule fields and abyssal dives at 160×120 (the engine's own look at their first 41 photos).
#[test]
fn dives_without_lasers_get_no_laser_paths() {
    let mut dives: Vec<(String, Vec<Photo>)> = [0.05f32, 0.3]
        .iter()
        .map(|&c| {
            (
                format!("plain {c}"),
                dive(W, H, FRAMES, 0, c, false, 12).photos,
            )
        })
        .collect();
    for name in ["g02", "n01", "n06", "a01", "a03", "a09"] {
        let (spec, seed) = matrix::dive_and_seed(name, 0).unwrap();
        let sim = spec.simulation(seed, (W, H));
        dives.push((name.to_string(), sim.render().unwrap().survey));
    }
    for (name, photos) in dives {
        let mut engine: Engine<usize> = Engine::new(Params::default(), None, None).unwrap();
        for (i, p) in photos.into_iter().enumerate() {
            engine.push((p, i)).unwrap();
        }
        engine.finish();
        assert!(engine.laser_paths_decided(), "{name}");
        assert!(
            engine.laser_paths_share().is_none(),
            "{name}: paths on {:.2} % of the frame",
            100.0 * engine.laser_paths_share().unwrap()
        );
    }
}

/// `photo` with one channel, its red: a grey photo of the mission's size.
fn grey(photo: &Photo) -> Photo {
    let Samples::U8(v) = &photo.samples else {
        panic!("an 8-bit dive")
    };
    Photo {
        layout: abysslight::Layout {
            channels: 1,
            ..photo.layout
        },
        samples: Samples::U8(v.iter().step_by(3).copied().collect()),
        alpha: None,
    }
}

/// `abysslight correct --survey - --out OUT` fed the photos of `survey` one after the other (in the run's order),
/// with `args`; its console.
fn piped(survey: &Path, out: &Path, args: &[&str]) -> String {
    use std::process::{Command, Stdio};
    let mut input = Vec::new();
    for e in find_photos(survey).unwrap().photos {
        input.extend(std::fs::read(&e.path).unwrap());
    }
    let mut child = Command::new(BIN)
        .args(["correct", "--survey", "-", "--out", s(out)])
        .args(args)
        .stdin(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let feeder = std::thread::spawn(move || std::io::Write::write_all(&mut stdin, &input));
    let o = child.wait_with_output().unwrap();
    feeder.join().unwrap().unwrap();
    stderr(&o)
}

/// One grey photo among the mission's first 41 (photo 5, of the mission's size): the engine refuses it (its channels
/// are not the mission's), and so do both of a batch run's passes over the folder, the survey and the look for the
/// paths of laser dots, which count the next colour photo instead. A run over the folder, `--survey -` and the engine
/// find the same paths and write the same pixels: in a mission of 45 photos, and in one of 20, where the grey photo
/// counted would make the 20 photos the paths are decided on (19 colour photos are too few).
#[test]
fn a_grey_photo_among_the_first_is_passed_over_by_the_batch_run_as_by_the_engine() {
    for frames in [FRAMES, 20] {
        let d = tempfile::tempdir().unwrap();
        let mut photos = laser_dive().photos;
        photos.truncate(frames);
        photos[5] = grey(&photos[5]);
        let survey = d.path().join("survey");
        write_all(&photos, &survey, "img", "png");
        let batch = d.path().join("batch");
        let opts = Options {
            survey: Some(survey.clone()),
            out: Some(batch.clone()),
            transfer: Some(Transfer::Linear),
            ..Options::default()
        };
        let report = correct_mission(&opts, &Silent).unwrap();
        assert_eq!(report.corrected, frames - 1);
        assert_eq!(report.failed, 1, "the grey photo is refused");
        let batch_outs = outputs_of(&batch);
        assert_eq!(batch_outs.len(), frames - 1);

        let piped_out = d.path().join("piped");
        let console = piped(&survey, &piped_out, &["--transfer", "linear", "-q"]);
        let piped_outs = outputs_of(&piped_out);
        assert_eq!(piped_outs.len(), frames - 1, "{console}");

        let mut engine = Engine::new(opts.params().unwrap(), None, None).unwrap();
        let mut out = Vec::new();
        for (i, e) in find_photos(&survey).unwrap().photos.into_iter().enumerate() {
            match engine.push((decode(&e.path).unwrap(), i)) {
                Ok(o) => out.extend(o),
                Err(abysslight::Error::Mismatch { .. }) => assert_eq!(i, 5),
                Err(e) => panic!("{e}"),
            }
        }
        out.extend(engine.finish());
        assert_eq!(out.len(), frames - 1);
        let note = report
            .warnings
            .iter()
            .find(|w| w.contains("they are left out of F"));
        match (frames, engine.laser_paths_share()) {
            (FRAMES, Some(share)) => {
                let note = note.expect("the batch run finds the paths");
                assert!(
                    note.contains(&format!("({:.1} % of the frame", 100.0 * share)),
                    "the batch run finds the engine's paths ({:.1} %): {note}",
                    100.0 * share
                );
            }
            (20, None) => assert!(note.is_none(), "paths from 19 colour photos: {note:?}"),
            (_, share) => panic!("{frames} photos: the engine's paths {share:?}"),
        }
        for (k, c) in out.iter().enumerate() {
            let want = &c.photo.as_ref().unwrap().samples;
            assert!(
                batch_outs[k].samples == *want,
                "{frames} photos: batch, photo {}",
                c.tag
            );
            assert!(
                piped_outs[k].samples == *want,
                "{frames} photos: --survey -, photo {}",
                c.tag
            );
        }
    }
}

/// Laser dots in a mission of fewer than 20 photos (12): too few photos to tell their paths from something red on
/// the seafloor, so they are not left out of `F`; the run says so and points to `--mask-auto`, over a folder and
/// through a pipe alike, and the engine decides on no paths.
#[test]
fn laser_dots_in_a_short_mission_are_said_with_the_way_to_mask_them() {
    let d = tempfile::tempdir().unwrap();
    let mut dive = laser_dive();
    dive.photos.truncate(12);
    let survey = d.path().join("survey");
    write_all(&dive.photos, &survey, "img", "png");
    let opts = Options {
        survey: Some(survey.clone()),
        out: Some(d.path().join("batch")),
        transfer: Some(Transfer::Linear),
        ..Options::default()
    };
    let report = correct_mission(&opts, &Silent).unwrap();
    assert_eq!(report.corrected, 12);
    let short: Vec<&String> = report
        .warnings
        .iter()
        .filter(|w| w.starts_with("laser dots"))
        .collect();
    assert_eq!(short.len(), 1, "{:?}", report.warnings);
    assert!(
        short[0].contains("12 photos")
            && short[0].contains("fewer than 20")
            && short[0].contains("--mask-auto"),
        "{}",
        short[0]
    );
    let console = piped(&survey, &d.path().join("piped"), &["--transfer", "linear"]);
    assert!(
        console.contains("fewer than 20") && console.contains("--mask-auto"),
        "{console}"
    );
    // A mission without dots of the same length is told nothing of lasers.
    let plain = d.path().join("plain");
    write_all(&dive_plain(12), &plain, "img", "png");
    let r = correct_mission(
        &Options {
            survey: Some(plain),
            out: Some(d.path().join("plain-out")),
            transfer: Some(Transfer::Linear),
            ..Options::default()
        },
        &Silent,
    )
    .unwrap();
    assert!(
        !r.warnings.iter().any(|w| w.starts_with("laser dots")),
        "{:?}",
        r.warnings
    );
    let mut engine = Engine::new(opts.params().unwrap(), None, None).unwrap();
    for (i, p) in dive.photos.into_iter().enumerate() {
        engine.push((p, i)).unwrap();
    }
    engine.finish();
    assert!(engine.laser_paths_decided() && engine.laser_paths_share().is_none());
}

/// The simple dive of [`laser_dive`] without its dots, `frames` photos.
fn dive_plain(frames: usize) -> Vec<Photo> {
    dive(W, H, frames, 0, 0.05, false, 11).photos
}
