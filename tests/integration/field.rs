//! Real-footage problems on synthetic dives: burned-in overlays and laser dots (masks), gamma-encoded photos.

use crate::common;

use abysslight::io::decode;
use abysslight::Mask;
use abysslight::{correct_mission, Options, Silent};
use abysslight::{Photo, Samples};
use common::*;

const W: usize = 128;
const H: usize = 96;
/// Blocks around a bright spot that `--mask-auto` also leaves out (the library's rule: two on each side).
const SPOT_GROW: usize = 2;

/// Overlay: a text box in the top-left corner (static pattern plus digits that change every frame) and three
/// laser dots.
fn overlay_pixel(x: usize, y: usize, frame: usize) -> Option<[u8; 3]> {
    if (4..70).contains(&x) && (3..13).contains(&y) {
        let digit_zone = x >= 50;
        let on = if digit_zone {
            ((x * 7 + y * 3 + frame * 13) % 5) < 2
        } else {
            (x / 2 + y).is_multiple_of(3)
        };
        return Some(if on { [255, 255, 255] } else { [0, 0, 0] });
    }
    for (cx, cy) in [(30i32, 60i32), (100, 60), (64, 40)] {
        if (x as i32 - cx).pow(2) + (y as i32 - cy).pow(2) <= 5 {
            return Some([255, 40, 30]);
        }
    }
    None
}

fn truth_mask() -> Mask {
    let mut m = Mask::empty(W, H);
    for y in 0..H {
        for x in 0..W {
            m.ignore[y * W + x] = overlay_pixel(x, y, 0).is_some();
        }
    }
    m
}

fn burn_in(photos: &mut [Photo]) {
    for (f, p) in photos.iter_mut().enumerate() {
        let Samples::U8(v) = &mut p.samples else {
            unreachable!()
        };
        for y in 0..H {
            for x in 0..W {
                if let Some(rgb) = overlay_pixel(x, y, f) {
                    v[(y * W + x) * 3..(y * W + x) * 3 + 3].copy_from_slice(&rgb);
                }
            }
        }
    }
}

/// Scaled albedo error over the pixels within `ring` px of the overlay but not on it.
fn ring_error(corrected: &[Vec<f32>], albedo: &[Vec<f32>], ring: usize) -> f64 {
    let truth = truth_mask();
    let near = truth.dilate(ring);
    let pick = |v: &Vec<f32>| -> Vec<f32> {
        v.iter()
            .enumerate()
            .filter(|(i, _)| near.ignore[i / 3] && !truth.ignore[i / 3])
            .map(|(_, v)| *v)
            .collect()
    };
    scaled_error(
        &corrected.iter().map(pick).collect::<Vec<_>>(),
        &albedo.iter().map(pick).collect::<Vec<_>>(),
    )
}

