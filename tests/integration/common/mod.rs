//! Small synthetic dives for the integration tests: `I = A·F + S` with everything known.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use abysslight::io::{write_atomic, EncodeSettings};
use abysslight::{Layout, Photo, Samples};

mod command;
pub use command::*;

/// xorshift64*: deterministic, dependency-free test randomness.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in [0, 1).
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// A dive with known albedo, light pattern and backscatter.
pub struct Dive {
    pub width: usize,
    pub height: usize,
    /// Albedo of each survey photo, interleaved RGB in [0, 1].
    pub albedo: Vec<Vec<f32>>,
    /// Survey photos as stored (8- or 16-bit), interleaved RGB.
    pub photos: Vec<Photo>,
    pub water: Vec<Photo>,
}

pub const SEDIMENT: [f32; 3] = [0.55, 0.5, 0.42];

/// Smooth light cone, different per channel (blue-green water): F in about [0.2, 1].
pub fn light(x: usize, y: usize, c: usize, w: usize, h: usize) -> f32 {
    let (cx, cy) = (0.45 * w as f32, 0.55 * h as f32);
    let (sx, sy) = (0.45 * w as f32, 0.5 * h as f32);
    let d = ((x as f32 - cx) / sx).powi(2) + ((y as f32 - cy) / sy).powi(2);
    let gain = [0.75, 1.0, 0.9][c];
    gain * (0.2 + 0.8 * (-d).exp())
}

/// Smooth backscatter, strongest near the top of the frame.
pub fn backscatter(x: usize, y: usize, c: usize, w: usize, h: usize) -> f32 {
    let t = 1.0 - y as f32 / h as f32;
    let s = 0.5 + 0.5 * (x as f32 / w as f32);
    [0.02, 0.05, 0.06][c] * (0.5 + t * s)
}

fn quantise(values: &[f32], sixteen: bool) -> Samples {
    if sixteen {
        Samples::U16(
            values
                .iter()
                .map(|&v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16)
                .collect(),
        )
    } else {
        Samples::U8(
            values
                .iter()
                .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
                .collect(),
        )
    }
}

/// Render a dive: `frames` survey photos whose albedo is sediment with fine texture and random dark blobs
/// covering about `contamination` of each photo, and `water_frames` water-column frames (backscatter plus
/// bright particles).
pub fn dive(
    w: usize,
    h: usize,
    frames: usize,
    water_frames: usize,
    contamination: f32,
    sixteen: bool,
    seed: u64,
) -> Dive {
    dive_with(
        w,
        h,
        frames,
        water_frames,
        contamination,
        sixteen,
        seed,
        |_| SEDIMENT,
    )
}

