//! `abysslight bench`: a self-contained benchmark of a whole `correct` run against the codec floor.
//!
//! It generates a synthetic mission (lit seafloor texture under a light cone, plus backscatter, saved as camera-like
//! JPEGs) in a temporary folder, then measures in one run on the same machine:
//!
//! - photos per second of `correct` over the long mission (whole run: scatter estimation, medians, correction,
//!   encoding, atomic writes);
//! - photos per second of decode + encode alone (the same photos, threads, writer and settings): the floor any
//!   corrector pays;
//! - their ratio;
//! - the size of `correct`'s JPEG outputs against that of its inputs (outputs follow their inputs' quality and
//!   subsampling by default);
//! - with the `turbojpeg` feature, libjpeg-turbo decode + encode in memory alone (no writer, no metadata): the
//!   best codec on the machine;
//! - peak memory (VmHWM) of a short and of a 10× longer mission, each `correct` run in a child process of the same
//!   binary, so the two peaks are separate.
//!
//! Speed targets live here, never in timed unit tests.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::io::{self, EncodeSettings};
use crate::method::raster::{Layout, Photo, Samples};
use crate::report::Silent;
use crate::run::options::Options;
use crate::run::source::Sink;

/// What to benchmark.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Photo width in pixels (default 4000).
    pub width: usize,
    /// Photo height in pixels (default 3000).
    pub height: usize,
    /// Survey photos of the short mission; the long one has `long_factor` times as many.
    pub photos: usize,
    /// How many times more photos the long mission has than the short one (default 10).
    pub long_factor: usize,
    /// Distinct synthetic photos generated: 0 (the default), every survey photo of the mission; fewer, and the
    /// mission cycles forth and back through them as hard links (quicker to make, but a survey reads the repeats
    /// as a camera standing still, which changes what the default `--window auto` does).
    pub distinct: usize,
    /// Water-column photos generated for the estimate of `S` (default 9).
    pub water_column: usize,
    /// Sensor noise added to every photo before it is saved, standard deviation in 8-bit levels (default 3: dark
    /// abyssal photos are noisy, and the noise-aware blend of the default method runs on them).
    pub noise: f32,
    /// JPEG quality of the generated mission (default 92; 4:2:0 always, like a camera's).
    pub quality: u8,
    /// A Python with OpenCV (`cv2`) for the libjpeg-turbo floor (default `python3`); the line is left out, with
    /// the reason, where it has no `cv2`.
    pub python: PathBuf,
    /// A peer implementation to time on the same mission, run as `PYTHON PEER paper WATER SURVEY OUT`.
    pub peer: Option<PathBuf>,
    /// Worker threads of `correct` and of the codec floor (default 2).
    pub threads: usize,
    /// Sliding-window length `n` in photos passed to `correct` (and to the peer); `None` (the default): none,
    /// so `correct` runs with its default window (`auto`) and the peer with its own.
    pub window: Option<usize>,
    /// JPEG output quality; `None`: each input's (the default of `correct`).
    pub jpeg_quality: Option<u8>,
    /// JPEG output subsampling; `None`: each input's.
    pub jpeg_subsampling: Option<io::Subsampling>,
    /// Where the mission is generated (default: a temporary folder, removed afterwards).
    pub dir: Option<PathBuf>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            width: 4000,
            height: 3000,
            photos: 60,
            long_factor: 1,
            distinct: 0,
            water_column: 9,
            noise: 3.0,
            quality: 92,
            python: PathBuf::from("python3"),
            peer: None,
            threads: 2,
            window: None,
            jpeg_quality: None,
            jpeg_subsampling: None,
            dir: None,
        }
    }
}

/// What one child `correct` run measured.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct ChildResult {
    /// Survey photos the run corrected (its report's `corrected`).
    pub photos: usize,
    /// Wall-clock seconds of the whole run.
    pub seconds: f64,
    /// Peak resident memory (VmHWM) of the child process, in KiB.
    pub peak_kib: u64,
}

/// The whole benchmark's result.
#[derive(Debug, Clone, Serialize)]
pub struct BenchResult {
    /// CPU model name of the machine.
    pub machine: String,
    /// Logical cores available.
    pub cores: usize,
    /// `rustc --version` output.
    pub rustc: String,
    /// Photo width in pixels.
    pub width: usize,
    /// Photo height in pixels.
    pub height: usize,
    /// Worker threads used.
    pub threads: usize,
    /// Sensor noise of the generated photos (standard deviation, 8-bit levels).
    pub noise: f32,
    /// JPEG quality of the generated photos.
    pub quality: u8,
    /// Water-column frames of the mission.
    pub water_column: usize,
    /// Seconds spent generating the synthetic mission.
    pub generate_s: f64,
    /// The short mission's `correct` run (only with a long factor above 1: its peak memory beside the long one's).
    pub short: Option<ChildResult>,
    /// The mission's `correct` run (the headline figure).
    pub long: ChildResult,
    /// Decode + encode with abysslight's own codec and writer.
    pub codec: CodecFloors,
    /// The libjpeg-turbo floor measured through OpenCV, or why it was not.
    pub opencv_floor: std::result::Result<OpencvFloor, String>,
    /// Wall-clock seconds of the peer on the same mission.
    pub peer_s: Option<f64>,
}

