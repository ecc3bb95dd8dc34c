//! Where the lights fade out: a simulated dive whose light fades to black towards one corner, corrected at default
//! options. The input fades smoothly to black; the output must fade to the fill as smoothly, with no staircase of
//! blocks at the border of the unlit corner.

use abysslight::{Layout, Photo, Samples};

use crate::common::{abysslight_in, decoded_photos, write_all, Rng};

const W: usize = 256;
const H: usize = 160;
const PHOTOS: usize = 24;

/// The sRGB code value (0..1) of linear light, by the standard's formula.
fn srgb(l: f32) -> f32 {
    if l <= 0.003_130_8 {
        12.92 * l
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    }
}

/// The light of photo `i`: 1 at the bottom-right corner, fading smoothly to 0 along a diagonal towards the top-left
/// one. Where it ends swings from photo to photo (the vehicle's pitch), so the window's `F` is a code or two above
/// black over most of the corner where one photo's own blocks are black.
fn light(x: usize, y: usize, i: usize) -> f32 {
    let d = x as f32 / W as f32 + y as f32 / H as f32;
    let end = 0.5 + 0.3 * (0.8 * i as f32).sin();
    ((d - end) / 1.2).clamp(0.0, 1.0).powf(1.5)
}

/// Sediment with a mild texture, moving 9 pixels a photo: a seafloor the camera passes over.
fn albedo(x: usize, y: usize, i: usize) -> f32 {
    let u = (x + 9 * i) as f32;
    let v = y as f32;
    0.45 * (1.0 + 0.08 * (u * 0.31).sin() * (v * 0.23).cos() + 0.05 * (u * 0.07 + v * 0.11).sin())
}

/// The dive: grey 8-bit photos, sRGB-coded, `A·F` plus sensor noise of a third of a code (so the blend measures it).
fn photos() -> Vec<Photo> {
    let mut rng = Rng::new(56);
    (0..PHOTOS)
        .map(|i| {
            let samples = (0..W * H)
                .map(|p| {
                    let (x, y) = (p % W, p / W);
                    let (u1, u2) = (rng.f32().max(1e-7), rng.f32());
                    let n = (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos();
                    let code = 255.0 * srgb(albedo(x, y, i) * light(x, y, i)) + 0.35 * n;
                    code.round().clamp(0.0, 255.0) as u8
                })
                .collect();
            Photo {
                layout: Layout {
                    width: W,
                    height: H,
                    channels: 1,
                },
                samples: Samples::U8(samples),
                alpha: None,
            }
        })
        .collect()
}

fn codes(p: &Photo) -> Vec<i32> {
    match &p.samples {
        Samples::U8(v) => v.iter().map(|&c| i32::from(c)).collect(),
        Samples::U16(_) => panic!("8-bit in, 8-bit out"),
    }
}

/// The 99th percentile of `v`.
fn p99(mut v: Vec<i32>) -> i32 {
    v.sort_unstable();
    v[(v.len() - 1) * 99 / 100]
}

#[test]
fn an_unlit_corner_fades_to_the_fill_without_block_steps() {
    let d = tempfile::tempdir().unwrap();
    let input = photos();
    // JPEG: undeclared, so sRGB-coded as a camera's (as AQUALOC's frames).
    write_all(&input, &d.path().join("survey"), "img", "jpg");
    let out = abysslight_in(&["correct", "--survey", "survey", "--out", "out"], d.path());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got = decoded_photos(&d.path().join("out"));
    assert_eq!(got.len(), PHOTOS);
    // Steps between horizontal and vertical neighbours of the output, where the input is near black (both
    // samples at most 3 codes: the last of the fade, where the corner's border lies) and where it is lit (both
    // at least 40 codes).
    let (mut dim, mut lit) = (Vec::new(), Vec::new());
    for (k, (_, photo)) in got.iter().enumerate() {
        let (a, b) = (codes(&input[k]), codes(photo));
        for y in 0..H {
            for x in 0..W {
                let p = y * W + x;
                for q in [(x + 1 < W).then_some(p + 1), (y + 1 < H).then_some(p + W)]
                    .into_iter()
                    .flatten()
                {
                    let step = (b[q] - b[p]).abs();
                    if a[p].max(a[q]) <= 3 {
                        dim.push(step);
                    } else if a[p].min(a[q]) >= 40 {
                        lit.push(step);
                    }
                }
            }
        }
    }
    assert!(
        dim.len() > 10_000 && lit.len() > 10_000,
        "{} {}",
        dim.len(),
        lit.len()
    );
    let (dim99, lit99) = (p99(dim.clone()), p99(lit));
    eprintln!("unlit border: output steps where the input is near black p99 {dim99}; where lit p99 {lit99}");
    // The fade is within three times the lit seafloor's own texture and noise (the staircase of blocks the blend
    // drew before its fields faded to the fill: 22 codes against 5; now 8 against 3).
    assert!(
        dim99 <= 3 * lit99.max(2),
        "p99 step near black {dim99} against {lit99} where lit"
    );
}