/// As [`dive`], with the sediment colour of each frame given by `sediment(frame)`.
#[allow(clippy::too_many_arguments)]
pub fn dive_with(
    w: usize,
    h: usize,
    frames: usize,
    water_frames: usize,
    contamination: f32,
    sixteen: bool,
    seed: u64,
    sediment: impl Fn(usize) -> [f32; 3],
) -> Dive {
    let mut rng = Rng::new(seed);
    let mut albedo = Vec::new();
    let mut photos = Vec::new();
    for frame in 0..frames {
        let colour = sediment(frame);
        let mut a = vec![0.0f32; w * h * 3];
        for px in a.chunks_exact_mut(3) {
            let tex = 1.0 + 0.16 * (rng.f32() - 0.5);
            for c in 0..3 {
                px[c] = colour[c] * tex;
            }
        }
        // Dark blobs until the target share of pixels is covered.
        let mut dark = vec![false; w * h];
        let mut covered = 0usize;
        while (covered as f32) < contamination * (w * h) as f32 {
            let (bx, by) = (rng.f32() * w as f32, rng.f32() * h as f32);
            let r = 2.0 + rng.f32() * 0.08 * w as f32;
            for y in 0..h {
                for x in 0..w {
                    let d2 = (x as f32 - bx).powi(2) + (y as f32 - by).powi(2);
                    if d2 <= r * r && !dark[y * w + x] {
                        dark[y * w + x] = true;
                        covered += 1;
                    }
                }
            }
        }
        for (i, d) in dark.iter().enumerate() {
            if *d {
                for c in 0..3 {
                    a[i * 3 + c] *= 0.15;
                }
            }
        }
        let mut img = vec![0.0f32; w * h * 3];
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    let i = (y * w + x) * 3 + c;
                    let noise = 0.004 * (rng.f32() - 0.5);
                    img[i] = a[i] * light(x, y, c, w, h) + backscatter(x, y, c, w, h) + noise;
                }
            }
        }
        photos.push(Photo {
            layout: Layout {
                width: w,
                height: h,
                channels: 3,
            },
            samples: quantise(&img, sixteen),
            alpha: None,
        });
        albedo.push(a);
    }
    let mut water = Vec::new();
    for _ in 0..water_frames {
        let mut img = vec![0.0f32; w * h * 3];
        for y in 0..h {
            for x in 0..w {
                let particle = rng.f32() < 0.03;
                for c in 0..3 {
                    let i = (y * w + x) * 3 + c;
                    img[i] = backscatter(x, y, c, w, h) + if particle { 0.6 } else { 0.0 };
                }
            }
        }
        water.push(Photo {
            layout: Layout {
                width: w,
                height: h,
                channels: 3,
            },
            samples: quantise(&img, sixteen),
            alpha: None,
        });
    }
    Dive {
        width: w,
        height: h,
        albedo,
        photos,
        water,
    }
}

/// Write photos as `dir/<prefix><i>.<ext>` (1-based, unpadded so natural order matters); returns the paths.
pub fn write_all(photos: &[Photo], dir: &Path, prefix: &str, ext: &str) -> Vec<PathBuf> {
    std::fs::create_dir_all(dir).unwrap();
    photos
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let path = dir.join(format!("{prefix}{}.{ext}", i + 1));
            write_atomic(
                p,
                &path,
                EncodeSettings {
                    jpeg_quality: 98,
                    ..EncodeSettings::default()
                },
            )
            .unwrap();
            path
        })
        .collect()
}

/// Normalised samples of a photo.
pub fn normalised(p: &Photo) -> Vec<f32> {
    match &p.samples {
        Samples::U8(v) => v.iter().map(|&s| s as f32 / 255.0).collect(),
        Samples::U16(v) => v.iter().map(|&s| s as f32 / 65535.0).collect(),
    }
}

/// Relative error of `got` against `truth` after the best global per-channel scale (least squares):
/// mean |got − s·truth| / mean(s·truth), over all samples of all photos.
pub fn scaled_error(got: &[Vec<f32>], truth: &[Vec<f32>]) -> f64 {
    let mut num = [0.0f64; 3];
    let mut den = [0.0f64; 3];
    for (g, t) in got.iter().zip(truth) {
        for (i, (&gv, &tv)) in g.iter().zip(t).enumerate() {
            num[i % 3] += gv as f64 * tv as f64;
            den[i % 3] += tv as f64 * tv as f64;
        }
    }
    let s: Vec<f64> = (0..3).map(|c| num[c] / den[c]).collect();
    let (mut err, mut mag) = (0.0f64, 0.0f64);
    for (g, t) in got.iter().zip(truth) {
        for (i, (&gv, &tv)) in g.iter().zip(t).enumerate() {
            let e = s[i % 3] * tv as f64;
            err += (gv as f64 - e).abs();
            mag += e;
        }
    }
    err / mag
}

/// A small photo of a varied pattern, `w`×`h`: `seed` varies the content.
pub fn pattern(w: u32, h: u32, seed: u32) -> image::RgbImage {
    image::RgbImage::from_fn(w, h, |x, y| {
        let v = ((x * 7 + y * 13 + seed * 31) % 200 + 30) as u8;
        image::Rgb([v, v / 2, 255 - v])
    })
}

