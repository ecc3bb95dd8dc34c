//! `abysslight simulate`: a physically based renderer of a deep-sea survey dive with known ground truth.
//!
//! The world is a flat seafloor (`z = 0`, metres) with a procedural albedo map: sediment colour with
//! low-frequency variation and fine texture, dark nodules covering a chosen fraction, and a few bright objects.
//! A downward-looking pinhole camera flies a transect along `+y` with overlap, slowly varying altitude, roll and
//! pitch. Lights rigidly mounted beside/behind the camera have an angular fall-off; light reaching the camera is
//! attenuated per channel by `exp(−η·d)` on the light→floor and floor→camera paths, falls off with the inverse
//! square and the cosine of incidence (Lambertian floor). Backscatter is the single-scattering integral along each
//! viewing ray up to the floor (Henyey–Greenstein phase), so it is *not* exactly the water-column image, which
//! integrates to open water. Both kinds of frame carry floating particles and sensor noise (shot + read), and are
//! quantised to 8 or 16 bits after an optional sRGB curve.
//!
//! Output layout (documented in `docs/evaluation.md`):
//! `water/0001.png…`, `survey/0001.png…`, `truth/albedo/0001.png…` (16-bit, linear albedo),
//! `truth/dive.json` ([`Truth`]: camera, rig, water, poses, homographies) and `truth/placements.txt`; and the
//! vehicle's `navigation.csv` (each survey photo's altitude, for `correct --navigation`).

use std::path::{Path, PathBuf};
use std::str::FromStr;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::io::{write_atomic, EncodeSettings};
use crate::method::raster::{Layout, Photo, Raster, Samples};
use crate::method::transfer::Transfer;

/// Light rig layouts (positions in the camera frame: x right, y towards the image bottom = behind, z forward).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Rig {
    /// Two lights beside the camera.
    Two,
    /// Two beside and one behind (default).
    #[default]
    Three,
    /// Four lights on a ring around the camera.
    Four,
    /// An AUV's layout: two lights well behind the camera and one beside it, all tilted forward, so the lit
    /// area is off-centre and the frame's leading edge is dim.
    Aft,
}

impl FromStr for Rig {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "two" | "2" => Ok(Rig::Two),
            "three" | "3" => Ok(Rig::Three),
            "four" | "4" => Ok(Rig::Four),
            "aft" => Ok(Rig::Aft),
            _ => Err(format!(
                "invalid rig {s:?}: expected two, three, four or aft"
            )),
        }
    }
}

/// A light in the camera frame.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Light {
    /// Position, metres, camera frame.
    pub position: [f32; 3],
    /// Beam axis (unit), camera frame.
    pub axis: [f32; 3],
    /// Relative power.
    pub power: f32,
    /// Angular fall-off of an LED behind a reflector: power · exp(−(θ/σ)⁶/2), flat in the middle with a soft but
    /// steeper edge than a Gaussian; σ in degrees.
    pub sigma_deg: f32,
}

impl Rig {
    /// The rig's lights, each with beam half-width `beam_deg` (σ of the fall-off, degrees).
    pub fn lights(self, beam_deg: f32) -> Vec<Light> {
        let l = |x: f32, y: f32, z: f32, ax: f32, ay: f32, power: f32| {
            let n = (ax * ax + ay * ay + 1.0).sqrt();
            Light {
                position: [x, y, z],
                axis: [ax / n, ay / n, 1.0 / n],
                power,
                sigma_deg: beam_deg,
            }
        };
        match self {
            Rig::Two => vec![
                l(-0.7, 0.25, 0.0, 0.18, -0.05, 1.0),
                l(0.7, 0.25, 0.0, -0.18, -0.05, 0.9),
            ],
            Rig::Three => vec![
                l(-0.7, 0.25, 0.0, 0.18, -0.05, 1.0),
                l(0.7, 0.25, 0.0, -0.18, -0.05, 0.9),
                l(0.0, 1.0, 0.1, 0.0, -0.3, 0.8),
            ],
            Rig::Four => vec![
                l(-0.6, 0.0, 0.0, 0.15, 0.0, 1.0),
                l(0.6, 0.0, 0.0, -0.15, 0.0, 0.95),
                l(0.0, -0.6, 0.0, 0.0, 0.15, 0.85),
                l(0.0, 0.6, 0.0, 0.0, -0.15, 0.9),
            ],
            Rig::Aft => vec![
                l(-0.5, 1.4, 0.0, 0.1, -0.32, 1.0),
                l(0.5, 1.4, 0.0, -0.1, -0.32, 0.95),
                l(0.9, 0.1, 0.0, -0.2, 0.0, 0.6),
            ],
        }
    }
}

/// Settings of a simulated dive.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields, rename_all = "kebab-case")]
pub struct Simulation {
    /// Survey photos. Default: 30.
    pub frames: usize,
    /// Water-column frames. Default: 15.
    pub water_column: usize,
    /// Photo width in pixels. Default: 320.
    pub width: usize,
    /// Photo height in pixels. Default: 240.
    pub height: usize,
    /// Seed of every random choice (floor, poses, particles, noise); same seed, same dive. Default: 1.
    pub seed: u64,
    /// Share of the seafloor covered by dark nodules. Default: 0.2.
    pub contamination: f64,
    /// 8 or 16. Default: 8.
    pub bit_depth: u32,
    /// Curve applied before quantisation: `linear` or `srgb` (any [`Transfer`]). Default: linear.
    pub encode: Transfer,
    /// Layout of the lights around the camera. Default: [`Rig::Three`].
    pub rig: Rig,
    /// Mean altitude above the floor, metres. Default: 3.
    pub altitude: f32,
    /// Share of a photo's along-track extent seen by the next photo. Default: 0.6.
    pub overlap: f32,
    /// Horizontal field of view, degrees. Default: 75.
    pub fov_deg: f32,
    /// Sensor noise multiplier (1 = default shot and read noise, 0 = none).
    pub noise: f32,
    /// Beam width of the lights (σ of the fall-off, degrees): 36 lights the whole frame evenly in the middle; with
    /// narrower beams the edges of the light cones come into the frame, as on many real rigs. Default: 36.
    pub beam_deg: f32,
    /// Water: per-channel attenuation `η` (1/m) and scattering `b` (1/m). Default: the mild water of the first
    /// versions ([`Water::MILD`]); see [`Water::preset`] for Jerlov-like presets.
    pub water: Water,
    /// Altitude swing, metres (amplitude of a slow and a faster oscillation around `altitude`, like a sledge or
    /// an AUV bouncing over terrain). Default: none, i.e. 5 % of the altitude, slowly.
    pub altitude_swing: Option<f32>,
    /// Camera white-balance gains applied to the sensor values (after the sensor noise, as a camera does), red,
    /// green, blue. Default: 1,1,1.
    pub white_balance: [f32; 3],
    /// How the exposure is set: `centre` (sediment at the image centre of a level camera reads 0.7 in green;
    /// default) or `brightest` (the brightest sediment anywhere in the frame, any channel after white balance,
    /// reads 0.8 — as an auto-exposure avoiding clipping does, so red-starved photos become dark and noisy).
    pub exposure: Exposure,
    /// Nodule coverage that changes along the track: the share at the first photo, the middle one and the last
    /// (linear in between), in place of `contamination` (a dive from bare sediment into a dense field and out to
    /// a sparse one). Default: none (one coverage).
    pub contamination_along: Option<[f64; 3]>,
}

/// How a simulated camera sets its exposure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Exposure {
    /// Sediment at the image centre of a level camera reads 0.7 in green (default).
    #[default]
    Centre,
    /// The brightest sediment anywhere in the frame, any channel after white balance, reads 0.8.
    Brightest,
}

impl FromStr for Exposure {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "centre" | "center" => Ok(Exposure::Centre),
            "brightest" => Ok(Exposure::Brightest),
            _ => Err(format!(
                "invalid exposure {s:?}: expected centre or brightest"
            )),
        }
    }
}

