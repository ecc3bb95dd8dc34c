//! The crate root as a caller sees it: what it builds from `abysslight::` alone, that its types cross threads,
//! and that a caller's mistakes come back as errors, never as panics.

use abysslight::{
    Engine, Error, Layout, Mask, Options, Params, Photo, Raster, Report, Samples, Scatter, Use,
};

/// Compile-time: the engine and what feeds it can move to and be shared between threads (rayon, a server).
#[allow(dead_code)]
fn send_and_sync() {
    fn both<T: Send + Sync>() {}
    both::<Engine<usize>>();
    both::<Engine<std::path::PathBuf>>();
    both::<Scatter>();
    both::<Params>();
    both::<Options>();
    both::<Report>();
    both::<Photo>();
    both::<Raster>();
    both::<Mask>();
    both::<Error>();
}

fn photo(width: usize, height: usize, channels: usize, samples: usize) -> Photo {
    Photo {
        layout: Layout {
            width,
            height,
            channels,
        },
        samples: Samples::U8(vec![100; samples]),
        alpha: None,
    }
}

fn engine() -> Engine<usize> {
    Engine::new(
        Params {
            window: abysslight::Window::Fixed(3),
            ..Params::default()
        },
        None,
        None,
    )
    .unwrap()
}

/// Every malformed photo is refused by `push` with an error that says what is wrong; the engine goes on.
#[test]
fn a_callers_malformed_photo_is_an_error_not_a_panic() {
    let bad = [
        (photo(0, 8, 3, 0), "no pixels"),
        (photo(8, 8, 0, 0), "channels"),
        (photo(8, 8, 7, 8 * 8 * 7), "channels"),
        (photo(8, 8, 3, 10), "samples"),
        (photo(8, 8, 3, 8 * 8 * 3 + 1), "samples"),
        (
            Photo {
                alpha: Some(Samples::U8(vec![255; 5])),
                ..photo(8, 8, 3, 192)
            },
            "alpha",
        ),
        (
            Photo {
                alpha: Some(Samples::U16(vec![255; 64])),
                ..photo(8, 8, 3, 192)
            },
            "alpha",
        ),
    ];
    let mut e = engine();
    for (i, (p, why)) in bad.into_iter().enumerate() {
        let got = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| e.push((p, i))));
        let err = got.expect("no panic").expect_err("refused");
        assert!(err.to_string().contains(why), "{why}: {err}");
    }
    // The engine was not spoilt: a good mission still runs through it.
    let mut out = Vec::new();
    for i in 0..5 {
        out.extend(
            e.push((photo(16, 12, 3, 16 * 12 * 3), i, Use::Correct))
                .unwrap(),
        );
    }
    out.extend(e.finish());
    assert_eq!(out.len(), 5);
}

/// Water-column frames are checked the same way; no frames is no scatter, not an error.
#[test]
fn malformed_water_frames_are_errors_and_none_is_no_scatter() {
    assert!(Scatter::from_frames(&[]).unwrap().is_none());
    let e = Scatter::from_frames(&[photo(8, 8, 3, 192), photo(8, 8, 3, 12)]).unwrap_err();
    assert!(e.to_string().contains("frame 1"), "{e}");
    let e = Scatter::from_frames(&[photo(8, 8, 3, 192), photo(9, 8, 3, 216)]).unwrap_err();
    assert!(e.to_string().contains("9x8"), "{e}");
    // A scatter of another channel count than the photos: refused at the first photo.
    let grey = Scatter::from_frames(&[photo(8, 8, 1, 64)])
        .unwrap()
        .unwrap();
    let mut e = Engine::new(Params::default(), Some(&grey), None).unwrap();
    assert!(e.push((photo(8, 8, 3, 192), 0usize)).is_err());
}

/// Settings a caller can get wrong are refused by `Engine::new`, not later.
#[test]
fn impossible_params_are_refused_up_front() {
    for window in [0, 2] {
        let p = Params {
            window: abysslight::Window::Fixed(window),
            ..Params::default()
        };
        assert!(
            Engine::<usize>::new(p, None, None).is_err(),
            "window {window}"
        );
    }
}
