//! `cargo bench --bench kernels`: the correction kernel alone, one thread, on a synthetic 12 MP photo (4000×3000
//! RGB, `F` at 8×8 blocks, a full-resolution `S`), for each kind of sample the cruise meets: 8-bit linear codes,
//! 8-bit sRGB (camera JPEGs: a table into linear light, a search back to the code) and 16-bit sRGB, and 8- and
//! 16-bit sRGB and 16-bit linear with the noise-aware blend of `--method abyss` over the whole frame (what a
//! noisy, dim photo pays). Prints the
//! best of 7 runs per kind and its ratio to 8-bit linear, measured in the same run, and the machine. The last two
//! rows correct the photo in bands of 64 rows, each copied out just before (in the cache, as a decoder writing
//! bands would leave it): what a one-pass banded pipeline would save of the kernel's memory traffic.

use std::time::Instant;

use abysslight::kernels::Blended;
use abysslight::kernels::Prepared;
use abysslight::kernels::{correct_with_offset, Blend};
use abysslight::{kernels::Curve, Transfer};
use abysslight::{Layout, Raster};

/// Best wall time (ms) of 7 corrections of `photo`, with the noise-aware blend when `blend`.
fn time<T: abysslight::Sample + Clone + Send + Sync>(
    photo: &[T],
    layout: Layout,
    transfer: Transfer,
    levels: usize,
    blend: bool,
) -> f64 {
    time_in_bands(photo, layout, transfer, levels, blend, layout.height)
}

/// [`time`] with the photo corrected a band of `band` rows at a time, each band copied out of the photo just
/// before its correction (as a decoder writing a band would leave it in the cache) and only the corrections
/// timed: with bands that fit the cache, what a one-pass banded pipeline would save of the kernel's memory
/// traffic.
fn time_in_bands<T: abysslight::Sample + Clone + Send + Sync>(
    photo: &[T],
    layout: Layout,
    transfer: Transfer,
    levels: usize,
    blend: bool,
    band: usize,
) -> f64 {
    let layout_full = layout;
    let layout = Layout {
        height: band.min(layout.height),
        ..layout
    };
    let (w, h, c) = (layout.width, layout.height, layout.channels);
    let s = Raster::from_fn(w, h, c, |x, y, ch| {
        0.02 + 0.01 * ch as f32 + 0.02 * ((x * 7 + y * 3) % 11) as f32 / 11.0
    });
    let scatter = Prepared::from_raster(&s, transfer);
    let f = Raster::from_fn(w.div_ceil(8), h.div_ceil(8), c, |x, y, _| {
        0.3 + 0.001 * x as f32 + 0.001 * y as f32
    });
    let curve = Curve::new(transfer, levels);
    // A blend that matters everywhere: weights 0.2–0.9 varying across the blocks, a level near the seafloor grey.
    let blended = Blended {
        level: Raster::from_fn(f.width, f.height, c, |x, y, _| {
            0.35 + 0.1 * ((x + y) % 5) as f32 / 5.0
        }),
        weight: Raster::from_fn(f.width, f.height, c, |x, y, ch| {
            0.2 + 0.7 * ((x * 3 + y + ch) % 7) as f32 / 7.0
        }),
        noise_var: vec![1e-4; c],
        prior_precision: 20.0,
    };
    let scale = vec![1.0f32; c];
    let with = blend.then_some(Blend {
        fields: Some(&blended),
        scatter_scale: &scale,
    });
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool");
    let mut best = f64::MAX;
    let band_len = w * h * c;
    let bands = layout_full.height / h;
    for _ in 0..7 {
        let mut total = 0.0;
        let mut whole = (bands == 1).then(|| photo.to_vec());
        for b in 0..bands {
            let mut p = match whole.take() {
                Some(p) => p,
                None => photo[b * band_len..(b + 1) * band_len].to_vec(),
            };
            let t = Instant::now();
            pool.install(|| {
                correct_with_offset(&mut p, layout, Some(&scatter), &f, with, 8, 1e-6, &curve)
            });
            total += t.elapsed().as_secs_f64() * 1000.0;
        }
        best = best.min(total);
    }
    best
}

fn main() {
    let layout = Layout {
        width: 4000,
        height: 3000,
        channels: 3,
    };
    let n = layout.width * layout.height * layout.channels;
    let mut r = 1u64;
    let mut next = move || {
        r ^= r << 13;
        r ^= r >> 7;
        r ^= r << 17;
        r
    };
    // Codes around a mid grey with texture and noise (the level does not change the kernels' cost).
    let codes: Vec<u16> = (0..n)
        .map(|i| (15_000 + (i % 97) * 200) as u16 + (next() % 10_000) as u16)
        .collect();
    let p8: Vec<u8> = codes.iter().map(|&v| (v >> 8) as u8).collect();
    let (cpu, cores, rustc) = abysslight::eval::machine();
    println!(
        "correction kernel, 4000x3000 RGB, one thread, best of 7 ({cpu}, {cores} cores, {rustc})"
    );
    let linear = time(&p8, layout, Transfer::Linear, 256, false);
    println!("  {:38} {linear:7.1} ms", "8-bit linear");
    for (label, ms) in [
        ("8-bit sRGB", time(&p8, layout, Transfer::Srgb, 256, false)),
        (
            "16-bit sRGB",
            time(&codes, layout, Transfer::Srgb, 65536, false),
        ),
        (
            "8-bit sRGB, blend",
            time(&p8, layout, Transfer::Srgb, 256, true),
        ),
        (
            "16-bit sRGB, blend",
            time(&codes, layout, Transfer::Srgb, 65536, true),
        ),
        (
            "16-bit linear, blend",
            time(&codes, layout, Transfer::Linear, 65536, true),
        ),
        (
            "8-bit sRGB, blend, in bands of 64 rows",
            time_in_bands(&p8, layout, Transfer::Srgb, 256, true, 64),
        ),
        (
            "8-bit sRGB, in bands of 64 rows",
            time_in_bands(&p8, layout, Transfer::Srgb, 256, false, 64),
        ),
    ] {
        println!(
            "  {label:38} {ms:7.1} ms   {:.2}x the 8-bit linear kernel",
            ms / linear
        );
    }
}