impl BenchResult {
    /// Photos per second of `correct` over the mission.
    pub fn correct_rate(&self) -> f64 {
        self.long.photos as f64 / self.long.seconds
    }
    /// Photos per second of the codec floor (decode + encode of the inputs).
    pub fn floor_rate(&self) -> f64 {
        self.codec.photos as f64 / self.codec.floor_s
    }
    /// Photos per second of decode + encode of `correct`'s own outputs.
    pub fn outputs_floor_rate(&self) -> f64 {
        self.long.photos as f64 / self.codec.outputs_floor_s
    }
    /// The libjpeg-turbo floor's seconds on `threads` cores with perfect parallelism (one thread's ÷ threads).
    pub fn opencv_floor_s(&self) -> Option<f64> {
        let f = self.opencv_floor.as_ref().ok()?;
        Some((f.decode_s + f.encode_s) / self.threads.max(1) as f64)
    }
    /// The table printed at the end (Markdown).
    pub fn table(&self) -> String {
        let mut s = format!(
            "machine: {} ({} cores), {}\n",
            self.machine, self.cores, self.rustc
        );
        s += &format!(
            "mission: {} + {} water-column {}x{} RGB JPEGs (quality {}, 4:2:0, sensor noise {} levels), {} threads \
             (generated in {:.1} s)\nJPEG codec: {}\n\n| measure | value |\n|---|---|\n",
            self.long.photos,
            self.water_column,
            self.width,
            self.height,
            self.quality,
            self.noise,
            self.threads,
            self.generate_s,
            self.codec.codec
        );
        s += &format!(
            "| correct ({} photos) | {:.2} s, {:.2} photos/s |\n",
            self.long.photos,
            self.long.seconds,
            self.correct_rate()
        );
        s += &self.against_floors();
        s += &self.sizes_and_memory();
        s
    }

    fn against_floors(&self) -> String {
        let mut s = String::new();
        match (&self.opencv_floor, self.opencv_floor_s()) {
            (Ok(f), Some(t)) => {
                s += &format!(
                    "| libjpeg-turbo floor (OpenCV, one thread: decode {} inputs {:.2} s + encode {} outputs \
                     {:.2} s; ÷ {}) | {:.2} s |\n",
                    f.inputs, f.decode_s, f.outputs, f.encode_s, self.threads, t
                );
                s += &format!(
                    "| **correct / libjpeg-turbo floor (time)** | **{:.2}×** |\n",
                    self.long.seconds / t
                );
            }
            (Err(why), _) => {
                s += &format!("| libjpeg-turbo floor (OpenCV) | not measured: {why} |\n")
            }
            (Ok(_), None) => {}
        }
        if let Some(p) = self.peer_s {
            s += &format!(
                "| peer ({} photos) | {:.2} s; **correct's throughput / the peer's: {:.2}×** |\n",
                self.long.photos,
                p,
                p / self.long.seconds
            );
        }
        s += &format!(
            "| abysslight's decode + encode ({} photos) | {:.2} photos/s; correct / that (rate) {:.3} |\n",
            self.codec.photos,
            self.floor_rate(),
            self.correct_rate() / self.floor_rate()
        );
        s += &format!(
            "| abysslight's decode + encode of correct's outputs | {:.2} photos/s; correct / that (rate) {:.3} |\n",
            self.outputs_floor_rate(),
            self.correct_rate() / self.outputs_floor_rate()
        );
        if let Some(t) = self.codec.turbo_floor_s {
            let rate = self.codec.photos as f64 / t;
            s += &format!(
                "| libjpeg-turbo decode + encode in memory, {} threads | {:.2} photos/s; correct / that (rate) {:.3} |\n",
                self.threads,
                rate,
                self.correct_rate() / rate
            );
        }
        s
    }

    fn sizes_and_memory(&self) -> String {
        let mib = |k: u64| k as f64 / 1024.0;
        let c = &self.codec;
        let mut s = format!(
            "| output / input size ({} JPEGs) | {:.2} ({:.1} / {:.1} MB) |\n",
            self.long.photos,
            c.output_bytes as f64 / c.input_bytes.max(1) as f64,
            c.output_bytes as f64 / 1e6,
            c.input_bytes as f64 / 1e6
        );
        if let Some(short) = &self.short {
            s += &format!(
                "| peak memory, {} photos | {:.0} MiB |\n",
                short.photos,
                mib(short.peak_kib)
            );
        }
        s += &format!(
            "| peak memory, {} photos | {:.0} MiB |\n",
            self.long.photos,
            mib(self.long.peak_kib)
        );
        s
    }
}

/// Peak resident memory of this process in KiB (`VmHWM`), or 0 where `/proc` is not available.
pub fn peak_memory_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse().ok())
        })
        .unwrap_or(0)
}

/// The machine a benchmark ran on: CPU model, cores available, `rustc -V`.
pub fn machine() -> (String, usize, String) {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.into());
    let cores = std::thread::available_parallelism().map_or(1, |p| p.get());
    let rustc = Command::new("rustc")
        .arg("-V")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|| "rustc unknown".into());
    (cpu, cores, rustc)
}

