//! The method as a library: the in-memory [`Engine`] on simulated dives, without touching the disk, and the same
//! result as a folder run.

use abysslight::eval::evaluate::albedo_error;
use abysslight::eval::simulate::Simulation;
use abysslight::method::engine::{Engine, Params, Use};
use abysslight::method::raster::{Layout, Photo, Raster, Samples};
use abysslight::method::scatter::Scatter;
use abysslight::Error;

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
            window: n,
            ..Params::default()
        },
        scatter.as_ref(),
        None,
    )
    .unwrap();
    let mut out = Vec::new();
    for (i, p) in dive.survey.iter().cloned().enumerate() {
        out.extend(engine.push(p, i).unwrap());
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
        assert!(c.window.contains(&c.index));
        assert_eq!(c.factor.width, 128 / 8);
        assert!(c.health.contamination < 0.4, "{:?}", c.health);
    }
    assert_eq!(out[0].window, 0..5, "shifted at the start");
    assert_eq!(out[7].window, 5..10, "centred");
    assert_eq!(out[14].window, 10..15, "shifted at the end");
    let got: Vec<Raster> = out
        .iter()
        .map(|c| Raster::from_photo(c.photo.as_ref().unwrap()))
        .collect();
    let raw: Vec<Raster> = dive.survey.iter().map(Raster::from_photo).collect();
    let (before, after) = (
        albedo_error(&raw, &dive.albedo),
        albedo_error(&got, &dive.albedo),
    );
    assert!(after < 0.4 * before, "albedo error {before} -> {after}");
}

#[test]
fn other_uses_and_a_photo_of_another_size() {
    let dive = small_dive(6, 9);
    let mut engine = Engine::new(
        Params {
            window: 3,
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
        out.extend(engine.push_as(p, i, use_).unwrap());
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
            let e = engine.push(odd, 99).unwrap_err();
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
            window: 5,
            // The folder run's `--downsample auto` for photos of this size (the engine takes a block size).
            downsample: abysslight::method::factor::auto_block(96, 64),
            ..Params::default()
        },
        scatter.as_ref(),
        None,
    )
    .unwrap();
    let mut out = Vec::new();
    for e in &frames {
        out.extend(engine.push(decode(&e.path), e.relative.clone()).unwrap());
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