/// Optical properties of the simulated water, per channel (red, green, blue).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub struct Water {
    /// Attenuation coefficient `η`, 1/m.
    pub attenuation: [f32; 3],
    /// Scattering coefficient `b`, 1/m (drives the backscatter).
    pub scattering: [f32; 3],
}

impl Default for Water {
    fn default() -> Self {
        Water::MILD
    }
}

impl Water {
    /// The water of the first simulator versions (and of `demo`): mild, red only 3× blue.
    pub const MILD: Water = Water {
        attenuation: [0.25, 0.07, 0.09],
        scattering: [0.03, 0.04, 0.045],
    };

    /// Jerlov-like presets by name: `mild` (the default), `oceanic-i` (clear open ocean: red ~0.4/m, blue
    /// ~0.03/m), `oceanic-iii` (more particles: stronger scattering, blue and green attenuated more) and
    /// `coastal` (turbid, green water). Values follow the shape of Jerlov's diffuse attenuation curves at
    /// 600/530/470 nm, rounded; they are meant to make realistic test dives, not to model a given site.
    pub fn preset(name: &str) -> Option<Water> {
        Some(match name {
            "mild" => Water::MILD,
            "oceanic-i" | "jerlov-i" => Water {
                attenuation: [0.40, 0.065, 0.035],
                scattering: [0.02, 0.03, 0.035],
            },
            "oceanic-iii" | "jerlov-iii" => Water {
                attenuation: [0.45, 0.11, 0.10],
                scattering: [0.05, 0.06, 0.065],
            },
            "coastal" | "jerlov-3c" => Water {
                attenuation: [0.55, 0.20, 0.32],
                scattering: [0.09, 0.10, 0.10],
            },
            _ => return None,
        })
    }
}

impl FromStr for Water {
    type Err = String;

    /// A preset name, or `ηr,ηg,ηb` (attenuation only; scattering stays that of `mild`).
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        let t = s.trim().to_ascii_lowercase();
        if let Some(w) = Water::preset(&t) {
            return Ok(w);
        }
        let bad = || {
            format!(
                "invalid water {s:?}: expected mild, oceanic-i, oceanic-iii, coastal or three attenuation \
                 coefficients per metre such as 0.4,0.07,0.03"
            )
        };
        let v: Vec<f32> = t
            .split(',')
            .map(|p| p.trim().parse::<f32>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| bad())?;
        match v.as_slice() {
            [r, g, b] if v.iter().all(|x| (0.0..5.0).contains(x)) => Ok(Water {
                attenuation: [*r, *g, *b],
                ..Water::MILD
            }),
            _ => Err(bad()),
        }
    }
}

impl Default for Simulation {
    fn default() -> Self {
        Simulation {
            frames: 30,
            water_column: 15,
            width: 320,
            height: 240,
            seed: 1,
            contamination: 0.2,
            bit_depth: 8,
            encode: Transfer::Linear,
            rig: Rig::default(),
            altitude: 3.0,
            overlap: 0.6,
            fov_deg: 75.0,
            noise: 1.0,
            beam_deg: 36.0,
            water: Water::MILD,
            altitude_swing: None,
            white_balance: [1.0; 3],
            exposure: Exposure::Centre,
            contamination_along: None,
        }
    }
}

/// Pinhole camera model (pixel centres at integer + 0.5 are pixel `(x, y)`; `u = fx·X/Z + cx`).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct Camera {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Horizontal focal length in pixels.
    pub fx: f64,
    /// Vertical focal length in pixels (equal to `fx`: square pixels).
    pub fy: f64,
    /// Principal point, x in pixels (the image centre).
    pub cx: f64,
    /// Principal point, y in pixels (the image centre).
    pub cy: f64,
}

/// Pose of one survey photo.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Pose {
    /// File name in `survey/` (and `truth/albedo/`).
    pub file: String,
    /// Camera centre in world metres (`z` = altitude above the floor).
    pub position: [f64; 3],
    /// Roll about the track (world y), degrees.
    pub roll_deg: f64,
    /// Pitch about world x, degrees.
    pub pitch_deg: f64,
    /// Yaw about the vertical (world z), degrees.
    pub yaw_deg: f64,
    /// Camera-to-world rotation, row-major (columns: camera x right, y down in the image, z optical axis).
    pub rotation: [f64; 9],
    /// Homography from photo pixel coordinates to mosaic coordinates (row-major), as in `placements.txt`.
    pub homography: [f64; 9],
}

/// `truth/dive.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Truth {
    /// What wrote the dive (`abysslight VERSION simulate`).
    pub tool: String,
    /// The settings the dive was rendered with.
    pub settings: Simulation,
    /// The camera model of every photo.
    pub camera: Camera,
    /// Mosaic pixels per metre on the floor (the placements' unit).
    pub mosaic_pixels_per_metre: f64,
    /// Per-channel attenuation coefficient η (1/m).
    pub attenuation: [f32; 3],
    /// The rig's lights in the camera frame, as JSON.
    pub lights: serde_json::Value,
    /// Pose of each survey photo, in order.
    pub poses: Vec<Pose>,
    /// Water-column file names in `water/`.
    pub water: Vec<String>,
}

/// Albedo of the grey seafloor whose look `truth/lit/` records (`F·LIT_GREY`).
pub(crate) const LIT_GREY: f32 = 0.4;
/// Henyey–Greenstein asymmetry.
const HG_G: f32 = 0.6;
/// Water-column rays are integrated this far (metres).
const OPEN_WATER: f32 = 12.0;

// ---- deterministic randomness ---------------------------------------------------------------------------------

fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn hash3(seed: u64, a: i64, b: i64) -> u64 {
    mix(mix(mix(seed) ^ a as u64) ^ (b as u64).rotate_left(32))
}

fn unit(h: u64) -> f32 {
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// Sequential generator (splitmix64).
struct Rng(u64);
impl Rng {
    fn f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(1);
        unit(mix(self.0))
    }
}

/// Smooth value noise in `[0, 1]` on a unit lattice.
fn value_noise(seed: u64, x: f32, y: f32) -> f32 {
    let (fx, fy) = (x.floor(), y.floor());
    let (ix, iy) = (fx as i64, fy as i64);
    let (tx, ty) = (x - fx, y - fy);
    let (sx, sy) = (tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty));
    let v = |dx: i64, dy: i64| unit(hash3(seed, ix + dx, iy + dy));
    let a = v(0, 0) + (v(1, 0) - v(0, 0)) * sx;
    let b = v(0, 1) + (v(1, 1) - v(0, 1)) * sx;
    a + (b - a) * sy
}

// ---- the seafloor ---------------------------------------------------------------------------------------------

struct Floor {
    seed: u64,
    sediment: [f32; 3],
    /// Nodules per square metre and radius range.
    nodule_density: f32,
    /// Coverage along the track: at `y = 0`, at the middle and at the end `y = length` ([`Simulation::contamination_along`]).
    along: Option<([f64; 3], f32)>,
    r_min: f32,
    r_max: f32,
}

const NODULE_CELL: f32 = 0.4;
const OBJECT_CELL: f32 = 2.0;

impl Floor {
    fn new(seed: u64, contamination: f64) -> Floor {
        let (r_min, r_max) = (0.03f32, 0.10f32);
        let nodule_density = density(contamination, r_min, r_max);
        let mut rng = Rng(mix(seed ^ 0x5EA));
        let shade = 0.9 + 0.2 * rng.f32();
        Floor {
            seed,
            sediment: [0.62 * shade, 0.54 * shade, 0.42 * shade],
            nodule_density,
            along: None,
            r_min,
            r_max,
        }
    }