/// A small, fast hash of three integers to `[0, 1)`.
#[inline]
fn hash(x: u32, y: u32, z: u32) -> f32 {
    let mut h = x
        .wrapping_mul(0x8da6_b343)
        .wrapping_add(y.wrapping_mul(0xd816_3841))
        .wrapping_add(z.wrapping_mul(0xcb1a_b31f));
    h ^= h >> 15;
    h = h.wrapping_mul(0x2c1b_3c6d);
    h ^= h >> 12;
    (h >> 8) as f32 / (1u32 << 24) as f32
}

/// Smooth value noise at cell size `cell`.
#[inline]
fn value_noise(x: f32, y: f32, cell: f32, seed: u32) -> f32 {
    let (gx, gy) = (x / cell, y / cell);
    let (ix, iy) = (gx.floor(), gy.floor());
    let (fx, fy) = (gx - ix, gy - iy);
    let (ix, iy) = (ix as i32 as u32, iy as i32 as u32);
    let a = hash(ix, iy, seed);
    let b = hash(ix + 1, iy, seed);
    let c = hash(ix, iy + 1, seed);
    let d = hash(ix + 1, iy + 1, seed);
    let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
    let top = a + (b - a) * sx;
    let bottom = c + (d - c) * sx;
    top + (bottom - top) * sy
}

/// Backscatter of the synthetic rig: brighter near the top, bluish.
#[inline]
fn backscatter(y: usize, h: usize, c: usize) -> f32 {
    let up = 1.0 - y as f32 / h as f32;
    [0.03, 0.05, 0.07][c] * (0.5 + up)
}

/// A synthetic survey photo number `j`: seafloor texture moving past under a light cone, plus backscatter, plus
/// an occasional bright object (a fish) that the median has to ignore, and a little uniform noise (±1 %).
pub fn synthetic_photo(width: usize, height: usize, j: usize, water_column: bool) -> Photo {
    noisy_photo(width, height, j, water_column, None)
}

/// Noise of sample `c` of pixel (`x`, `y`) of photo `j`, in `[0, 1]` units: uniform ±1 % (`sigma: None`), or
/// of standard deviation `sigma` 8-bit levels (the sum of three uniform variates: close to a Gaussian's shape).
#[inline]
fn noise_at(x: usize, y: usize, c: usize, j: usize, sigma: Option<f32>) -> f32 {
    let h = |k: u32| hash(x as u32, y as u32, k + 11 + c as u32 + 3 * j as u32);
    match sigma {
        None => (h(0) - 0.5) * 0.02,
        // Each uniform variate has variance 1/12: three have 1/4, so twice their centred sum has variance 1.
        Some(s) => (h(0) + h(1 << 20) + h(2 << 20) - 1.5) * 2.0 * s / 255.0,
    }
}

/// [`synthetic_photo`] with sensor noise of standard deviation `sigma` 8-bit levels instead of ±1 %.
pub fn noisy_photo(
    width: usize,
    height: usize,
    j: usize,
    water_column: bool,
    sigma: Option<f32>,
) -> Photo {
    let look = Look::new(width, height, j, water_column, sigma);
    let shift = look.shift as f32;
    let mut data = vec![0u8; width * height * 3];
    data.par_chunks_mut(width * 3)
        .enumerate()
        .for_each(|(y, row)| {
            look.row(
                row,
                y,
                |x| light_at(x, y, width, height),
                |x| texture_at(x as f32 + shift, y as f32, sigma),
            )
        });
    rgb8_photo(width, height, data)
}

fn rgb8_photo(width: usize, height: usize, data: Vec<u8>) -> Photo {
    Photo {
        layout: Layout {
            width,
            height,
            channels: 3,
        },
        samples: Samples::U8(data),
        alpha: None,
    }
}

/// The light cone's factor at pixel (`x`, `y`) of a `width`×`height` photo.
#[inline]
fn light_at(x: usize, y: usize, width: usize, height: usize) -> f32 {
    let (cx, cy) = (width as f32 * 0.5, height as f32 * 0.58);
    let sigma2 = 2.0 * (0.38 * width as f32).powi(2);
    let r2 = (x as f32 - cx).powi(2) + (y as f32 - cy).powi(2);
    0.1 + 0.9 * (-r2 / sigma2).exp()
}

/// The seafloor's texture at (`sx`, `sy`) of the seafloor (a photo's column plus the photo's shift, its row).
#[inline]
fn texture_at(sx: f32, sy: f32, sigma: Option<f32>) -> f32 {
    let coarse = value_noise(sx, sy, 180.0, 1);
    let mid = value_noise(sx, sy, 23.0, 2);
    // With sensor noise, the finest texture a few pixels across (white grain would be read as noise by nothing
    // but its scaling with the light).
    let grain = match sigma {
        None => hash(sx as u32, sy as u32, 3),
        Some(_) => value_noise(sx, sy, 3.0, 3),
    };
    0.45 + 0.5 * coarse + 0.35 * mid + 0.2 * grain
}

/// What makes photo `j` itself: where the seafloor is (shifted by a ninth of the width a photo), where its fish
/// swims, its noise.
struct Look {
    width: usize,
    height: usize,
    j: usize,
    water_column: bool,
    sigma: Option<f32>,
    shift: usize,
    fish: (f32, f32),
}