#[test]
fn masked_overlays_leave_no_halo_and_stay_recognisable() {
    let d = tempfile::tempdir().unwrap();
    let frames = 20;
    let mut dive = dive(W, H, frames, 7, 0.2, false, 17);
    burn_in(&mut dive.photos);
    burn_in(&mut dive.water);
    write_dive(&dive, d.path(), "png");
    truth_mask().save(&d.path().join("mask.png")).unwrap();
    let base = Options {
        water_column: Some(d.path().join("water")),
        survey: Some(d.path().join("survey")),
        contamination: Some(0.2),
        ..Options::default()
    };
    let mut errors = Vec::new();
    for (name, mask, auto) in [
        ("none", None, false),
        ("given", Some(d.path().join("mask.png")), false),
        ("auto", None, true),
    ] {
        let out = d.path().join(format!("out_{name}"));
        let r = correct_mission(
            &Options {
                out: Some(out.clone()),
                mask,
                mask_auto: auto,
                ..base.clone()
            },
            &Silent,
        )
        .unwrap();
        assert_eq!(r.corrected, frames);
        let photos: Vec<Photo> = (1..=frames)
            .map(|i| decode(&out.join(format!("img{i}.png"))).unwrap())
            .collect();
        let corrected: Vec<Vec<f32>> = photos.iter().map(normalised).collect();
        let ring = ring_error(&corrected, &dive.albedo, 12);
        let all = scaled_error(&corrected, &dive.albedo);
        eprintln!(
            "mask {name}: error within 12 px of the overlay {ring:.4}, whole photos {all:.4}"
        );
        errors.push(ring);
        if name != "none" {
            // The overlay stays recognisable: its white and black pixels stay white and black.
            for (f, p) in photos.iter().enumerate() {
                let Samples::U8(a) = &p.samples else {
                    unreachable!()
                };
                for y in 3..13 {
                    for x in 4..70 {
                        let px = (y * W + x) * 3;
                        match overlay_pixel(x, y, f) {
                            Some([255, 255, 255]) => {
                                assert!(a[px + 1] >= 240, "{name}: text at ({x},{y}) lost")
                            }
                            Some([0, 0, 0]) => {
                                assert!(
                                    a[px + 1] <= 10,
                                    "{name}: box at ({x},{y}) lost: {}",
                                    a[px + 1]
                                )
                            }
                            _ => {}
                        }
                    }
                }
            }
        }
        if auto {
            let found = Mask::load(&out.join("_abysslight/mask-auto.png")).unwrap();
            let truth = truth_mask();
            let hit = truth
                .ignore
                .iter()
                .zip(&found.ignore)
                .filter(|(t, f)| **t && **f)
                .count();
            assert!(
                hit as f64 >= 0.9 * truth.count() as f64,
                "auto mask found {hit} of {}",
                truth.count()
            );
            let far = truth.dilate(4);
            let false_pos = found
                .ignore
                .iter()
                .zip(&far.ignore)
                .filter(|(f, n)| **f && !**n)
                .count();
            assert!(
                false_pos < W * H / 100,
                "auto mask marks {false_pos} pixels far from any overlay"
            );
        }
    }
    let (none, given, auto) = (errors[0], errors[1], errors[2]);
    assert!(given < 0.03, "halo with the true mask: {given}");
    assert!(auto < 0.03, "halo with the automatic mask: {auto}");
    assert!(
        none > given,
        "the unmasked overlay disturbs its surroundings more ({none} vs {given})"
    );
    // Without a mask the static laser dots are absorbed into F and vanish from the photos; with one they stay.
    let redness = |dir: &str| -> f64 {
        let p = normalised(&decode(&d.path().join(dir).join("img10.png")).unwrap());
        let dots: Vec<usize> = (0..W * H)
            .filter(|&i| i / W > 20 && truth_mask().ignore[i])
            .collect();
        dots.iter()
            .map(|&i| (p[i * 3] - p[i * 3 + 1]) as f64)
            .sum::<f64>()
            / dots.len() as f64
    };
    let (red_none, red_given) = (redness("out_none"), redness("out_given"));
    eprintln!("laser dot redness (R - G): no mask {red_none:.3}, mask {red_given:.3}");
    assert!(red_given > 0.7, "{red_given}");
    assert!(red_none < 0.3, "{red_none}");
}

/// Under `--window auto` a laser dot's path is left out of `F` and said (with `--no-laser-paths`, the survey warns of
/// it and names the fix instead): a red dot 6
/// pixels across (as small against the frame as the Nephrops runs' are against theirs, within a few blocks) at A in
/// three photos of every five and 20 pixels to the right in the others. The same dive without the dot gets no
/// such warning (bright spots that pass through the frame are not a path).
#[test]
fn the_survey_warns_of_a_laser_dot_s_path_and_names_the_fix() {
    let frames = 25;
    let (a, b, y0) = (40i32, 60i32, 56i32);
    for laser in [true, false] {
        let d = tempfile::tempdir().unwrap();
        let mut dive = dive(W, H, frames, 7, 0.2, false, 29);
        if laser {
            for (f, p) in dive.photos.iter_mut().enumerate() {
                let Samples::U8(v) = &mut p.samples else {
                    unreachable!()
                };
                let x0 = if f % 5 < 3 { a } else { b };
                for y in 0..H {
                    for x in 0..W {
                        if (x as i32 - x0).pow(2) + (y as i32 - y0).pow(2) <= 9 {
                            v[(y * W + x) * 3..(y * W + x) * 3 + 3].copy_from_slice(&[255, 40, 30]);
                        }
                    }
                }
            }
        }
        write_dive(&dive, d.path(), "png");
        // At default options the paths are left out of F and said; with --no-laser-paths the survey warns of them
        // and names the fix.
        for (laser_paths, said) in [
            (true, "--no-laser-paths keeps them in F"),
            (false, "to keep those paths out of F"),
        ] {
            let out = d.path().join(format!("out-{laser_paths}"));
            correct_mission(
                &Options {
                    water_column: Some(d.path().join("water")),
                    survey: Some(d.path().join("survey")),
                    out: Some(out.clone()),
                    laser_paths,
                    ..Options::default()
                },
                &Silent,
            )
            .unwrap();
            let report = std::fs::read_to_string(out.join("_abysslight/report.json")).unwrap();
            assert_eq!(
                report.contains("laser dots:") && report.contains(said),
                laser,
                "laser {laser}, paths {laser_paths}: {report}"
            );
        }
    }
}

