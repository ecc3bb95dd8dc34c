//! A window whose exposure jumps from photo to photo (a sledge that lifts and drops): the default levels it to one
//! exposure before its median (docs/method.md, step 8); without that, the median takes the middle-exposure photo's
//! scene into `F`, and the corrected photos carry its ghost.

use abysslight::{Engine, Layout, Params, Photo, Samples, Scatter, Steps};

use crate::common::{backscatter, light, normalised, scaled_error, Rng};

/// `frames` photos of independent textured seafloor (blobs a few blocks wide, ±20 %) under the common light,
/// each photo's seafloor signal scaled by its exposure (the backscatter is not), 16-bit linear; and the albedo.
fn jumpy_mission(frames: usize, exposures: &[f32]) -> (Vec<Photo>, Vec<Vec<f32>>) {
    let (w, h) = (128usize, 96usize);
    let mut rng = Rng::new(7);
    let (mut photos, mut albedo) = (Vec::new(), Vec::new());
    for f in 0..frames {
        let blobs: Vec<(f32, f32, f32)> = (0..60)
            .map(|_| {
                (
                    rng.f32() * w as f32,
                    rng.f32() * h as f32,
                    0.8 + 0.4 * rng.f32(),
                )
            })
            .collect();
        let mut a = vec![0.0f32; w * h * 3];
        let mut img = vec![0u16; w * h * 3];
        for y in 0..h {
            for x in 0..w {
                let mut tex = 1.0;
                for &(bx, by, k) in &blobs {
                    if (x as f32 - bx).powi(2) + (y as f32 - by).powi(2) < 36.0 {
                        tex = k;
                    }
                }
                for c in 0..3 {
                    let i = (y * w + x) * 3 + c;
                    a[i] = 0.5 * tex;
                    let v = exposures[f % exposures.len()] * a[i] * light(x, y, c, w, h)
                        + backscatter(x, y, c, w, h);
                    img[i] = (v.clamp(0.0, 1.0) * 65535.0).round() as u16;
                }
            }
        }
        photos.push(Photo {
            layout: Layout {
                width: w,
                height: h,
                channels: 3,
            },
            samples: Samples::U16(img),
            alpha: None,
        });
        albedo.push(a);
    }
    (photos, albedo)
}

/// The mission corrected with `params`, each photo normalised, in mission order.
fn corrected(photos: &[Photo], params: Params) -> Vec<Vec<f32>> {
    let mut engine = Engine::new(params, None::<&Scatter>, None).unwrap();
    let mut out = Vec::new();
    for (i, p) in photos.iter().cloned().enumerate() {
        out.extend(engine.push((p, i)).unwrap());
    }
    out.extend(engine.finish());
    assert_eq!(out.len(), photos.len());
    out.sort_by_key(|c| c.index);
    out.iter()
        .map(|c| normalised(c.photo.as_ref().unwrap()))
        .collect()
}

/// Albedo error of the mission corrected with `params`.
fn corrected_error(photos: &[Photo], albedo: &[Vec<f32>], params: Params) -> f64 {
    scaled_error(&corrected(photos, params), albedo)
}

/// `params` with exposure levelling on or off.
fn levelling(params: Params, on: bool) -> Params {
    Params {
        steps: Steps {
            level_exposures: on,
            ..params.steps
        },
        ..params
    }
}

#[test]
fn a_window_with_exposure_jumps_is_levelled_and_a_steady_one_is_left_alone() {
    let jumps = [1.0, 0.7, 1.35, 0.85, 1.2, 0.75, 1.1, 0.9, 1.3];
    let (photos, albedo) = jumpy_mission(18, &jumps);
    let without = Params {
        steps: Steps {
            level_exposures: false,
            ..Steps::default()
        },
        ..Params::default()
    };
    let levelled = corrected_error(&photos, &albedo, Params::default());
    let plain = corrected_error(&photos, &albedo, without);
    assert!(
        levelled < 0.8 * plain,
        "levelled {levelled:.4}, without levelling {plain:.4}"
    );
    // One exposure: levelling finds no jump and changes nothing, to the bit.
    let (photos, albedo) = jumpy_mission(18, &[1.0]);
    let steady = corrected_error(&photos, &albedo, Params::default());
    let steady_without = corrected_error(&photos, &albedo, without);
    assert_eq!(steady, steady_without);
}

/// Whether levelling changes any corrected photo of the mission under windows of `window` photos.
fn levels(photos: &[Photo], window: usize) -> bool {
    let params = Params {
        window: abysslight::Window::Fixed(window),
        ..Params::default()
    };
    corrected(photos, levelling(params, true)) != corrected(photos, levelling(params, false))
}

#[test]
fn a_window_of_five_is_not_levelled() {
    let jumps = [1.0, 0.7, 1.35, 0.85, 1.2, 0.75, 1.1, 0.9, 1.3];
    let (photos, _) = jumpy_mission(12, &jumps);
    assert!(!levels(&photos, 5), "window 5");
    assert!(levels(&photos, 7), "window 7");
}

#[test]
fn a_near_window_is_levelled_only_with_its_window() {
    // An exposure step at photo 9: no window of 9 has a photo off both its neighbours (a step is not a spike) but
    // the windows with the step at an end (their last photo is 9, or their first is 8), where the three photos at
    // that end hold the step. Photo 7's window (photos 3-11) and photo 10's (6-14) hold it inside, so they are
    // not levelled; their near windows of 5 (5-9 and 8-12) hold it at an end, and would be.
    let exposures: Vec<f32> = (0..18).map(|f| if f < 9 { 1.0 } else { 1.25 }).collect();
    let (photos, _) = jumpy_mission(18, &exposures);
    let params = Params {
        window: abysslight::Window::Fixed(9),
        steps: Steps {
            near_window: Some(5),
            ..Steps::default()
        },
        ..Params::default()
    };
    let on = corrected(&photos, levelling(params, true));
    let off = corrected(&photos, levelling(params, false));
    for i in [7, 10] {
        assert!(
            on[i] == off[i],
            "photo {i}: its near window was levelled, its window not"
        );
    }
    // The windows with the step at an end are levelled (photo 5's, 1-9; photo 12's, 8-16).
    for i in [5, 12] {
        assert!(on[i] != off[i], "photo {i}: its window was not levelled");
    }
}

#[test]
fn a_long_window_is_not_levelled_for_its_end_photo_alone() {
    // Photo 17, the mission's last, 30 % brighter than the rest: in windows of 15 it is only ever at an end (the
    // windows of photos 10-17 are photos 3-17), where a swing that turns looks like a jump. In windows of 11 the
    // ends are judged.
    let exposures: Vec<f32> = (0..18).map(|f| if f == 17 { 1.3 } else { 1.0 }).collect();
    let (photos, _) = jumpy_mission(18, &exposures);
    assert!(!levels(&photos, 15), "window 15");
    assert!(levels(&photos, 11), "window 11");
    // The same photo inside the windows of 15 (photo 9 of 18): levelled.
    let exposures: Vec<f32> = (0..18).map(|f| if f == 9 { 1.3 } else { 1.0 }).collect();
    let (photos, _) = jumpy_mission(18, &exposures);
    assert!(levels(&photos, 15), "window 15, the jump inside");
}