impl Look {
    fn new(width: usize, height: usize, j: usize, water_column: bool, sigma: Option<f32>) -> Self {
        Look {
            width,
            height,
            j,
            water_column,
            sigma,
            shift: j * width / 9,
            fish: (
                (hash(j as u32, 1, 7) * width as f32),
                (hash(j as u32, 2, 7) * height as f32),
            ),
        }
    }

    /// Row `y` of the photo into `row` (RGB), given the light cone's factor and the texture at each column.
    #[inline(always)]
    fn row(
        &self,
        row: &mut [u8],
        y: usize,
        light: impl Fn(usize) -> f32,
        tex: impl Fn(usize) -> f32,
    ) {
        let colour = [0.45f32, 0.40, 0.32];
        let (width, yf) = (self.width, y as f32);
        for x in 0..width {
            let xf = x as f32;
            let f = light(x);
            let tex = if self.water_column { 0.0 } else { tex(x) };
            let in_fish = !self.water_column
                && (xf - self.fish.0).powi(2) + 4.0 * (yf - self.fish.1).powi(2)
                    < (0.04 * width as f32).powi(2);
            for c in 0..3 {
                let s = backscatter(y, self.height, c);
                let noise = noise_at(x, y, c, self.j, self.sigma);
                let a = if in_fish { 0.95 } else { colour[c] * tex };
                let v = if self.water_column {
                    s + noise
                } else {
                    a * f + s + noise
                };
                row[x * 3 + c] = (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
            }
        }
    }
}

/// Survey photos of [`noisy_photo`] made one after the other, cheaper than one by one: the light cone's factor
/// computed once, and the seafloor's texture of each column once (held for the columns of the last photo, so a
/// photo computes only the columns it has that the one before did not: a ninth). The same photos, bit for bit.
struct Frames {
    width: usize,
    height: usize,
    sigma: Option<f32>,
    light: Vec<f32>,
    /// The texture of seafloor column `X` at `tex[y·width + X mod width]`, for `X` in `held`.
    tex: Vec<f32>,
    held: std::ops::Range<usize>,
}

impl Frames {
    fn new(width: usize, height: usize, sigma: Option<f32>) -> Self {
        let mut light = vec![0.0f32; width * height];
        light
            .par_chunks_mut(width.max(1))
            .enumerate()
            .for_each(|(y, row)| {
                for (x, l) in row.iter_mut().enumerate() {
                    *l = light_at(x, y, width, height);
                }
            });
        Frames {
            width,
            height,
            sigma,
            light,
            tex: vec![0.0; width * height],
            held: 0..0,
        }
    }

    /// Survey photo `j` (`noisy_photo(width, height, j, false, sigma)`).
    fn photo(&mut self, j: usize) -> Photo {
        let (w, h) = (self.width, self.height);
        let look = Look::new(w, h, j, false, self.sigma);
        let want = look.shift..look.shift + w;
        if want.end > 1 << 24 {
            // Columns past f32's integers: the texture's column is rounded as `noisy_photo` rounds it.
            return noisy_photo(w, h, j, false, self.sigma);
        }
        let new = if want.start >= self.held.start && want.start <= self.held.end {
            self.held.end..want.end
        } else {
            want.clone()
        };
        let sigma = self.sigma;
        self.tex.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for sx in new.clone() {
                row[sx % w] = texture_at(sx as f32, y as f32, sigma);
            }
        });
        self.held = want;
        let (light, tex) = (&self.light, &self.tex);
        let mut data = vec![0u8; w * h * 3];
        data.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
            let (l, t) = (&light[y * w..(y + 1) * w], &tex[y * w..(y + 1) * w]);
            let s0 = look.shift % w;
            look.row(
                row,
                y,
                |x| l[x],
                |x| t[if s0 + x < w { s0 + x } else { s0 + x - w }],
            );
        });
        rgb8_photo(w, h, data)
    }
}

/// Camera-like JPEG: 4:2:0 (as most survey cameras write them) at `quality`.
fn save_camera_jpeg(photo: &Photo, path: &Path, quality: u8) -> Result<()> {
    let Samples::U8(d) = &photo.samples else {
        unreachable!("synthetic photos are 8-bit")
    };
    let l = photo.layout;
    let enc_err = |e: String| Error::Encode {
        path: path.to_owned(),
        reason: e,
    };
    let buf = libjpeg_turbo_rs::compress(
        d,
        l.width,
        l.height,
        libjpeg_turbo_rs::PixelFormat::Rgb,
        quality,
        libjpeg_turbo_rs::Subsampling::S420,
    )
    .map_err(|e| enc_err(e.to_string()))?;
    crate::io::write_with(path, |w| {
        std::io::Write::write_all(w, &buf).map_err(|e| Error::io(path, e))
    })
}

/// The generated mission: water-column frames and the distinct survey photos.
struct Mission {
    water_column: PathBuf,
    distinct: Vec<PathBuf>,
}