/// A tiny mission on disk for the tests of files and runs: `root/survey` (`photos` 32×24 PNGs of a varied
/// pattern) and `root/water` (3 dark frames). Returns both folders.
pub fn tiny_mission(root: &Path, photos: u32) -> (PathBuf, PathBuf) {
    let survey = root.join("survey");
    let water = root.join("water");
    for d in [&survey, &water] {
        std::fs::create_dir_all(d).unwrap();
    }
    for i in 0..photos {
        pattern(32, 24, i)
            .save(survey.join(format!("IMG_{i:04}.png")))
            .unwrap();
    }
    for i in 0..3u8 {
        image::RgbImage::from_pixel(32, 24, image::Rgb([10 + i, 12, 14]))
            .save(water.join(format!("wc{i}.png")))
            .unwrap();
    }
    (survey, water)
}

/// Write a dive as a mission: `root/water/w1.png`… and `root/survey/img1.<ext>`…; returns the survey photos' paths.
pub fn write_dive(dive: &Dive, root: &Path, ext: &str) -> Vec<PathBuf> {
    write_all(&dive.water, &root.join("water"), "w", "png");
    write_all(&dive.photos, &root.join("survey"), "img", ext)
}

/// `abysslight correct` on the mission [`write_dive`] wrote in `root`, into `root/<out>`, with `extra` arguments.
pub fn correct_dive(root: &Path, out: &str, extra: &[&str]) -> std::process::Output {
    let mut args = vec![
        "correct",
        "--water-column",
        "water",
        "--survey",
        "survey",
        "--out",
        out,
    ];
    args.extend_from_slice(extra);
    abysslight_in(&args, root)
}

/// A small dive whose seafloor moves from photo to photo (so that `--mask-auto` finds only what is static):
/// `root/survey/img1.png`… and `root/water/w1.png`…, 48 × 32. Returns both folders.
pub fn moving_mission(root: &Path, photos: usize) -> (PathBuf, PathBuf) {
    write_dive(&dive(48, 32, photos, 3, 0.2, false, 5), root, "png");
    (root.join("survey"), root.join("water"))
}

/// A PNG chunk written by hand (independent of the library's writer): length, type, data, CRC.
pub fn png_chunk(kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
    let mut c = (data.len() as u32).to_be_bytes().to_vec();
    c.extend_from_slice(kind);
    c.extend_from_slice(data);
    let mut crc = crc32fast::Hasher::new();
    crc.update(kind);
    crc.update(data);
    c.extend_from_slice(&crc.finalize().to_be_bytes());
    c
}

/// The photos of a folder (searched as a run searches it), decoded as a run decodes them, each with its path
/// relative to the folder, in the run's order.
pub fn decoded_photos(dir: &Path) -> Vec<(PathBuf, Photo)> {
    abysslight::io::find_photos(dir)
        .unwrap()
        .photos
        .into_iter()
        .map(|e| (e.relative.clone(), abysslight::io::decode(&e.path).unwrap()))
        .collect()
}

/// The in-memory engine at `params`, its `S` from the water-column photos in `water` (as the command makes it).
pub fn engine_over(water: &Path, params: abysslight::Params) -> abysslight::Engine<PathBuf> {
    let frames: Vec<Photo> = decoded_photos(water).into_iter().map(|(_, p)| p).collect();
    let scatter = abysslight::Scatter::from_frames(&frames).unwrap();
    abysslight::Engine::new(params, scatter.as_ref(), None).unwrap()
}

/// The survey photos of `root/survey` corrected by the in-memory engine at `params` over `root/water` (what Python
/// and `--watch` run), pushed in mission order with their names as tags; every photo it gave back, in order.
pub fn engine_corrects(
    root: &Path,
    params: abysslight::Params,
) -> Vec<abysslight::Corrected<PathBuf>> {
    let mut engine = engine_over(&root.join("water"), params);
    let mut out = Vec::new();
    for (name, photo) in decoded_photos(&root.join("survey")) {
        out.extend(engine.push((photo, name)).unwrap());
    }
    out.extend(engine.finish());
    out
}