    /// Nodules per square metre at along-track position `y` (the coverage of [`Floor::along`] there, or the
    /// floor's one coverage).
    fn density_at(&self, y: f32) -> f32 {
        let Some((c, length)) = self.along else {
            return self.nodule_density;
        };
        let t = (y / length.max(1e-6)).clamp(0.0, 1.0) as f64 * 2.0;
        let c = if t <= 1.0 {
            c[0] + (c[1] - c[0]) * t
        } else {
            c[1] + (c[2] - c[1]) * (t - 1.0)
        };
        density(c, self.r_min, self.r_max)
    }

    /// Albedo (linear, per channel) at world point `(x, y)`.
    fn albedo(&self, x: f32, y: f32) -> [f32; 3] {
        let s = self.seed;
        // Bright objects (holothurians, sponges): ellipses on a coarse grid, one in ~7 cells.
        let (gx, gy) = (
            (x / OBJECT_CELL).floor() as i64,
            (y / OBJECT_CELL).floor() as i64,
        );
        for cy in gy - 1..=gy + 1 {
            for cx in gx - 1..=gx + 1 {
                let h = hash3(s ^ 0x0B7E, cx, cy);
                if unit(h) > 0.14 {
                    continue;
                }
                let ox = (cx as f32 + unit(mix(h ^ 1))) * OBJECT_CELL;
                let oy = (cy as f32 + unit(mix(h ^ 2))) * OBJECT_CELL;
                let len = 0.12 + 0.18 * unit(mix(h ^ 3));
                let ang = std::f32::consts::PI * unit(mix(h ^ 4));
                let (dx, dy) = (x - ox, y - oy);
                let (u, v) = (
                    dx * ang.cos() + dy * ang.sin(),
                    -dx * ang.sin() + dy * ang.cos(),
                );
                let e = (u / len).powi(2) + (v / (0.4 * len)).powi(2);
                if e <= 1.0 {
                    let t = 0.85 + 0.1 * value_noise(h, x * 40.0, y * 40.0);
                    return [0.92 * t, 0.86 * t, 0.80 * t];
                }
            }
        }
        // Nodules: a Poisson number per cell, discs of random radius.
        let (gx, gy) = (
            (x / NODULE_CELL).floor() as i64,
            (y / NODULE_CELL).floor() as i64,
        );
        for cy in gy - 1..=gy + 1 {
            for cx in gx - 1..=gx + 1 {
                // Nodule fields are patchy: the density varies over a few metres (mean factor 1).
                let patch = value_noise(
                    s ^ 0x9A7,
                    cx as f32 * NODULE_CELL / 2.5,
                    cy as f32 * NODULE_CELL / 2.5,
                );
                let density = self.density_at((cy as f32 + 0.5) * NODULE_CELL);
                let mean = density * NODULE_CELL * NODULE_CELL * (0.3 + 1.4 * patch);
                let mut rng = Rng(hash3(s ^ 0x90D, cx, cy));
                // Poisson by inversion.
                let u = rng.f32();
                let (mut k, mut p) = (0u32, (-mean).exp());
                let mut cdf = p;
                while u > cdf && k < 60 {
                    k += 1;
                    p *= mean / k as f32;
                    cdf += p;
                }
                for _ in 0..k {
                    let nx = (cx as f32 + rng.f32()) * NODULE_CELL;
                    let ny = (cy as f32 + rng.f32()) * NODULE_CELL;
                    let r = self.r_min + (self.r_max - self.r_min) * rng.f32();
                    let tone = 0.8 + 0.4 * rng.f32();
                    let d2 = (x - nx).powi(2) + (y - ny).powi(2);
                    if d2 <= r * r {
                        let t = tone * (0.85 + 0.3 * value_noise(s ^ 0x77, x * 60.0, y * 60.0));
                        return [0.075 * t, 0.065 * t, 0.055 * t];
                    }
                }
            }
        }
        // Sediment: low-frequency colour variation and fine texture.
        let low = value_noise(s ^ 1, x / 3.0, y / 3.0) - 0.5;
        let tint = value_noise(s ^ 2, x / 5.0, y / 5.0) - 0.5;
        let tex = 0.6 * (value_noise(s ^ 3, x / 0.02, y / 0.02) - 0.5)
            + 0.4 * (value_noise(s ^ 4, x / 0.07, y / 0.07) - 0.5);
        let g = (1.0 + 0.25 * low) * (1.0 + 0.35 * tex);
        [
            self.sediment[0] * g * (1.0 + 0.12 * tint),
            self.sediment[1] * g,
            self.sediment[2] * g * (1.0 - 0.12 * tint),
        ]
    }
}

/// Nodules per square metre for a coverage `c` of discs with radii uniform in `[r_min, r_max]` (Boolean model:
/// coverage = 1 − exp(−λ·π·E[r²])).
fn density(c: f64, r_min: f32, r_max: f32) -> f32 {
    let er2 = (r_min * r_min + r_min * r_max + r_max * r_max) / 3.0;
    let c = c.clamp(0.0, 0.95) as f32;
    -(1.0 - c).ln() / (std::f32::consts::PI * er2)
}

// ---- geometry -------------------------------------------------------------------------------------------------

type V3 = [f32; 3];

fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn norm(a: V3) -> V3 {
    let l = dot(a, a).sqrt();
    [a[0] / l, a[1] / l, a[2] / l]
}
fn mat_vec(r: &[f64; 9], v: V3) -> V3 {
    let f =
        |i: usize| (r[i] * v[0] as f64 + r[i + 1] * v[1] as f64 + r[i + 2] * v[2] as f64) as f32;
    [f(0), f(3), f(6)]
}
fn mat_mul(a: &[f64; 9], b: &[f64; 9]) -> [f64; 9] {
    let mut o = [0.0; 9];
    for i in 0..3 {
        for j in 0..3 {
            o[i * 3 + j] = (0..3).map(|k| a[i * 3 + k] * b[k * 3 + j]).sum();
        }
    }
    o
}

/// Inverse of a 3×3 matrix (row-major); `None` when singular.
pub(crate) fn invert3(m: &[f64; 9]) -> Option<[f64; 9]> {
    let [a, b, c, d, e, f, g, h, i] = *m;
    let co = [
        e * i - f * h,
        -(b * i - c * h),
        b * f - c * e,
        -(d * i - f * g),
        a * i - c * g,
        -(a * f - c * d),
        d * h - e * g,
        -(a * h - b * g),
        a * e - b * d,
    ];
    let det = a * co[0] + b * co[3] + c * co[6];
    if det.abs() < 1e-300 || !det.is_finite() {
        return None;
    }
    Some(co.map(|v| v / det))
}

fn rotation(roll: f64, pitch: f64, yaw: f64) -> [f64; 9] {
    // Base: camera x = world x, camera y (image down) = world −y (behind), optical axis = world −z.
    let base = [1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0];
    let (sr, cr) = roll.to_radians().sin_cos();
    let (sp, cp) = pitch.to_radians().sin_cos();
    let (sy, cy) = yaw.to_radians().sin_cos();
    let ry = [cr, 0.0, sr, 0.0, 1.0, 0.0, -sr, 0.0, cr]; // roll about the track (world y)
    let rx = [1.0, 0.0, 0.0, 0.0, cp, -sp, 0.0, sp, cp]; // pitch about world x
    let rz = [cy, -sy, 0.0, sy, cy, 0.0, 0.0, 0.0, 1.0];
    mat_mul(&rz, &mat_mul(&ry, &mat_mul(&rx, &base)))
}

/// Homography from pixel coordinates to floor coordinates (metres) for a camera at `c` with rotation `r`.
fn pixel_to_floor(cam: &Camera, r: &[f64; 9], c: [f64; 3]) -> [f64; 9] {
    // Floor → pixel: K · Rᵀ · [e1 e2 −C].
    let rt = [r[0], r[3], r[6], r[1], r[4], r[7], r[2], r[5], r[8]];
    let rtc = [
        rt[0] * c[0] + rt[1] * c[1] + rt[2] * c[2],
        rt[3] * c[0] + rt[4] * c[1] + rt[5] * c[2],
        rt[6] * c[0] + rt[7] * c[1] + rt[8] * c[2],
    ];
    let m = [
        rt[0], rt[1], -rtc[0], rt[3], rt[4], -rtc[1], rt[6], rt[7], -rtc[2],
    ];
    let k = [cam.fx, 0.0, cam.cx, 0.0, cam.fy, cam.cy, 0.0, 0.0, 1.0];
    invert3(&mat_mul(&k, &m)).expect("camera sees the floor")
}