/// Generate the water-column frames and `distinct` survey photos (photos `0, 1, …` of [`noisy_photo`], each
/// the last shifted by a ninth of the width).
fn generate(o: &BenchOptions, root: &Path, distinct: usize) -> Result<Mission> {
    let wc = root.join("water-column");
    let pool = root.join("distinct");
    for d in [&wc, &pool] {
        std::fs::create_dir_all(d).map_err(|e| Error::io(d, e))?;
    }
    let sigma = (o.noise > 0.0).then_some(o.noise);
    for j in 0..o.water_column {
        // Noise seeds apart from the survey photos'.
        let p = noisy_photo(o.width, o.height, 1000 + j, true, sigma);
        save_camera_jpeg(&p, &wc.join(format!("wc{j:03}.jpg")), o.quality)?;
    }
    let mut frames = Frames::new(o.width, o.height, sigma);
    let mut paths = Vec::new();
    for j in 0..distinct.max(1) {
        let path = pool.join(format!("d{j:05}.jpg"));
        save_camera_jpeg(&frames.photo(j), &path, o.quality)?;
        paths.push(path);
    }
    Ok(Mission {
        water_column: wc,
        distinct: paths,
    })
}

/// A survey folder of `count` photos (hard links, copies where links fail): the distinct photos in order, or,
/// where there are fewer, forth and back through them. Photos of an earlier, longer mission in `dir` go.
fn survey_folder(m: &Mission, dir: &Path, count: usize) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let name = |i: usize| dir.join(format!("img{i:05}.jpg"));
    for i in count.. {
        match std::fs::remove_file(name(i)) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => break,
            Err(e) => return Err(Error::io(name(i), e)),
            Ok(()) => {}
        }
    }
    for i in 0..count {
        // Forth and back through the distinct photos, so neighbours stay neighbours.
        let period = 2 * m.distinct.len().max(2) - 2;
        let p = i % period.max(1);
        let j = if p < m.distinct.len() { p } else { period - p };
        let src = &m.distinct[j.min(m.distinct.len() - 1)];
        let dst = name(i);
        // A folder left by an earlier `--dir` run: its entries may be links to `src` itself, and copying a file
        // onto itself empties it. Start from a clean name.
        match std::fs::remove_file(&dst) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(Error::io(&dst, e)),
            _ => {}
        }
        if std::fs::hard_link(src, &dst).is_err() {
            std::fs::copy(src, &dst).map_err(|e| Error::io(&dst, e))?;
        }
    }
    Ok(())
}

/// Decode + encode every photo of `survey` into `out` with `threads` threads, the way `correct` reads and writes
/// them (same decoder, writer and settings). Returns seconds.
pub fn floor(
    survey: &Path,
    out: &Path,
    threads: usize,
    settings: EncodeSettings,
) -> Result<(usize, f64)> {
    let (n, secs, failed) = on_every_photo(survey, threads, |e| {
        io::decode(&e.path)
            .and_then(|p| {
                Sink::Folder {
                    carry_metadata: true,
                }
                .write(&p, &e.path, &out.join(&e.relative), settings, &|_| {})
            })
            .is_ok()
    })?;
    if failed {
        return Err(Error::Usage("bench: decode + encode failed".into()));
    }
    Ok((n, secs))
}

/// Run `work` on every photo of `survey` on `threads` threads, each taking the next photo not yet taken. Returns
/// the number of photos, the seconds it took, and whether `work` failed (returned false) on any.
fn on_every_photo(
    survey: &Path,
    threads: usize,
    work: impl Fn(&io::Entry) -> bool + Sync,
) -> Result<(usize, f64, bool)> {
    let found = io::find_photos(survey)?;
    let next = AtomicUsize::new(0);
    let failed = AtomicUsize::new(0);
    let t = Instant::now();
    std::thread::scope(|s| {
        for _ in 0..threads.max(1) {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::SeqCst);
                let Some(e) = found.photos.get(i) else { break };
                if !work(e) {
                    failed.fetch_add(1, Ordering::SeqCst);
                }
            });
        }
    });
    Ok((
        found.photos.len(),
        t.elapsed().as_secs_f64(),
        failed.load(Ordering::SeqCst) > 0,
    ))
}

/// The child side: run `correct` on one mission and print a [`ChildResult`] line on stdout.
pub fn child(
    water_column: &Path,
    survey: &Path,
    out: &Path,
    threads: usize,
    window: Option<usize>,
    jpeg_quality: Option<u8>,
    jpeg_subsampling: Option<io::Subsampling>,
) -> Result<ChildResult> {
    let opts = Options {
        water_column: Some(water_column.to_owned()),
        survey: Some(survey.to_owned()),
        out: Some(out.to_owned()),
        threads: Some(threads),
        window,
        jpeg_quality,
        jpeg_subsampling,
        ..Options::default()
    };
    let t = Instant::now();
    let report = crate::correct_mission(&opts, &Silent)?;
    let seconds = t.elapsed().as_secs_f64();
    if !report.all_ok() {
        return Err(Error::Usage(format!(
            "bench: {} photo(s) failed",
            report.failed + report.water_column_failed
        )));
    }
    Ok(ChildResult {
        photos: report.corrected,
        seconds,
        peak_kib: peak_memory_kib(),
    })
}

/// Prefix of the line a child prints.
pub const CHILD_LINE: &str = "abysslight-bench-child ";

