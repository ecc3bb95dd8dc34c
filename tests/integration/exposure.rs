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

/// Albedo error of the mission corrected with `params`.
fn corrected_error(photos: &[Photo], albedo: &[Vec<f32>], params: Params) -> f64 {
    let mut engine = Engine::new(params, None::<&Scatter>, None).unwrap();
    let mut out = Vec::new();
    for (i, p) in photos.iter().cloned().enumerate() {
        out.extend(engine.push(p, i).unwrap());
    }
    out.extend(engine.finish());
    assert_eq!(out.len(), photos.len());
    let got: Vec<Vec<f32>> = out
        .iter()
        .map(|c| normalised(c.photo.as_ref().unwrap()))
        .collect();
    scaled_error(&got, albedo)
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