/// Apply a homography to a point.
#[doc(hidden)]
pub fn apply_h(h: &[f64; 9], x: f64, y: f64) -> (f64, f64) {
    let w = h[6] * x + h[7] * y + h[8];
    (
        (h[0] * x + h[1] * y + h[2]) / w,
        (h[3] * x + h[4] * y + h[5]) / w,
    )
}

fn hg(cos: f32) -> f32 {
    let g2 = HG_G * HG_G;
    (1.0 - g2) / (4.0 * std::f32::consts::PI * (1.0 + g2 - 2.0 * HG_G * cos).powf(1.5))
}

/// Lights in world coordinates for one pose.
struct WorldLight {
    pos: V3,
    axis: V3,
    power: f32,
    inv_sigma: f32,
    eta: [f32; 3],
}

fn world_lights(lights: &[Light], r: &[f64; 9], c: V3, eta: [f32; 3]) -> Vec<WorldLight> {
    lights
        .iter()
        .map(|l| {
            let p = mat_vec(r, l.position);
            WorldLight {
                pos: [c[0] + p[0], c[1] + p[1], c[2] + p[2]],
                axis: norm(mat_vec(r, l.axis)),
                power: l.power,
                inv_sigma: 1.0 / l.sigma_deg.to_radians(),
                eta,
            }
        })
        .collect()
}

impl WorldLight {
    /// Irradiance-like term at `q` per channel, without the surface cosine: power·fall-off·exp(−η d)/d².
    #[inline]
    fn reach(&self, q: V3) -> ([f32; 3], V3, f32) {
        let v = [q[0] - self.pos[0], q[1] - self.pos[1], q[2] - self.pos[2]];
        let d = dot(v, v).sqrt().max(0.15);
        let dir = [v[0] / d, v[1] / d, v[2] / d];
        let th = dot(dir, self.axis).clamp(-1.0, 1.0).acos();
        let base = self.power * (-0.5 * (th * self.inv_sigma).powi(6)).exp() / (d * d);
        (
            [
                base * (-self.eta[0] * d).exp(),
                base * (-self.eta[1] * d).exp(),
                base * (-self.eta[2] * d).exp(),
            ],
            dir,
            d,
        )
    }
}

/// Everything needed to render one frame.
struct View<'a> {
    cam: Camera,
    r: [f64; 9],
    c: V3,
    lights: Vec<WorldLight>,
    floor: Option<&'a Floor>,
    water: Water,
}

impl View<'_> {
    fn ray(&self, u: f32, v: f32) -> V3 {
        let d = [
            (u - self.cam.cx as f32) / self.cam.fx as f32,
            (v - self.cam.cy as f32) / self.cam.fy as f32,
            1.0,
        ];
        norm(mat_vec(&self.r, d))
    }

    /// Single-scattering backscatter along the ray `d` up to `len` metres.
    fn backscatter(&self, d: V3, len: f32) -> [f32; 3] {
        const STEPS: usize = 40;
        let mut s = [0.0f32; 3];
        // Denser samples near the camera, where the lights are close.
        for k in 0..STEPS {
            let t0 = len * (k as f32 / STEPS as f32).powi(2);
            let t1 = len * ((k + 1) as f32 / STEPS as f32).powi(2);
            let t = 0.5 * (t0 + t1);
            let q = [
                self.c[0] + t * d[0],
                self.c[1] + t * d[1],
                self.c[2] + t * d[2],
            ];
            for l in &self.lights {
                let (e, dir, _) = l.reach(q);
                let phase = hg(dot(dir, [-d[0], -d[1], -d[2]]));
                for ch in 0..3 {
                    s[ch] += self.water.scattering[ch]
                        * e[ch]
                        * phase
                        * (-self.water.attenuation[ch] * t).exp()
                        * (t1 - t0);
                }
            }
        }
        s
    }
}

/// A rendered frame: radiance after exposure, and for survey frames the true albedo; with `lighting`, also the
/// true factor `F` (what an albedo of 1 would read, per pixel and channel) and backscatter `S`, both after
/// exposure and before white balance and noise.
struct Rendered {
    img: Raster,
    albedo: Option<Raster>,
    factor: Option<Raster>,
    backscatter: Option<Raster>,
}

/// Render a frame in linear light.
fn render(view: &View, exposure: f32, lighting: bool) -> Rendered {
    let (w, h) = (view.cam.width, view.cam.height);
    // Backscatter is smooth: computed on a coarse grid and interpolated.
    let grid = BackscatterGrid::new(view, 4);
    let mut img = Raster::filled(w, h, 3, 0.0);
    let mut alb = view.floor.map(|_| Raster::filled(w, h, 3, 0.0));
    let mut fac = (lighting && view.floor.is_some()).then(|| Raster::filled(w, h, 3, 0.0));
    let mut bsc = lighting.then(|| Raster::filled(w, h, 3, 0.0));
    fn rows(r: &mut Option<Raster>, w: usize, h: usize) -> Vec<Option<&mut [f32]>> {
        match r {
            Some(r) => r.data.chunks_mut(w * 3).map(Some).collect(),
            None => (0..h).map(|_| None).collect(),
        }
    }
    let (ar, fr, sr) = (
        rows(&mut alb, w, h),
        rows(&mut fac, w, h),
        rows(&mut bsc, w, h),
    );
    img.data
        .par_chunks_mut(w * 3)
        .zip(ar)
        .zip(fr)
        .zip(sr)
        .enumerate()
        .for_each(|(y, (((img, albedo), factor), backscatter))| {
            let out = RowOut {
                img,
                albedo,
                factor,
                backscatter,
            };
            render_row(view, &grid, exposure, y, out)
        });
    Rendered {
        img,
        albedo: alb,
        factor: fac,
        backscatter: bsc,
    }
}

/// A view's backscatter on a coarse grid (every `step` pixels, one node beyond each border), interpolated per
/// pixel: backscatter is smooth.
struct BackscatterGrid {
    nodes: Vec<[f32; 3]>,
    cols: usize,
    step: usize,
}

impl BackscatterGrid {
    /// Integrate the backscatter along the ray of every grid node (to the floor, or through open water).
    fn new(view: &View, step: usize) -> Self {
        let (w, h) = (view.cam.width, view.cam.height);
        let (gw, gh) = (w.div_ceil(step) + 1, h.div_ceil(step) + 1);
        let nodes: Vec<[f32; 3]> = (0..gw * gh)
            .into_par_iter()
            .map(|i| {
                let (gx, gy) = ((i % gw) * step, (i / gw) * step);
                let d = view.ray(gx as f32 + 0.5, gy as f32 + 0.5);
                let len = match view.floor {
                    Some(_) if d[2] < -1e-3 => (-view.c[2] / d[2]).min(OPEN_WATER),
                    _ => OPEN_WATER,
                };
                view.backscatter(d, len)
            })
            .collect();
        BackscatterGrid {
            nodes,
            cols: gw,
            step,
        }
    }

    /// Bilinear interpolation of the grid at pixel `(x, y)`.
    fn at(&self, x: usize, y: usize) -> [f32; 3] {
        let step = self.step;
        let (fx, fy) = (x as f32 / step as f32, y as f32 / step as f32);
        let (x0, y0) = (fx as usize, fy as usize);
        let (tx, ty) = (fx - x0 as f32, fy - y0 as f32);
        let g = |xx: usize, yy: usize| self.nodes[yy * self.cols + xx];
        let mut px = [0.0f32; 3];
        for (ch, p) in px.iter_mut().enumerate() {
            let a = g(x0, y0)[ch] + (g(x0 + 1, y0)[ch] - g(x0, y0)[ch]) * tx;
            let b = g(x0, y0 + 1)[ch] + (g(x0 + 1, y0 + 1)[ch] - g(x0, y0 + 1)[ch]) * tx;
            *p = a + (b - a) * ty;
        }
        px
    }
}