fn run_child(
    exe: &Path,
    o: &BenchOptions,
    wc: &Path,
    survey: &Path,
    out: &Path,
) -> Result<ChildResult> {
    let mut cmd = Command::new(exe);
    cmd.arg("bench");
    if let Some(q) = o.jpeg_quality {
        cmd.arg("--jpeg-quality").arg(q.to_string());
    }
    if let Some(s) = o.jpeg_subsampling {
        cmd.arg("--jpeg-subsampling").arg(s.name());
    }
    if let Some(n) = o.window {
        cmd.arg("--window").arg(n.to_string());
    }
    let output = cmd
        .arg("--child")
        .arg("--child-water-column")
        .arg(wc)
        .arg("--child-survey")
        .arg(survey)
        .arg("--child-out")
        .arg(out)
        .arg("--threads")
        .arg(o.threads.to_string())
        .output()
        .map_err(|e| Error::io(exe, e))?;
    let stdout = String::from_utf8_lossy(&output.stdout);
    stdout
        .lines()
        .find_map(|l| l.strip_prefix(CHILD_LINE))
        .and_then(|j| serde_json::from_str(j).ok())
        .ok_or_else(|| {
            Error::Usage(format!(
                "bench: child run failed: {}",
                String::from_utf8_lossy(&output.stderr).trim()
            ))
        })
}

/// Run the whole benchmark; `exe` is the `abysslight` binary (children run `exe bench --child ...`).
/// `say` hears progress lines.
pub fn run(exe: &Path, o: &BenchOptions, say: &dyn Fn(&str)) -> Result<BenchResult> {
    if o.width > u16::MAX as usize || o.height > u16::MAX as usize || o.photos == 0 {
        return Err(Error::Usage(
            "bench: size must fit a JPEG and --photos be at least 1".into(),
        ));
    }
    let tmp;
    let root = match &o.dir {
        Some(d) => d.clone(),
        None => {
            tmp = tempfile::Builder::new()
                .prefix("abysslight-bench.")
                .tempdir()
                .map_err(|e| Error::io(Path::new("tempdir"), e))?;
            tmp.path().to_owned()
        }
    };
    let (machine, cores, rustc) = machine();
    let total = o.photos * o.long_factor.max(1);
    let distinct = if o.distinct == 0 { total } else { o.distinct };
    say(&format!(
        "generating {} distinct {}x{} photos and {} water-column frames in {}",
        distinct,
        o.width,
        o.height,
        o.water_column,
        root.display()
    ));
    let t = Instant::now();
    let mission = generate(o, &root, distinct)?;
    let survey = root.join("survey");
    survey_folder(&mission, &survey, total)?;
    let generate_s = t.elapsed().as_secs_f64();
    let wc = &mission.water_column;
    let short = (o.long_factor > 1)
        .then(|| {
            say(&format!("correct, short mission ({} photos)", o.photos));
            let short_dir = root.join("survey-short");
            survey_folder(&mission, &short_dir, o.photos)?;
            let r = run_child(exe, o, wc, &short_dir, &root.join("out-short"));
            remove(&root.join("out-short"));
            r
        })
        .transpose()?;
    say(&format!(
        "correct ({total} photos, {})",
        o.window
            .map_or("default options".into(), |n| format!("--window {n}"))
    ));
    let out = root.join("out");
    let long = run_child(exe, o, wc, &survey, &out)?;
    let opencv_floor = opencv_floor(o, &[wc, &survey], &out, say);
    let codec = codec_floors(o, &survey, &out, &root, say)?;
    let peer_s = match &o.peer {
        Some(p) => Some(run_peer(o, p, wc, &survey, &root, say)?),
        None => None,
    };
    remove(&out);
    Ok(BenchResult {
        machine,
        cores,
        rustc,
        width: o.width,
        height: o.height,
        threads: o.threads,
        noise: o.noise,
        quality: o.quality,
        water_column: o.water_column,
        generate_s,
        short,
        long,
        codec,
        opencv_floor,
        peer_s,
    })
}

/// What the codec alone costs on the mission, through abysslight's own decoder and writer.
#[derive(Debug, Clone, Serialize)]
pub struct CodecFloors {
    /// Photos decoded and re-encoded for the floor (the mission's survey photos).
    pub photos: usize,
    /// Seconds of decode + encode of `photos` with the same threads, decoder, writer and settings as `correct`.
    pub floor_s: f64,
    /// Seconds of decode + encode of `correct`'s own outputs (same threads and settings): what the codec alone
    /// costs on corrected content, which encodes larger (flattened light, brightened corners) than the input.
    pub outputs_floor_s: f64,
    /// The JPEG codec built in.
    pub codec: String,
    /// Bytes of the survey photos.
    pub input_bytes: u64,
    /// Bytes of `correct`'s outputs of them.
    pub output_bytes: u64,
    /// Seconds of libjpeg-turbo decode + encode in memory (`turbojpeg` feature only).
    pub turbo_floor_s: Option<f64>,
}