/// A laser dot that wanders with the altitude (the real Nephrops runs), 12 pixels across: at A in three photos of
/// every five and at B, 32 pixels to the right, in the other two. A holds most of every window and B fewer than
/// half of it, so without a mask the window's median takes the dot into `F` at A (a dark stain there in the photos
/// whose dot is at B) and, more faintly, at B. `--mask-auto` finds A as a static pixel (it is there in most
/// photos of every third of the mission) and B as a place bright spots come back to more often than chance
/// (the bright spots' path; without it B keeps its stain, checked), leaves both out of every
/// median, and no stain is left at either.
#[test]
fn mask_auto_finds_where_a_wandering_laser_dot_goes_and_leaves_no_stain() {
    let d = tempfile::tempdir().unwrap();
    let frames = 25;
    let (a, b, y0) = (40usize, 72usize, 56usize);
    let at = |f: usize| if f % 5 < 3 { a } else { b };
    let mut dive = dive(W, H, frames, 7, 0.2, false, 29);
    for (f, p) in dive.photos.iter_mut().enumerate() {
        let Samples::U8(v) = &mut p.samples else {
            unreachable!()
        };
        for y in 0..H {
            for x in 0..W {
                if (x as i32 - at(f) as i32).pow(2) + (y as i32 - y0 as i32).pow(2) <= 36 {
                    v[(y * W + x) * 3..(y * W + x) * 3 + 3].copy_from_slice(&[255, 40, 30]);
                }
            }
        }
    }
    write_dive(&dive, d.path(), "png");
    // Corrected red over albedo red in a disc at `x` (the dot and its edge), against the same in a ring around it:
    // 1 where the correction leaves no stain.
    let stain = |c: &[f32], t: &[f32], x: usize| {
        let (mut disc, mut ring) = ([0.0f64; 2], [0.0f64; 2]);
        for yy in 0..H {
            for xx in 0..W {
                let r2 = (xx as i32 - x as i32).pow(2) + (yy as i32 - y0 as i32).pow(2);
                let i = (yy * W + xx) * 3;
                let sum = if r2 <= 49 {
                    &mut disc
                } else if (121..=225).contains(&r2) {
                    &mut ring
                } else {
                    continue;
                };
                sum[0] += c[i] as f64;
                sum[1] += t[i] as f64;
            }
        }
        (disc[0] / disc[1]) / (ring[0] / ring[1])
    };
    let mut worst = Vec::new();
    for auto in [false, true] {
        let out = d.path().join(format!("out_{auto}"));
        let r = correct_mission(
            &Options {
                water_column: Some(d.path().join("water")),
                survey: Some(d.path().join("survey")),
                out: Some(out.clone()),
                mask_auto: auto,
                ..Options::default()
            },
            &Silent,
        )
        .unwrap();
        assert_eq!(r.corrected, frames);
        if auto {
            // Masked, the dot's path needs no warning.
            let report = std::fs::read_to_string(out.join("_abysslight/report.json")).unwrap();
            assert!(!report.contains("laser dots"), "{report}");
        }
        // Each place in the photos whose dot is elsewhere; the median over them (a nodule may sit under one disc).
        let photos: Vec<Vec<f32>> = (1..=frames)
            .map(|i| normalised(&decode(&out.join(format!("img{i}.png"))).unwrap()))
            .collect();
        let at_place = |place: usize| {
            let mut v: Vec<f64> = (0..frames)
                .filter(|&f| at(f) != place)
                .map(|f| stain(&photos[f], &dive.albedo[f], place))
                .collect();
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let (sa, sb) = (at_place(a), at_place(b));
        eprintln!("mask-auto {auto}: red where the dot is not, against the ring around: at A {sa:.3}, at B {sb:.3}");
        worst.push((sa, sb));
        if auto {
            let found = Mask::load(&out.join("_abysslight/mask-auto.png")).unwrap();
            for x in [a, b] {
                assert!(
                    found.ignore[y0 * W + x],
                    "the dot's place ({x}, {y0}) is not masked"
                );
            }
            // Nothing else: a spot's blocks (8 pixels) and the two around it.
            let k = 8 * (1 + SPOT_GROW);
            for i in (0..W * H).filter(|&i| found.ignore[i]) {
                let (x, y) = (i % W, i / W);
                assert!(
                    y.abs_diff(y0) < k && x + k > a && x < b + k,
                    "({x}, {y}) masked, far from the dot"
                );
            }
        }
    }
    let ((none_a, none_b), (auto_a, auto_b)) = (worst[0], worst[1]);
    assert!(none_a < 0.8, "no stain at A without a mask? {none_a}");
    assert!(none_b < 0.97, "no stain at B without a mask? {none_b}");
    for s in [auto_a, auto_b] {
        assert!((s - 1.0).abs() < 0.05, "stain with --mask-auto: {s}");
    }
}

#[test]
fn seafloor_colour_change_half_way_is_flagged() {
    let d = tempfile::tempdir().unwrap();
    let frames = 30;
    let blue = [0.35, 0.5, 0.6];
    let dive = dive_with(64, 48, frames, 0, 0.2, false, 23, |f| {
        if f < 15 {
            SEDIMENT
        } else {
            blue
        }
    });
    write_all(&dive.photos, &d.path().join("survey"), "img", "png");
    let r = correct_mission(
        &Options {
            survey: Some(d.path().join("survey")),
            out: Some(d.path().join("out")),
            window: Some(7),
            ..Options::default()
        },
        &Silent,
    )
    .unwrap();
    let flagged: Vec<bool> = r
        .frames
        .iter()
        .map(|f| !f.health.flags.is_empty())
        .collect();
    eprintln!(
        "colour shift per photo: {:?}",
        r.frames
            .iter()
            .map(|f| (
                (f.health.colour_shift * 100.0).round(),
                (f.health.roughness * 100.0).round()
            ))
            .collect::<Vec<_>>()
    );
    // Before the change (and before its window reaches it) nothing is flagged; after it every photo is.
    assert!(flagged[..11].iter().all(|f| !f), "{flagged:?}");
    assert!(flagged[19..].iter().all(|f| *f), "{flagged:?}");
    assert!(
        r.frames[25]
            .health
            .flags
            .iter()
            .any(|f| f.kind == "colour-shift"),
        "{:?}",
        r.frames[25].health.flags
    );
    assert!(r.monitor.colour_shift >= 11, "{:?}", r.monitor);
    // The user sees it: an overview plot and a contact sheet of flagged photos with their F.
    let overview = image::open(d.path().join("out/_abysslight/overview.png")).unwrap();
    assert!(overview.width() >= 600 && overview.height() >= 400);
    let sheet = image::open(d.path().join("out/_abysslight/flagged.png")).unwrap();
    assert!(sheet.height() > 6 * 48, "six flagged photos in rows");
    // A dive without a change is not flagged.
    let steady = dive_with(64, 48, frames, 0, 0.2, false, 23, |_| SEDIMENT);
    write_all(&steady.photos, &d.path().join("steady"), "img", "png");
    let r = correct_mission(
        &Options {
            survey: Some(d.path().join("steady")),
            out: Some(d.path().join("out_steady")),
            window: Some(7),
            ..Options::default()
        },
        &Silent,
    )
    .unwrap();
    assert_eq!(
        r.monitor.flagged,
        0,
        "{:#?}",
        r.frames.iter().map(|f| &f.health).collect::<Vec<_>>()
    );
}