/// One image row of a [`Rendered`] frame: the radiance, and the rows of the truths being rendered.
struct RowOut<'a> {
    img: &'a mut [f32],
    albedo: Option<&'a mut [f32]>,
    factor: Option<&'a mut [f32]>,
    backscatter: Option<&'a mut [f32]>,
}

/// Where the ray of a pixel meets the floor: the albedo there, the irradiance of all lights (with their angle of
/// incidence), the ray's length and the camera's vignetting (cos⁴ off axis).
struct FloorHit {
    albedo: [f32; 3],
    irradiance: [f32; 3],
    t: f32,
    vignette: f32,
}

/// The floor as seen through pixel `(x, y)` of `view`.
fn floor_hit(view: &View, floor: &Floor, x: usize, y: usize) -> FloorHit {
    let d = view.ray(x as f32 + 0.5, y as f32 + 0.5);
    let t = -view.c[2] / d[2];
    let q = [view.c[0] + t * d[0], view.c[1] + t * d[1], 0.0];
    let a = floor.albedo(q[0], q[1]);
    let mut e = [0.0f32; 3];
    for l in &view.lights {
        let (r, dir, _) = l.reach(q);
        let cos_inc = (-dir[2]).max(0.0);
        for ch in 0..3 {
            e[ch] += r[ch] * cos_inc;
        }
    }
    let cos_cam = dot(d, mat_vec(&view.r, [0.0, 0.0, 1.0])).max(0.0);
    FloorHit {
        albedo: a,
        irradiance: e,
        t,
        vignette: cos_cam.powi(4),
    }
}

/// Render row `y` of `view` into `out`: backscatter from `grid`, plus the lit floor when in view; all after
/// `exposure`.
fn render_row(view: &View, grid: &BackscatterGrid, exposure: f32, y: usize, mut out: RowOut) {
    let eta = view.water.attenuation;
    for x in 0..view.cam.width {
        let mut px = grid.at(x, y);
        if let Some(sr) = out.backscatter.as_deref_mut() {
            for ch in 0..3 {
                sr[x * 3 + ch] = px[ch] * exposure;
            }
        }
        if let Some(floor) = view.floor {
            let FloorHit {
                albedo: a,
                irradiance: e,
                t,
                vignette,
            } = floor_hit(view, floor, x, y);
            for ch in 0..3 {
                px[ch] += a[ch] * e[ch] / std::f32::consts::PI * (-eta[ch] * t).exp() * vignette;
            }
            if let Some(fr) = out.factor.as_deref_mut() {
                for ch in 0..3 {
                    fr[x * 3 + ch] =
                        e[ch] / std::f32::consts::PI * (-eta[ch] * t).exp() * vignette * exposure;
                }
            }
            if let Some(ar) = out.albedo.as_deref_mut() {
                ar[x * 3..x * 3 + 3].copy_from_slice(&a);
            }
        }
        for (o, v) in out.img[x * 3..x * 3 + 3].iter_mut().zip(px) {
            *o = v * exposure;
        }
    }
}

/// Particles in a frame of `width`×`height`: one per 2500 pixels of a 320×240 frame (at least 3). [`add_particles`]
/// grows their radius with the frame above 320 pixels across, so there their number stays that of 320×240: the
/// same water seen at a higher resolution, not more of it. (Before, it grew with the pixel count too: a 640×480
/// dive had four times the particle cover, its red channel under ×6 white balance read 6e-4 brighter everywhere,
/// and the oracle's residual pattern on the median matrix dive was 2.5× that at 320×240.)
fn particle_count(width: usize, height: usize) -> usize {
    let above = (width as f32 / 320.0).max(1.0);
    ((width * height) as f32 / 2500.0 / (above * above)).max(3.0) as usize
}

/// Floating particles: small bright blobs lit by the lights.
fn add_particles(img: &mut Raster, rng: &mut Rng, count: usize) {
    let (w, h) = (img.width, img.height);
    let scale = w as f32 / 320.0;
    for _ in 0..count {
        let (px, py) = (rng.f32() * w as f32, rng.f32() * h as f32);
        let r = (0.6 + 1.4 * rng.f32()) * scale;
        let b = 0.15 + 0.6 * rng.f32();
        let tint = [0.7 + 0.2 * rng.f32(), 1.0, 0.95];
        let reach = (2.5 * r).ceil() as i64;
        for y in (py as i64 - reach).max(0)..(py as i64 + reach + 1).min(h as i64) {
            for x in (px as i64 - reach).max(0)..(px as i64 + reach + 1).min(w as i64) {
                let d2 = (x as f32 + 0.5 - px).powi(2) + (y as f32 + 0.5 - py).powi(2);
                let v = b * (-d2 / (r * r)).exp();
                for (ch, t) in tint.iter().enumerate() {
                    img.data[(y as usize * w + x as usize) * 3 + ch] += v * t;
                }
            }
        }
    }
}

/// Shot and read noise, the white-balance gains, then the transfer curve and quantisation.
fn finish(img: &Raster, seed: u64, noise: f32, bits: u32, encode: Transfer, wb: [f32; 3]) -> Photo {
    let max = if bits == 16 { 65535.0 } else { 255.0 };
    let vals: Vec<f32> = img
        .data
        .par_iter()
        .enumerate()
        .map(|(i, &v)| {
            let h = mix(seed ^ (i as u64).wrapping_mul(0x2545_F491));
            // Sum of four uniforms: approximately normal, unit variance.
            let n = (0..4).map(|k| unit(mix(h ^ k)) - 0.5).sum::<f32>() * 3.0f32.sqrt();
            let sigma = noise * (0.0003 * v.max(0.0) + 0.003f32.powi(2)).sqrt();
            let l = ((v + sigma * n) * wb[i % 3]).clamp(0.0, 1.0);
            encode.from_linear(l) * max
        })
        .collect();
    let layout = Layout {
        width: img.width,
        height: img.height,
        channels: 3,
    };
    let samples = if bits == 16 {
        Samples::U16(vals.iter().map(|&v| (v + 0.5) as u16).collect())
    } else {
        Samples::U8(vals.iter().map(|&v| (v + 0.5) as u8).collect())
    };
    Photo {
        layout,
        samples,
        alpha: None,
    }
}

/// The rendered dive, in memory.
pub struct Dive {
    /// Everything `truth/dive.json` records: settings, camera, poses, file names.
    pub truth: Truth,
    /// The survey photos, as the camera encoded them.
    pub survey: Vec<Photo>,
    /// The water-column photos (open water, no floor in view).
    pub water: Vec<Photo>,
    /// True albedo of each survey photo (linear).
    pub albedo: Vec<Raster>,
    /// With [`Simulation::render_with_lighting`]: each survey photo's true `F` (the linear value an albedo of 1
    /// would read, white balance included) and true backscatter `S` (linear, white balance included), so that an
    /// oracle correction `(I − S)/F` can be scored. Empty otherwise.
    pub factor: Vec<Raster>,
    /// True backscatter `S` of each survey photo with [`Simulation::render_with_lighting`]; empty otherwise.
    pub backscatter: Vec<Raster>,
}

/// The survey photos of a dive with their truths (see [`Dive`]).
struct SurveyFrames {
    survey: Vec<Photo>,
    albedo: Vec<Raster>,
    factor: Vec<Raster>,
    backscatter: Vec<Raster>,
}