/// Decode + encode of the inputs and of `correct`'s outputs (in `out`) with abysslight's own codec and writer.
fn codec_floors(
    o: &BenchOptions,
    survey: &Path,
    out: &Path,
    root: &Path,
    say: &dyn Fn(&str),
) -> Result<CodecFloors> {
    let settings = Options {
        jpeg_quality: o.jpeg_quality,
        jpeg_subsampling: o.jpeg_subsampling,
        ..Options::default()
    }
    .encode_settings();
    let scratch = root.join("out-floor");
    say("decode + encode of correct's outputs");
    let (_, outputs_floor_s) = floor(out, &scratch, o.threads, settings)?;
    remove(&scratch);
    say("floor: decode + encode of the survey photos");
    let (photos, floor_s) = floor(survey, &scratch, o.threads, settings)?;
    remove(&scratch);
    #[cfg(feature = "turbojpeg")]
    let turbo_floor_s = {
        say("libjpeg-turbo decode + encode in memory of the survey photos");
        Some(turbo_floor(survey, o.threads, settings)?)
    };
    #[cfg(not(feature = "turbojpeg"))]
    let turbo_floor_s = None;
    Ok(CodecFloors {
        photos,
        floor_s,
        outputs_floor_s,
        codec: crate::io::jpeg::codec_name().into(),
        input_bytes: photo_bytes(survey)?,
        output_bytes: photo_bytes(out)?,
        turbo_floor_s,
    })
}

/// The libjpeg-turbo floor as OpenCV measures it: `cv2.imread` of every input, `cv2.imencode` of every corrected
/// output (decoded first, untimed) at the inputs' quality and 4:2:0, one thread. Prints the decode and encode
/// seconds and the counts.
const OPENCV_FLOOR: &str = r#"
import os, sys, time
import cv2
cv2.setNumThreads(1)
def photos(d):
    return sorted(os.path.join(r, f) for r, _, fs in os.walk(d) for f in fs if f.lower().endswith(".jpg"))
q, outs, ins = int(sys.argv[1]), sys.argv[2], sys.argv[3:]
dec = enc = 0.0
n_in = n_out = 0
for d in ins:
    for p in photos(d):
        t = time.perf_counter(); x = cv2.imread(p, cv2.IMREAD_UNCHANGED); dec += time.perf_counter() - t
        assert x is not None, p
        n_in += 1
params = [cv2.IMWRITE_JPEG_QUALITY, q, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420]
for p in photos(outs):
    x = cv2.imread(p, cv2.IMREAD_UNCHANGED)
    assert x is not None, p
    t = time.perf_counter(); ok, b = cv2.imencode(".jpg", x, params); enc += time.perf_counter() - t
    assert ok, p
    n_out += 1
print(dec, enc, n_in, n_out)
"#;

/// The libjpeg-turbo floor as OpenCV measures it ([`OPENCV_FLOOR`]), in seconds of one thread.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct OpencvFloor {
    /// Seconds of `cv2.imread` of every input (water-column frames and survey photos), one thread.
    pub decode_s: f64,
    /// Seconds of `cv2.imencode` of every corrected output, one thread.
    pub encode_s: f64,
    /// Inputs decoded.
    pub inputs: usize,
    /// Outputs encoded.
    pub outputs: usize,
}

/// Run [`OPENCV_FLOOR`] with `o.python` on `inputs` and the outputs in `out`; `Err` with the reason where that
/// Python has no OpenCV.
fn opencv_floor(
    o: &BenchOptions,
    inputs: &[&Path],
    out: &Path,
    say: &dyn Fn(&str),
) -> std::result::Result<OpencvFloor, String> {
    say(&format!(
        "libjpeg-turbo floor: OpenCV decode + encode, one thread ({})",
        o.python.display()
    ));
    let q = o.jpeg_quality.unwrap_or(o.quality).to_string();
    let r = Command::new(&o.python)
        .args(["-c", OPENCV_FLOOR, &q])
        .arg(out)
        .args(inputs)
        .output()
        .map_err(|e| format!("cannot run {}: {e}", o.python.display()))?;
    let text = String::from_utf8_lossy(&r.stdout);
    let v: Vec<f64> = text
        .split_whitespace()
        .filter_map(|t| t.parse().ok())
        .collect();
    match (r.status.success(), v.as_slice()) {
        (true, &[d, e, i, n]) => Ok(OpencvFloor {
            decode_s: d,
            encode_s: e,
            inputs: i as usize,
            outputs: n as usize,
        }),
        _ => Err(format!(
            "{} with OpenCV failed: {}",
            o.python.display(),
            String::from_utf8_lossy(&r.stderr)
                .lines()
                .last()
                .unwrap_or("")
        )),
    }
}

/// Wall-clock seconds of the peer on the same mission (`PYTHON PEER paper WATER SURVEY OUT`, and `--window N`
/// where the bench was given one).
fn run_peer(
    o: &BenchOptions,
    peer: &Path,
    wc: &Path,
    survey: &Path,
    root: &Path,
    say: &dyn Fn(&str),
) -> Result<f64> {
    say(&format!("peer: {} paper", peer.display()));
    let out = root.join("out-peer");
    let t = Instant::now();
    let mut cmd = Command::new(&o.python);
    cmd.arg(peer).arg("paper").args([wc, survey, &out]);
    if let Some(n) = o.window {
        cmd.args(["--window", &n.to_string()]);
    }
    let r = cmd.output().map_err(|e| Error::io(peer, e))?;
    let secs = t.elapsed().as_secs_f64();
    remove(&out);
    if !r.status.success() {
        return Err(Error::Usage(format!(
            "bench: the peer failed: {}",
            String::from_utf8_lossy(&r.stderr).trim()
        )));
    }
    Ok(secs)
}

