//! The method as a library: the in-memory [`Engine`] on simulated dives, without touching the disk, and the same
//! result as a folder run.

use abysslight::eval::evaluate::albedo_error;
use abysslight::eval::simulate::Simulation;
use abysslight::Error;
use abysslight::Scatter;
use abysslight::{Engine, Params, Use};
use abysslight::{Layout, Photo, Raster, Samples};

fn small_dive(seed: u64, frames: usize) -> abysslight::eval::simulate::Dive {
    Simulation {
        frames,
        water_column: 9,
        width: 128,
        height: 96,
        seed,
        ..Simulation::default()
    }
    .render()
    .unwrap()
}

#[test]
fn engine_corrects_a_dive_in_memory_in_order_with_bounded_memory() {
    let dive = small_dive(5, 15);
    let scatter = Scatter::from_frames(&dive.water).unwrap();
    let n = 5;
    let mut engine = Engine::new(
        Params {
            window: abysslight::Window::Fixed(n),
            ..Params::default()
        },
        scatter.as_ref(),
        None,
    )
    .unwrap();
    let mut out = Vec::new();
    for (i, p) in dive.survey.iter().cloned().enumerate() {
        out.extend(engine.push((p, i)).unwrap());
        // A photo waits only for the n/2 photos after it (n at the start of the mission).
        assert!(engine.waiting() <= n, "{} waiting", engine.waiting());
        if i >= n {
            assert!(engine.waiting() <= n / 2 + 1);
        }
    }
    out.extend(engine.finish());
    let tags: Vec<usize> = out.iter().map(|c| c.tag).collect();
    assert_eq!(tags, (0..15).collect::<Vec<_>>());
    for c in &out {
        assert_eq!(c.window.len(), n);
        assert!(c.window.span().contains(&c.index) && !c.window.by_altitude());
        // Params::default() blocks are auto, as the command line's: 4 for photos 128 wide.
        assert_eq!(
            c.factor.width,
            128 / abysslight::kernels::auto_block(128, 96)
        );
        assert!(c.health.contamination < 0.4, "{:?}", c.health);
    }
    assert_eq!(out[0].window.span(), 0..5, "shifted at the start");
    assert_eq!(out[7].window.span(), 5..10, "centred");
    assert_eq!(out[14].window.span(), 10..15, "shifted at the end");
    assert_eq!(out[7].window.photos(), &[5, 6, 7, 8, 9]);
    let got: Vec<Raster> = out
        .iter()
        .map(|c| Raster::from_photo(c.photo.as_ref().unwrap()))
        .collect();
    let raw: Vec<Raster> = dive.survey.iter().map(Raster::from_photo).collect();
    let (before, after) = (
        albedo_error(&raw, &dive.albedo, None),
        albedo_error(&got, &dive.albedo, None),
    );
    assert!(after < 0.4 * before, "albedo error {before} -> {after}");
}

#[test]
fn other_uses_and_a_photo_of_another_size() {
    let dive = small_dive(6, 9);
    let mut engine = Engine::new(
        Params {
            window: abysslight::Window::Fixed(3),
            ..Params::default()
        },
        None,
        None,
    )
    .unwrap();
    let mut out = Vec::new();
    for (i, p) in dive.survey.iter().cloned().enumerate() {
        let use_ = match i {
            0 | 1 => Use::Context,
            4 => Use::Estimate,
            _ => Use::Correct,
        };
        out.extend(engine.push((p, i, use_)).unwrap());
        if i == 5 {
            let odd = Photo {
                layout: Layout {
                    width: 64,
                    height: 48,
                    channels: 3,
                },
                samples: Samples::U8(vec![9; 64 * 48 * 3]),
                alpha: None,
            };
            let e = engine.push((odd, 99)).unwrap_err();
            assert!(matches!(e, Error::Mismatch { .. }), "{e}");
            assert!(e.to_string().contains("64x48"), "{e}");
        }
    }
    out.extend(engine.finish());
    let tags: Vec<usize> = out.iter().map(|c| c.tag).collect();
    assert_eq!(
        tags,
        vec![2, 3, 4, 5, 6, 7, 8],
        "context photos never come out"
    );
    assert_eq!(engine.accepted(), 9, "the odd photo was refused");
    for c in &out {
        assert_eq!(
            c.photo.is_none(),
            c.tag == 4,
            "estimate-only comes out without a photo"
        );
    }
}