/// The view of camera `cam` with the rig's `lights` at pose `p`, of `floor` if given (else open water).
fn pose_view<'a>(
    cam: Camera,
    lights: &[Light],
    p: &Pose,
    floor: Option<&'a Floor>,
    water: Water,
) -> View<'a> {
    View {
        cam,
        r: p.rotation,
        c: [
            p.position[0] as f32,
            p.position[1] as f32,
            p.position[2] as f32,
        ],
        lights: world_lights(
            lights,
            &p.rotation,
            [
                p.position[0] as f32,
                p.position[1] as f32,
                p.position[2] as f32,
            ],
            water.attenuation,
        ),
        floor,
        water,
    }
}

/// Largest photo side the simulator makes (pixels).
pub(crate) const MAX_SIDE: usize = 16384;

/// Most survey photos (and most water-column frames) of a simulated dive.
pub(crate) const MAX_FRAMES: usize = 1_000_000;

impl Simulation {
    /// Refuse settings the renderer cannot use: the ranges of `abysslight simulate`'s flags (counts, size, physical
    /// parameters; NaN nowhere), then what the renderer needs (size under 16×16, field of view outside 20–150°,
    /// ...). Each message names the command's flag. [`Simulation::render`] runs it first.
    pub fn validate(&self) -> Result<()> {
        use crate::eval::within;
        within("--frames", self.frames, 1, MAX_FRAMES)?;
        // No water-column frames is a dive of the library's (the command asks for at least one).
        within("--water-column", self.water_column, 0, MAX_FRAMES)?;
        within("--size (width)", self.width, 8, MAX_SIDE)?;
        within("--size (height)", self.height, 8, MAX_SIDE)?;
        within("--contamination", self.contamination, 0.0, 1.0)?;
        within("--altitude", self.altitude, 0.1, 1000.0)?;
        within("--overlap", self.overlap, 0.0, 0.99)?;
        within("--fov", self.fov_deg, 1.0, 170.0)?;
        within("--beam", self.beam_deg, 1.0, 180.0)?;
        within("--noise", self.noise, 0.0, 100.0)?;
        within(
            "--altitude-swing",
            self.altitude_swing.unwrap_or(0.0),
            0.0,
            1000.0,
        )?;
        for g in self.white_balance {
            within("--white-balance", g, 0.01, 100.0)?;
        }
        let bad = |m: String| Err(Error::Usage(m));
        if self.width < 16 || self.height < 16 {
            return bad(format!(
                "--size must be at least 16x16, got {}x{}",
                self.width, self.height
            ));
        }
        if self.frames == 0 {
            return bad("--frames must be at least 1".into());
        }
        if !(0.0..0.95).contains(&self.contamination) {
            return bad(format!(
                "--contamination must be in [0, 0.95), got {}",
                self.contamination
            ));
        }
        if self.bit_depth != 8 && self.bit_depth != 16 {
            return bad(format!(
                "--bit-depth must be 8 or 16, got {}",
                self.bit_depth
            ));
        }
        if !(self.altitude > 0.5 && self.altitude < 20.0) {
            return bad(format!(
                "--altitude must be between 0.5 and 20 m, got {}",
                self.altitude
            ));
        }
        if !(0.0..0.95).contains(&self.overlap) {
            return bad(format!(
                "--overlap must be in [0, 0.95), got {}",
                self.overlap
            ));
        }
        if self
            .altitude_swing
            .is_some_and(|m| !(m >= 0.0 && m < 0.8 * self.altitude))
        {
            return bad(format!(
                "--altitude-swing must be from 0 to 80 % of the altitude, got {:?}",
                self.altitude_swing
            ));
        }
        if self.white_balance.iter().any(|g| !(*g > 0.0 && *g < 50.0)) {
            return bad(format!(
                "--white-balance gains must be above 0 and below 50, got {:?}",
                self.white_balance
            ));
        }
        if !(20.0..150.0).contains(&self.fov_deg) {
            return bad(format!(
                "--fov must be 20 to 150 degrees, got {}",
                self.fov_deg
            ));
        }
        Ok(())
    }

    /// The pinhole camera of these settings: `width`×`height`, horizontal field of view `fov_deg`, centred.
    pub fn camera(&self) -> Camera {
        let f = (self.width as f64 / 2.0) / (self.fov_deg as f64 / 2.0).to_radians().tan();
        Camera {
            width: self.width,
            height: self.height,
            fx: f,
            fy: f,
            cx: self.width as f64 / 2.0,
            cy: self.height as f64 / 2.0,
        }
    }

    /// Render the dive in memory.
    pub fn render(&self) -> Result<Dive> {
        self.render_inner(false)
    }

    /// Render the dive in memory with each survey photo's true `F` and `S` ([`Dive::factor`],
    /// [`Dive::backscatter`]).
    pub fn render_with_lighting(&self) -> Result<Dive> {
        self.render_inner(true)
    }

    /// Pose of each survey photo along the track (slow random swings of altitude, roll, pitch, yaw and a side
    /// drift), with homographies into a mosaic whose origin is the top-left of all footprints.
    fn poses(&self, cam: &Camera) -> Vec<Pose> {
        let alt = self.altitude as f64;
        let ppm = cam.fy / alt;
        let footprint = alt * self.height as f64 / cam.fy;
        let step = footprint * (1.0 - self.overlap as f64);
        let mut rng = Rng(mix(self.seed ^ 0xD1E));
        let phase: Vec<f64> = (0..6)
            .map(|_| rng.f32() as f64 * std::f64::consts::TAU)
            .collect();
        let pose = |i: usize| {
            let t = i as f64;
            let z = match self.altitude_swing {
                None => alt * (1.0 + 0.05 * (0.1 * t + phase[0]).sin()),
                Some(m) => {
                    alt + m as f64
                        * (0.6 * (0.1 * t + phase[0]).sin() + 0.4 * (0.9 * t + phase[5]).sin())
                }
            };
            let roll = 3.0 * (0.17 * t + phase[1]).sin();
            let pitch = 3.0 * (0.13 * t + phase[2]).sin();
            let yaw = 2.0 * (0.09 * t + phase[3]).sin();
            let x = 0.15 * alt * (0.11 * t + phase[4]).sin();
            let y = step * t;
            let r = rotation(roll, pitch, yaw);
            let to_floor = pixel_to_floor(cam, &r, [x, y, z]);
            let to_mosaic = [ppm, 0.0, 0.0, 0.0, -ppm, 0.0, 0.0, 0.0, 1.0];
            Pose {
                file: format!("{:04}.png", i + 1),
                position: [x, y, z],
                roll_deg: roll,
                pitch_deg: pitch,
                yaw_deg: yaw,
                rotation: r,
                homography: mat_mul(&to_mosaic, &to_floor),
            }
        };
        let mut poses: Vec<Pose> = (0..self.frames).map(pose).collect();
        // Mosaic origin: the top-left of all footprints.
        let (mut mx, mut my) = (f64::INFINITY, f64::INFINITY);
        for p in &poses {
            for (u, v) in [
                (0.0, 0.0),
                (cam.width as f64, 0.0),
                (0.0, cam.height as f64),
                (cam.width as f64, cam.height as f64),
            ] {
                let (a, b) = apply_h(&p.homography, u, v);
                mx = mx.min(a);
                my = my.min(b);
            }
        }
        for p in &mut poses {
            let shift = [1.0, 0.0, -mx.floor(), 0.0, 1.0, -my.floor(), 0.0, 0.0, 1.0];
            p.homography = mat_mul(&shift, &p.homography);
        }
        poses
    }

