//! The JPEG encoder (libjpeg-turbo-rs, pinned in Cargo.toml) against independent checks: its files decoded by
//! zune-jpeg (abysslight's own strict decoder, written independently of libjpeg-turbo) and by its own decoder
//! agree within one level (two or three in a few samples) and are close to the pixels encoded; and its output is the same, byte for byte, with its
//! SIMD kernels off (`JSIMD_FORCENONE=1`: the scalar code a CPU without AVX2 runs) as with the kernels this CPU
//! takes. The scalar run is a child process of this test binary, so that the switch is read from its start.

use std::path::Path;

use abysslight::eval::noisy_photo;
use abysslight::io::{self, EncodeSettings, Subsampling};
use abysslight::{Layout, Photo, Samples};

/// Photos of odd and even sizes, RGB and grey, with the bench's texture and noise; each with the settings it is
/// encoded with.
fn corpus() -> Vec<(String, Photo, EncodeSettings)> {
    let mut out = Vec::new();
    let sizes = [(64, 48), (97, 61), (203, 137), (8, 8), (17, 3)];
    let codings = [
        (92, Subsampling::S420),
        (75, Subsampling::S422),
        (95, Subsampling::S444),
    ];
    for (i, &(w, h)) in sizes.iter().enumerate() {
        for (j, &(q, s)) in codings.iter().enumerate() {
            let p = noisy_photo(w, h, i * 3 + j, false, Some(3.0));
            let settings = EncodeSettings {
                jpeg_quality: q,
                jpeg_subsampling: s,
                ..EncodeSettings::default()
            };
            out.push((format!("{w}x{h} q{q} {}", s.name()), p, settings));
        }
        let Samples::U8(rgb) = noisy_photo(w, h, i, false, Some(3.0)).samples else {
            unreachable!()
        };
        let grey = Photo {
            layout: Layout {
                width: w,
                height: h,
                channels: 1,
            },
            samples: Samples::U8(rgb.chunks_exact(3).map(|p| p[1]).collect()),
            alpha: None,
        };
        out.push((format!("{w}x{h} grey q90"), grey, EncodeSettings::default()));
    }
    out
}

fn encode(p: &Photo, s: EncodeSettings) -> Vec<u8> {
    let mut bytes = Vec::new();
    io::encode_to(p, image::ImageFormat::Jpeg, s, &mut bytes).unwrap();
    bytes
}

fn samples(p: &Photo) -> &[u8] {
    let Samples::U8(v) = &p.samples else {
        panic!("8-bit")
    };
    v
}

#[test]
fn encoded_files_decode_alike_in_two_decoders_and_near_the_pixels() {
    let dir = tempfile::tempdir().unwrap();
    // Full and subsampled chroma: the largest difference between the decoders, samples more than one level
    // apart, samples.
    let mut tallies = [(0u8, 0usize, 0usize); 2];
    for (name, p, s) in corpus() {
        let bytes = encode(&p, s);
        let path = dir.path().join("a.jpg");
        std::fs::write(&path, &bytes).unwrap();
        let zune = io::decode(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(zune.layout, p.layout, "{name}");
        let own = libjpeg_turbo_rs::decompress(&bytes).unwrap();
        assert_eq!((own.width, own.height), (p.layout.width, p.layout.height));
        let (z, o, src) = (samples(&zune), &own.data, samples(&p));
        assert_eq!(z.len(), o.len(), "{name}");
        let subsampled = s.jpeg_subsampling != Subsampling::S444 && p.layout.channels == 3;
        let tally = &mut tallies[subsampled as usize];
        for (a, b) in z.iter().zip(o) {
            let d = a.abs_diff(*b);
            tally.0 = tally.0.max(d);
            tally.1 += (d > 1) as usize;
            tally.2 += 1;
        }
        // Close to what was encoded: the mean error of a q75–95 JPEG of noisy texture is a few levels.
        let mean_err = z
            .iter()
            .zip(src)
            .map(|(a, b)| a.abs_diff(*b) as f64)
            .sum::<f64>()
            / src.len() as f64;
        assert!(mean_err < 6.0, "{name}: mean error {mean_err}");
    }
    // Within one level, but for a few samples: the two decoders' IDCTs (and chroma upsampling, at odd edges too)
    // round differently.
    for ((worst, off, n), (max, share)) in tallies.into_iter().zip([(2, 0.005), (3, 0.03)]) {
        let got = off as f64 / n as f64;
        assert!(
            worst <= max && got <= share,
            "the decoders differ by up to {worst}, by more than one level in {got}"
        );
    }
}

/// Where the child run writes its encodings.
const CHILD_DIR: &str = "ABYSSLIGHT_TEST_ENCODE_DIR";

#[test]
fn scalar_and_simd_encoders_write_the_same_bytes() {
    if let Ok(dir) = std::env::var(CHILD_DIR) {
        // The child: encode the corpus with the kernels its environment chose.
        for (i, (_, p, s)) in corpus().into_iter().enumerate() {
            std::fs::write(Path::new(&dir).join(format!("{i}.jpg")), encode(&p, s)).unwrap();
        }
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let status = std::process::Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "jpeg_encoder_differential::scalar_and_simd_encoders_write_the_same_bytes",
            "--test-threads",
            "1",
        ])
        .env(CHILD_DIR, dir.path())
        .env("JSIMD_FORCENONE", "1")
        .status()
        .unwrap();
    assert!(status.success());
    for (i, (name, p, s)) in corpus().into_iter().enumerate() {
        let scalar = std::fs::read(dir.path().join(format!("{i}.jpg"))).unwrap();
        assert!(
            scalar == encode(&p, s),
            "{name}: the scalar encoder wrote other bytes"
        );
    }
}