#[test]
fn engine_and_folder_run_give_the_same_photos() {
    let d = tempfile::tempdir().unwrap();
    let sim = Simulation {
        frames: 9,
        water_column: 5,
        width: 96,
        height: 64,
        seed: 8,
        ..Simulation::default()
    };
    sim.write(&d.path().join("dive")).unwrap();
    let opts = abysslight::Options {
        water_column: Some(d.path().join("dive/water")),
        survey: Some(d.path().join("dive/survey")),
        out: Some(d.path().join("out")),
        window: Some(5),
        ..abysslight::Options::default()
    };
    abysslight::correct_mission(&opts, &abysslight::Silent).unwrap();

    let decode = |p: &std::path::Path| abysslight::io::decode(p).unwrap();
    let frames = abysslight::io::find_photos(&d.path().join("dive/survey"))
        .unwrap()
        .photos;
    let water = abysslight::io::find_photos(&d.path().join("dive/water"))
        .unwrap()
        .photos;
    let water: Vec<Photo> = water.iter().map(|e| decode(&e.path)).collect();
    let scatter = Scatter::from_frames(&water).unwrap();
    let mut engine = Engine::new(
        Params {
            window: abysslight::Window::Fixed(5),
            // The folder run's `--downsample auto` for photos of this size (the engine takes a block size).
            downsample: abysslight::kernels::auto_block(96, 64),
            ..Params::default()
        },
        scatter.as_ref(),
        None,
    )
    .unwrap();
    let mut out = Vec::new();
    for e in &frames {
        out.extend(engine.push((decode(&e.path), e.relative.clone())).unwrap());
    }
    out.extend(engine.finish());
    assert_eq!(out.len(), 9);
    for c in out {
        let written = decode(&d.path().join("out").join(&c.tag));
        assert_eq!(
            c.photo.unwrap().samples,
            written.samples,
            "{}",
            c.tag.display()
        );
    }
}

/// A laser dot that wanders with the altitude sits on the same blocks in most photos of a window. Kept, the
/// window's median takes it into `F` there and the photos without it come out with a dark red hole (on real
/// Nephrops photos: teal stains beside the red dots); with `bright_spots` (`--bright-spots`) `F` is filled there
/// from the blocks around, and no stain is left. Synthetic photos: a smooth light cone over grey mud with a fine
/// texture that moves with the camera, and a red dot at one place, 16 pixels to the right in photos 5–7 (the
/// vehicle bounced).
#[test]
fn a_wandering_laser_dot_leaves_no_stain_where_it_is_not() {
    use abysslight::Method;
    let (w, h, frames) = (128usize, 96usize, 15usize);
    let (ay, ax, bx, r) = (48.0f32, 40.0f32, 56.0f32, 3.5f32);
    let photo = |k: usize| {
        let mut v = vec![0u8; w * h * 3];
        for y in 0..h {
            for x in 0..w {
                let (fx, fy) = (x as f32 - 64.0, y as f32 - 48.0);
                let light = 0.8 * (-(fx * fx + fy * fy) / (2.0 * 45.0 * 45.0)).exp();
                let gx = (x + 3 * k) as u64;
                let hash =
                    (gx.wrapping_mul(73_856_093) ^ (y as u64).wrapping_mul(19_349_663)) % 1000;
                let albedo = 0.5 * (0.95 + 0.1 * hash as f32 / 1000.0);
                let dx = if (5..8).contains(&k) { bx } else { ax };
                let on_dot = (x as f32 - dx).hypot(y as f32 - ay) <= r;
                for ch in 0..3 {
                    let mut l = albedo * light;
                    if on_dot {
                        l = if ch == 0 { 1.0 } else { l * 1.2 };
                    }
                    v[(y * w + x) * 3 + ch] = (l * 255.0).round().clamp(0.0, 255.0) as u8;
                }
            }
        }
        Photo {
            layout: Layout {
                width: w,
                height: h,
                channels: 3,
            },
            samples: Samples::U8(v),
            alpha: None,
        }
    };
    // Red in a disc around (x, ay) against red in a ring of the same photo well away from both dots.
    let red_ratio = |p: &Raster, x: f32| {
        let (mut inside, mut n_in, mut around, mut n_around) = (0.0f64, 0, 0.0f64, 0);
        for y in 0..h {
            for xx in 0..w {
                let d = (xx as f32 - x).hypot(y as f32 - ay);
                let red = p.get(xx, y, 0) as f64;
                if d <= r + 1.0 {
                    inside += red;
                    n_in += 1;
                } else if (16.0..24.0).contains(&(y as f32 - ay).abs())
                    && (xx as f32 - x).abs() < 8.0
                {
                    around += red;
                    n_around += 1;
                }
            }
        }
        (inside / n_in as f64) / (around / n_around as f64)
    };
    let run = |bright_spots: bool| {
        let mut engine = Engine::new(
            Params {
                method: Method::Abyss,
                window: abysslight::Window::Fixed(9),
                downsample: 4,
                steps: abysslight::Steps {
                    bright_spots,
                    ..Default::default()
                },
                ..Params::default()
            },
            None,
            None,
        )
        .unwrap();
        let mut out = Vec::new();
        for k in 0..frames {
            out.extend(engine.push((photo(k), k)).unwrap());
        }
        out.extend(engine.finish());
        out.iter()
            .map(|c| Raster::from_photo(c.photo.as_ref().unwrap()))
            .collect::<Vec<_>>()
    };
    // Photos 5–7 lack the dot at A, which 6 of the 9 photos of their windows have; every photo is scored at the
    // place of the dot it lacks, the worst one counts.
    let worst = |photos: &[Raster]| {
        photos
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let missing = if (5..8).contains(&k) { ax } else { bx };
                red_ratio(p, missing)
            })
            .fold(f64::INFINITY, f64::min)
    };
    let (with, without) = (worst(&run(true)), worst(&run(false)));
    eprintln!("red where the photo has no dot, against the mud around: with bright_spots {with:.3}, without {without:.3}");
    assert!(with > 0.9, "stain with bright_spots: {with}");
    assert!(
        without < 0.8,
        "the stain this guards against did not show: {without}"
    );
}