    /// Exposure gain of the dive from the view of a level camera at the mean altitude (see [`Exposure`]).
    fn exposure_gain(&self, probe: &View, floor: &Floor) -> f32 {
        let cam = probe.cam;
        let eta = self.water.attenuation;
        let wb = self.white_balance;
        if self.exposure == Exposure::Brightest {
            // The brightest sediment of the frame, any channel, after white balance, reads 0.8.
            let mut brightest = 0.0f32;
            for gy in 0..=16 {
                for gx in 0..=16 {
                    let u = (gx as f32 / 16.0) * (cam.width as f32 - 1.0) + 0.5;
                    let v = (gy as f32 / 16.0) * (cam.height as f32 - 1.0) + 0.5;
                    let d = probe.ray(u, v);
                    let t = -probe.c[2] / d[2];
                    let q = [probe.c[0] + t * d[0], probe.c[1] + t * d[1], 0.0];
                    let cos_cam = dot(d, mat_vec(&probe.r, [0.0, 0.0, 1.0])).max(0.0);
                    for ch in 0..3 {
                        let e: f32 = probe
                            .lights
                            .iter()
                            .map(|l| {
                                let (r, dir, _) = l.reach(q);
                                r[ch] * (-dir[2]).max(0.0)
                            })
                            .sum();
                        let read = floor.sediment[ch] * e / std::f32::consts::PI
                            * (-eta[ch] * t).exp()
                            * cos_cam.powi(4)
                            * wb[ch];
                        brightest = brightest.max(read);
                    }
                }
            }
            0.8 / brightest
        } else {
            let d = probe.ray(cam.cx as f32, cam.cy as f32);
            let t = -probe.c[2] / d[2];
            let q = [probe.c[0] + t * d[0], probe.c[1] + t * d[1], 0.0];
            let e: f32 = probe
                .lights
                .iter()
                .map(|l| {
                    let (r, dir, _) = l.reach(q);
                    r[1] * (-dir[2]).max(0.0)
                })
                .sum();
            0.7 / (floor.sediment[1] * e / std::f32::consts::PI * (-eta[1] * t).exp())
        }
    }

    /// The water-column photos: `base` (the rig's backscatter in open water) with fresh particles and noise each.
    fn water_column(&self, base: &Raster, particles: usize) -> (Vec<Photo>, Vec<String>) {
        let wb = self.white_balance;
        let mut water = Vec::new();
        let mut names = Vec::new();
        for i in 0..self.water_column {
            let mut img = base.clone();
            let mut prng = Rng(mix(self.seed ^ 0x3A7E ^ ((i as u64) << 24)));
            add_particles(&mut img, &mut prng, particles * 2);
            water.push(finish(
                &img,
                mix(self.seed ^ 0xBEEF ^ i as u64),
                self.noise,
                self.bit_depth,
                self.encode,
                wb,
            ));
            names.push(format!("{:04}.png", i + 1));
        }
        (water, names)
    }

    /// Render the dive: survey photos with their true albedo (and with `lighting`, their true `F` and `S`), then
    /// the water column.
    fn render_inner(&self, lighting: bool) -> Result<Dive> {
        self.validate()?;
        let cam = self.camera();
        let poses = self.poses(&cam);
        let floor = self.floor(&poses);
        let lights = self.rig.lights(self.beam_deg);
        let alt = self.altitude as f64;
        let ppm = cam.fy / alt;
        let view = |p: &Pose, with_floor: bool| {
            let floor = if with_floor { Some(&floor) } else { None };
            pose_view(cam, &lights, p, floor, self.water)
        };
        // Exposure: from the view of a level camera at the mean altitude (see [`Exposure`]).
        let level = Pose {
            rotation: rotation(0.0, 0.0, 0.0),
            position: [0.0, 0.0, alt],
            ..poses[0].clone()
        };
        let probe = view(&level, true);
        let eta = self.water.attenuation;
        let exposure = self.exposure_gain(&probe, &floor);
        let particles = particle_count(self.width, self.height);
        let frames = self.survey_frames(&poses, |p| view(p, true), exposure, lighting);
        // Water column: the same rig and camera on the way down, open water in view.
        let (water, names) = if self.water_column > 0 {
            let base = render(&view(&level, false), exposure, false).img;
            self.water_column(&base, particles)
        } else {
            (Vec::new(), Vec::new())
        };
        let truth = Truth {
            tool: format!("abysslight {} simulate", env!("CARGO_PKG_VERSION")),
            settings: self.clone(),
            camera: cam,
            mosaic_pixels_per_metre: ppm,
            attenuation: eta,
            lights: serde_json::to_value(&lights).unwrap_or_default(),
            poses,
            water: names,
        };
        Ok(Dive {
            truth,
            survey: frames.survey,
            water,
            albedo: frames.albedo,
            factor: frames.factor,
            backscatter: frames.backscatter,
        })
    }

    /// The seafloor of the dive; with `contamination_along`, its contamination changes along the track up to the
    /// last pose.
    fn floor(&self, poses: &[Pose]) -> Floor {
        let mut floor = Floor::new(self.seed, self.contamination);
        if let Some(c) = self.contamination_along {
            let length = poses.last().map_or(0.0, |p| p.position[1]) as f32;
            floor.along = Some((c, length));
        }
        floor
    }

    /// Render the survey photos, one per pose (`view` gives each pose's view of the floor): particles, noise and
    /// encoding added to each, with its true albedo and, with `lighting`, its true `F` and `S` (white-balanced).
    fn survey_frames<'f>(
        &self,
        poses: &[Pose],
        view: impl Fn(&Pose) -> View<'f>,
        exposure: f32,
        lighting: bool,
    ) -> SurveyFrames {
        let wb = self.white_balance;
        let mut frames = SurveyFrames {
            survey: Vec::with_capacity(self.frames),
            albedo: Vec::with_capacity(self.frames),
            factor: Vec::new(),
            backscatter: Vec::new(),
        };
        let particles = particle_count(self.width, self.height);
        let with_wb = |mut r: Raster| {
            for (i, v) in r.data.iter_mut().enumerate() {
                *v *= wb[i % 3];
            }
            r
        };
        for (i, p) in poses.iter().enumerate() {
            let Rendered {
                mut img,
                albedo: alb,
                factor,
                backscatter,
            } = render(&view(p), exposure, lighting);
            let mut prng = Rng(mix(self.seed ^ 0x5A11 ^ ((i as u64) << 20)));
            add_particles(&mut img, &mut prng, particles / 2);
            frames.survey.push(finish(
                &img,
                mix(self.seed ^ 0xF00 ^ i as u64),
                self.noise,
                self.bit_depth,
                self.encode,
                wb,
            ));
            frames
                .albedo
                .push(alb.expect("survey frames see the floor"));
            if let (Some(f), Some(s)) = (factor, backscatter) {
                frames.factor.push(with_wb(f));
                frames.backscatter.push(with_wb(s));
            }
        }
        frames
    }

    /// Render the dive and write it to `out` (see the module docs for the layout).
    pub fn write(&self, out: &Path) -> Result<Truth> {
        let dive = self.render()?;
        dive.write(out)?;
        Ok(dive.truth)
    }
}

impl Dive {
    /// With true lighting rendered: `truth/lit/NNNN.png` (`F·0.4`, what a grey seafloor of albedo 0.4 reads,
    /// linear 16-bit) and `truth/backscatter/NNNN.png` (`S`, linear 16-bit).
    fn lighting_jobs(&self, out: &Path) -> Vec<(PathBuf, Photo)> {
        let photo = |r: &Raster, scale: f32| {
            let mut r = r.clone();
            for v in &mut r.data {
                *v *= scale;
            }
            Photo {
                layout: r.layout(),
                samples: Samples::U16(r.to_u16()),
                alpha: None,
            }
        };
        let mut jobs = Vec::new();
        for (pose, (f, s)) in self
            .truth
            .poses
            .iter()
            .zip(self.factor.iter().zip(&self.backscatter))
        {
            jobs.push((
                out.join("truth").join("lit").join(&pose.file),
                photo(f, LIT_GREY),
            ));
            jobs.push((
                out.join("truth").join("backscatter").join(&pose.file),
                photo(s, 1.0),
            ));
        }
        jobs
    }

