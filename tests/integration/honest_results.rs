//! Results that do not lie (docs/threat-model.md): `--watch` resolves `--transfer auto` as a batch run does,
//! `--mask-auto` finds the mission's size as the other passes do, and a mask that hides most of the frame is
//! warned about and counted in the report.

#![cfg(unix)]

use crate::common;

use common::{abysslight, moving_mission, report, s, stderr};

/// Camera JPEGs (no colour information: cameras write them sRGB-encoded, and `--transfer auto` takes `srgb` in a
/// batch run): a watch over the same folder writes the same bytes (before: the watch assumed `linear`, and every
/// output differed).
#[test]
fn watch_equals_batch_on_camera_jpegs() {
    let d = tempfile::tempdir().unwrap();
    let (survey, _) = common::tiny_mission(d.path(), 7);
    for e in std::fs::read_dir(&survey).unwrap().flatten() {
        let p = e.path();
        let img = image::open(&p).unwrap().to_rgb8();
        let mut jpg = Vec::new();
        jpeg_encoder::Encoder::new(&mut jpg, 90)
            .encode(img.as_raw(), 32, 24, jpeg_encoder::ColorType::Rgb)
            .unwrap();
        std::fs::write(p.with_extension("jpg"), jpg).unwrap();
        std::fs::remove_file(&p).unwrap();
    }
    let (batch, live) = (d.path().join("batch"), d.path().join("live"));
    let o = abysslight(&[
        "correct",
        "--survey",
        s(&survey),
        "--out",
        s(&batch),
        "--window",
        "3",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("camera curve srgb"), "{}", stderr(&o));
    #[rustfmt::skip]
    let o = abysslight(&["correct", "--survey", s(&survey), "--out", s(&live), "--window", "3", "--watch",
                  "--poll-interval", "40", "--idle-timeout", "1"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("camera curve srgb"), "{}", stderr(&o));
    let mut compared = 0;
    for e in std::fs::read_dir(&batch).unwrap().flatten() {
        if e.path().extension().is_some_and(|x| x == "jpg") {
            let name = e.file_name();
            let want = std::fs::read(e.path()).unwrap();
            let got = std::fs::read(live.join(&name)).unwrap();
            assert!(
                got == want,
                "{name:?}: the watch wrote other bytes than the batch run"
            );
            compared += 1;
        }
    }
    assert_eq!(compared, 7);
}

/// One odd-sized photo sorting first: `--mask-auto` still finds its mask, at the mission's size, from the others
/// (before: the first photo's size was taken, the others did not match it, and the mask was silently off).
#[test]
fn an_odd_first_photo_leaves_mask_auto_on() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = moving_mission(d.path(), 9);
    image::RgbImage::from_pixel(16, 12, image::Rgb([90, 90, 90]))
        .save(survey.join("0_thumb.png"))
        .unwrap();
    let out = d.path().join("out");
    #[rustfmt::skip]
    let o = abysslight(&["correct", "--survey", s(&survey), "--water-column", s(&water), "--out", s(&out),
                  "--window", "3", "--mask-auto"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let mask = image::open(out.join("_abysslight/mask-auto.png")).expect("no mask-auto.png");
    assert_eq!((mask.width(), mask.height()), (48, 32));
    assert_eq!(report(&out)["failed"], 1);
}

/// A mask that hides most of the frame (an inverted mask: white where black was meant) is warned about, and the
/// warning and the share are in the report (before: nothing was said, "the estimates look sound", exit 0).
#[test]
fn a_mask_hiding_most_of_the_frame_is_warned_about_and_reported() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = common::tiny_mission(d.path(), 6);
    let mask = d.path().join("mask.png");
    // White everywhere but a 10 × 8 corner: 90 % of the frame hidden.
    image::GrayImage::from_fn(32, 24, |x, y| {
        image::Luma([if x < 10 && y < 8 { 0 } else { 255 }])
    })
    .save(&mask)
    .unwrap();
    let out = d.path().join("out");
    #[rustfmt::skip]
    let o = abysslight(&["correct", "--survey", s(&survey), "--water-column", s(&water), "--out", s(&out),
                  "--window", "3", "--mask", s(&mask)]);
    let err = stderr(&o);
    assert!(err.contains("hides 90 % of the frame"), "{err}");
    let r = report(&out);
    let warned = r["warnings"].as_array().unwrap();
    assert!(
        warned
            .iter()
            .any(|w| w.as_str().unwrap().contains("hides 90 % of the frame")),
        "{r}"
    );
    // The good mask of the same size is not warned about.
    image::GrayImage::from_fn(32, 24, |x, y| {
        image::Luma([if x < 10 && y < 8 { 255 } else { 0 }])
    })
    .save(&mask)
    .unwrap();
    let out = d.path().join("out2");
    #[rustfmt::skip]
    let o = abysslight(&["correct", "--survey", s(&survey), "--water-column", s(&water), "--out", s(&out),
                  "--window", "3", "--mask", s(&mask)]);
    assert!(!stderr(&o).contains("of the frame"), "{}", stderr(&o));
}