/// The photos an engine holds in full (waiting for the photos after them) stay under the bounds docs/live.md and
/// docs/python.md state, for windows up to 31 photos, with and without altitudes: a window of `n` holds `n` photos
/// at the start of a mission and `n/2 + 1` after; chosen by altitude `2n + 1` and `n + 1`; at the default (the
/// window chosen per stretch as the photos come, up to 31) 41 and 26, with altitudes 63 and 32. A photo is counted
/// from its push (the photo being pushed included) until it comes out. The fixed windows reach their bounds.
#[test]
fn the_photos_held_stay_under_the_stated_bounds() {
    let altitude = |i: usize| 2.0 + 0.8 * (i as f32 * 0.4).sin();
    // The most photos held at the start (before the `start`-th push) and after.
    let peaks = |mut engine: Engine<usize>, photos: Vec<Photo>, alt: bool, start: usize| {
        let (mut first, mut after, total) = (0, 0, photos.len());
        let mut out = Vec::new();
        for (i, p) in photos.into_iter().enumerate() {
            let held = engine.waiting() + 1;
            match i < start {
                true => first = first.max(held),
                false => after = after.max(held),
            }
            out.extend(engine.push((p, i, alt.then(|| altitude(i)))).unwrap());
        }
        out.extend(engine.finish());
        assert_eq!(out.len(), total, "every photo comes out");
        let longest = out
            .iter()
            .filter_map(|c| c.choice.as_ref())
            .map(|c| c.window)
            .max();
        (first, after, longest)
    };
    let noise = |i: usize| {
        let mut r = (i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        let samples = (0..32 * 24 * 3)
            .map(|_| {
                r ^= r << 13;
                r ^= r >> 7;
                r ^= r << 17;
                60 + (r % 120) as u8
            })
            .collect();
        Photo {
            layout: Layout {
                width: 32,
                height: 24,
                channels: 3,
            },
            samples: Samples::U8(samples),
            alpha: None,
        }
    };
    for n in (1..=31).step_by(2) {
        for alt in [false, true] {
            let (start, after) = match alt {
                false => (n, n / 2 + 1),
                true => (2 * n + 1, n + 1),
            };
            let params = Params {
                window: abysslight::Window::Fixed(n),
                ..Params::default()
            };
            let engine = Engine::new(params, None, None).unwrap();
            let photos = (0..2 * start + 5).map(noise).collect();
            let (first, later, _) = peaks(engine, photos, alt, start);
            assert_eq!(
                (first, later),
                (start, after),
                "window {n}, altitudes {alt}"
            );
        }
    }
    // At the default, on a dense field under a slow camera, whose windows grow long.
    let photos = Simulation {
        frames: 140,
        width: 128,
        height: 96,
        contamination: 0.45,
        overlap: 0.9,
        seed: 4,
        ..Simulation::default()
    }
    .render()
    .unwrap()
    .survey;
    for alt in [false, true] {
        let (start, after) = match alt {
            false => (41, 26),
            true => (63, 32),
        };
        let mut engine = Engine::new(Params::default(), None, None).unwrap();
        if alt {
            engine.expect_altitudes().unwrap();
        }
        let (first, later, longest) = peaks(engine, photos.clone(), alt, start);
        eprintln!(
            "default window, altitudes {alt}: {first} photos held at the start, {later} after (windows up to \
             {longest:?})"
        );
        assert!(
            first <= start && later <= after,
            "altitudes {alt}: {first}, {later}"
        );
        assert!(
            first >= 41,
            "the first photo waits for the survey's first decision: {first}"
        );
        // Windows of up to 31 chosen by altitude: the first photos wait for their pools, past the 41.
        assert!(!alt || first > 41, "{first}");
    }
}