    /// Write `water/`, `survey/` and `truth/` below `out`.
    pub fn write(&self, out: &Path) -> Result<()> {
        let settings = EncodeSettings::default();
        let jobs: Vec<(PathBuf, Photo)> = self
            .water
            .iter()
            .zip(&self.truth.water)
            .map(|(p, n)| (out.join("water").join(n), p.clone()))
            .chain(
                self.survey
                    .iter()
                    .zip(&self.truth.poses)
                    .map(|(p, pose)| (out.join("survey").join(&pose.file), p.clone())),
            )
            .chain(self.albedo.iter().zip(&self.truth.poses).map(|(a, pose)| {
                (
                    out.join("truth").join("albedo").join(&pose.file),
                    Photo {
                        layout: a.layout(),
                        samples: Samples::U16(a.to_u16()),
                        alpha: None,
                    },
                )
            }))
            .chain(self.lighting_jobs(out))
            .collect();
        let mut dirs = vec!["water", "survey", "truth/albedo"];
        if !self.factor.is_empty() {
            dirs.extend(["truth/lit", "truth/backscatter"]);
        }
        for dir in dirs {
            let d = out.join(dir);
            std::fs::create_dir_all(&d).map_err(|e| Error::io(&d, e))?;
        }
        // The camera's photos declare their curve, as a camera's files do (PNG `sRGB` chunk, or `gAMA` 1.0 for a
        // linear camera; a power law as its `gAMA`), so `correct --transfer auto` reads it; truth files are plain.
        let declared = crate::io::metadata::Metadata {
            png_chunks: vec![match self.truth.settings.encode {
                Transfer::Srgb => (*b"sRGB", vec![0]),
                Transfer::Linear => (*b"gAMA", 100_000u32.to_be_bytes().to_vec()),
                Transfer::Gamma(g) => (
                    *b"gAMA",
                    ((100_000.0 / g).round() as u32).to_be_bytes().to_vec(),
                ),
            }],
            ..Default::default()
        };
        let camera = [out.join("water"), out.join("survey")];
        jobs.par_iter().try_for_each(|(path, photo)| {
            if camera.iter().any(|d| path.starts_with(d)) {
                crate::io::write_atomic_with_metadata(photo, path, settings, &declared).map(|_| ())
            } else {
                write_atomic(photo, path, settings)
            }
        })?;
        let json = out.join("truth").join("dive.json");
        crate::io::write_with(&json, |w| {
            serde_json::to_writer_pretty(w, &self.truth).map_err(|e| Error::Encode {
                path: json.clone(),
                reason: e.to_string(),
            })
        })?;
        let placements = out.join("truth").join("placements.txt");
        let text = crate::eval::evaluate::placements_text(
            self.truth
                .poses
                .iter()
                .map(|p| (p.file.as_str(), &p.homography)),
        );
        crate::io::write_with(&placements, |w| {
            use std::io::Write;
            w.write_all(text.as_bytes())
                .map_err(|e| Error::io(&placements, e))
        })?;
        // What the vehicle logs: each photo's altitude above the floor (the camera centre's height), in metres.
        let nav = out.join("navigation.csv");
        let mut text = String::from("file,altitude\n");
        for p in &self.truth.poses {
            text += &format!("{},{:.3}\n", p.file, p.position[2]);
        }
        crate::io::write_with(&nav, |w| {
            use std::io::Write;
            w.write_all(text.as_bytes()).map_err(|e| Error::io(&nav, e))
        })?;
        Ok(())
    }
}

/// Read `truth/dive.json`.
pub(crate) fn load_truth(path: &Path) -> Result<Truth> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| Error::Config {
        path: path.to_owned(),
        reason: format!("not a simulator truth file: {e}"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn homography_maps_pixels_to_the_floor_point_the_ray_hits() {
        let sim = Simulation {
            width: 64,
            height: 48,
            ..Simulation::default()
        };
        let cam = sim.camera();
        let r = rotation(4.0, -3.0, 10.0);
        let c = [1.0, 2.0, 3.0];
        let h = pixel_to_floor(&cam, &r, c);
        for (u, v) in [(0.0, 0.0), (63.0, 10.0), (32.0, 24.0), (5.0, 47.0)] {
            let d = [(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0];
            let w: Vec<f64> = (0..3)
                .map(|i| r[i * 3] * d[0] + r[i * 3 + 1] * d[1] + r[i * 3 + 2] * d[2])
                .collect();
            let t = -c[2] / w[2];
            let (x, y) = apply_h(&h, u, v);
            assert!((x - (c[0] + t * w[0])).abs() < 1e-9, "{u},{v}");
            assert!((y - (c[1] + t * w[1])).abs() < 1e-9, "{u},{v}");
        }
    }

    #[test]
    fn nodule_coverage_matches_the_contamination() {
        for c in [0.1, 0.2, 0.4] {
            let f = Floor::new(3, c);
            let n = 300;
            let mut dark = 0;
            for i in 0..n {
                for j in 0..n {
                    let a = f.albedo(i as f32 * 0.0137, j as f32 * 0.0131);
                    dark += (a[1] < 0.15) as usize;
                }
            }
            let share = dark as f64 / (n * n) as f64;
            assert!((share - c).abs() < 0.05, "contamination {c}: {share}");
        }
    }

    #[test]
    fn coverage_along_the_track_follows_the_profile() {
        // Bare at the start, 45 % in the middle, 15 % at the end of a 30 m track: the share of dark samples over
        // a 3 m stretch at each end and around the middle (the floor's patchiness is a factor of mean 1 over a
        // few metres, so a stretch of 3 m along and 40 m across reads the coverage within a few per cent).
        let mut f = Floor::new(5, 0.2);
        f.along = Some(([0.0, 0.45, 0.15], 30.0));
        let share = |y0: f32| {
            let n = 200;
            let mut dark = 0;
            for i in 0..n {
                for j in 0..n {
                    let a = f.albedo(i as f32 * 0.2013, y0 + j as f32 * 0.0149);
                    dark += (a[1] < 0.15) as usize;
                }
            }
            dark as f64 / (n * n) as f64
        };
        let (start, middle, end) = (share(0.0), share(13.5), share(27.0));
        assert!(start < 0.06, "start {start}");
        assert!((middle - 0.45).abs() < 0.08, "middle {middle}");
        assert!((end - 0.17).abs() < 0.06, "end {end}");
    }

    #[test]
    fn particle_cover_does_not_grow_with_the_resolution() {
        // The share of a frame that particles cover, at 320×240 and at twice and four times that: the same seed
        // puts the same particles at the same place in the frame, scaled, so the shares agree closely (with the
        // count growing with the pixel count too they were 4× and 16× apart).
        let cover = |w: usize, h: usize| {
            let mut img = Raster::filled(w, h, 3, 0.0);
            add_particles(&mut img, &mut Rng(mix(7)), particle_count(w, h));
            img.data
                .iter()
                .skip(1)
                .step_by(3)
                .filter(|&&v| v > 0.01)
                .count() as f64
                / (w * h) as f64
        };
        let base = cover(320, 240);
        assert!(base > 0.002, "particles cover {base} of the frame");
        for (w, h) in [(640, 480), (1280, 960)] {
            let r = cover(w, h) / base;
            assert!(
                (0.85..1.15).contains(&r),
                "{w}x{h}: cover {r}× that of 320x240"
            );
        }
        // Below 320 pixels across nothing changed: one per 2500 pixels, at least 3.
        assert_eq!(particle_count(320, 240), 30);
        assert_eq!(particle_count(96, 64), 3);
        assert_eq!(particle_count(200, 150), 12);
    }

    #[test]
    fn invert3_inverts() {
        let m = [2.0, 1.0, 0.0, 0.5, 3.0, 1.0, 0.0, 0.2, 1.0];
        let inv = invert3(&m).unwrap();
        let id = mat_mul(&m, &inv);
        for (i, v) in id.iter().enumerate() {
            let e = if i % 4 == 0 { 1.0 } else { 0.0 };
            assert!((v - e).abs() < 1e-12);
        }
    }
}