/// Total bytes of the photos below `dir` (each name counted, hard links too).
fn photo_bytes(dir: &Path) -> Result<u64> {
    let mut n = 0;
    for e in io::find_photos(dir)?.photos {
        n += std::fs::metadata(&e.path)
            .map_err(|err| Error::io(&e.path, err))?
            .len();
    }
    Ok(n)
}

/// libjpeg-turbo alone: read, decode and encode (quality and subsampling like each input unless `settings` set
/// them) every photo of `survey` in memory, on `threads` threads. Seconds.
#[cfg(feature = "turbojpeg")]
pub fn turbo_floor(survey: &Path, threads: usize, settings: EncodeSettings) -> Result<f64> {
    let (_, secs, failed) = on_every_photo(survey, threads, |e| {
        std::fs::read(&e.path)
            .ok()
            .and_then(|data| {
                let st = settings.like(crate::io::jpeg::parse(&data).as_ref());
                let (w, h, c, px) = crate::io::jpeg::turbo::decode(&data).ok()?;
                crate::io::jpeg::turbo::encode(&px, w, h, c, st.jpeg_quality, st.jpeg_subsampling)
                    .ok()
            })
            .is_some()
    })?;
    if failed {
        return Err(Error::Usage(
            "bench: libjpeg-turbo decode + encode failed".into(),
        ));
    }
    Ok(secs)
}

fn remove(dir: &Path) {
    let _ = std::fs::remove_dir_all(dir);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn synthetic_photos_differ_and_are_lit() {
        let a = synthetic_photo(64, 48, 0, false);
        let b = synthetic_photo(64, 48, 1, false);
        assert_ne!(a.samples, b.samples);
        let Samples::U8(d) = &a.samples else { panic!() };
        // Brighter in the light cone than in the corner.
        let centre = d[(28 * 64 + 32) * 3] as u32;
        let corner = d[0] as u32;
        assert!(centre > corner, "{centre} vs {corner}");
    }

    /// A mission small enough for a unit test.
    fn tiny() -> BenchOptions {
        BenchOptions {
            width: 48,
            height: 32,
            distinct: 3,
            water_column: 1,
            ..BenchOptions::default()
        }
    }

    #[test]
    fn a_mission_folder_can_be_made_again_in_place() {
        // `bench --dir DIR` twice: the second run must not empty the photos the first one linked.
        let d = tempfile::tempdir().unwrap();
        let o = tiny();
        for _ in 0..2 {
            let m = generate(&o, d.path(), o.distinct).unwrap();
            survey_folder(&m, &d.path().join("s"), 5).unwrap();
            for e in io::find_photos(&d.path().join("s")).unwrap().photos {
                io::decode(&e.path).unwrap_or_else(|err| panic!("{err}"));
            }
        }
    }

    #[test]
    fn generated_photos_are_camera_like_jpegs() {
        let d = tempfile::tempdir().unwrap();
        let m = generate(&tiny(), d.path(), 3).unwrap();
        let c = crate::io::jpeg::parse(&std::fs::read(&m.distinct[0]).unwrap()).unwrap();
        assert_eq!(c.subsampling, Some(io::Subsampling::S420));
        assert_eq!(c.quality, Some(tiny().quality));
    }

    #[test]
    fn floor_counts_photos() {
        let d = tempfile::tempdir().unwrap();
        let o = tiny();
        let m = generate(&o, d.path(), o.distinct).unwrap();
        survey_folder(&m, &d.path().join("s"), 5).unwrap();
        let (n, s) = floor(
            &d.path().join("s"),
            &d.path().join("o"),
            2,
            EncodeSettings::default(),
        )
        .unwrap();
        assert_eq!(n, 5);
        assert!(s > 0.0);
        assert_eq!(
            io::find_photos(&d.path().join("o")).unwrap().photos.len(),
            5
        );
    }

    #[test]
    fn photos_made_in_order_are_the_noisy_photos() {
        // The texture held from one photo to the next, a jump back and one forward past what is held: the same
        // bytes as each photo made alone.
        for (w, h, sigma) in [
            (50usize, 20usize, Some(3.0f32)),
            (16, 9, None),
            (37, 5, Some(1.0)),
        ] {
            let mut frames = Frames::new(w, h, sigma);
            for j in [0usize, 1, 2, 3, 9, 10, 4, 5, 40, 41, 42] {
                assert_eq!(
                    frames.photo(j).samples,
                    noisy_photo(w, h, j, false, sigma).samples,
                    "{w}x{h} photo {j}"
                );
            }
        }
    }

    #[test]
    fn the_mission_is_distinct_photos_by_default() {
        let d = tempfile::tempdir().unwrap();
        let o = BenchOptions {
            distinct: 0,
            ..tiny()
        };
        let m = generate(&o, d.path(), 6).unwrap();
        let s = d.path().join("s");
        // A longer mission made there before: its extra photos go.
        survey_folder(&m, &s, 6).unwrap();
        survey_folder(&m, &s, 4).unwrap();
        let photos = io::find_photos(&s).unwrap().photos;
        assert_eq!(photos.len(), 4);
        let bytes: Vec<Vec<u8>> = photos
            .iter()
            .map(|e| std::fs::read(&e.path).unwrap())
            .collect();
        for i in 0..bytes.len() {
            for j in 0..i {
                assert_ne!(bytes[i], bytes[j], "photos {j} and {i}");
            }
        }
    }
}
