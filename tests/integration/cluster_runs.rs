//! Never lose a photo on the cluster surfaces: a cruise never writes into a dive's inputs, a sharded cruise's
//! merge names a dive no task wrote a report for, a mask that hides every pixel is refused with or without a
//! water column, and photos of any legal size (thinner than a block, one pixel wide) are corrected or fail one by
//! one with a message, never a panic.

use crate::common;

use common::*;

#[test]
fn a_mask_hiding_every_pixel_is_refused_without_a_water_column() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    tiny_mission(root, 9);
    image::GrayImage::from_pixel(32, 24, image::Luma([255]))
        .save(root.join("white.png"))
        .unwrap();
    for (water, out) in [(false, "out1"), (true, "out2")] {
        let mut args = vec![
            "correct",
            "--survey",
            "survey",
            "--out",
            out,
            "--mask",
            "white.png",
        ];
        if water {
            args.extend(["--water-column", "water"]);
        }
        let o = abysslight_in(&args, root);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "water column {water}: {e}");
        assert!(
            e.contains("white.png") && e.contains("ignores every pixel"),
            "water column {water}: {e}"
        );
        assert!(
            !root.join(out).exists() || outputs(&root.join(out)).is_empty(),
            "water column {water}: photos written"
        );
    }
}

#[test]
fn photos_of_any_legal_size_are_corrected_or_fail_one_by_one() {
    let d = tempfile::tempdir().unwrap();
    let root = d.path();
    for (w, h) in [
        (4000, 7),
        (7, 4000),
        (1, 40),
        (40, 1),
        (2, 2),
        (1, 1),
        (9, 9),
        (3, 700),
    ] {
        let survey = root.join(format!("s{w}x{h}"));
        std::fs::create_dir_all(&survey).unwrap();
        for i in 0..9 {
            pattern(w, h, i)
                .save(survey.join(format!("img{i}.png")))
                .unwrap();
        }
        let out = root.join(format!("o{w}x{h}"));
        let o = abysslight_in(&["correct", "--survey", s(&survey), "--out", s(&out)], root);
        let e = stderr(&o);
        assert!(
            matches!(o.status.code(), Some(0 | 1)),
            "{w}x{h}: exit {:?}: {e}",
            o.status.code()
        );
        assert!(!e.contains("panicked"), "{w}x{h}: {e}");
        let r = report(&out);
        let frames = r["frames"].as_array().unwrap().len();
        let errors = r["errors"].as_array().unwrap();
        assert_eq!(frames + errors.len(), 9, "{w}x{h}: {r}");
        for err in errors {
            let m = err["message"].as_str().unwrap();
            assert!(
                m.contains("img"),
                "{w}x{h}: an error not naming its photo: {m}"
            );
        }
        assert_eq!(outputs(&out).len(), frames, "{w}x{h}");
    }
}
