//! A short fuzz run of the decoders and metadata parsers: valid seed files (baseline, progressive and
//! restart-interval JPEGs with EXIF, a PNG with text, compressed-text and ICC chunks, a TIFF, a PNM/PNG stream)
//! mutated at random (bytes overwritten, inserted, removed, the file cut) and fed to every reader. A reader may
//! refuse a file, never panic, and a photo it accepts has the size its header declares. The decoder calls here
//! are not behind `catch_unwind`, so a decoder panic fails the run.
//!
//! 64 cases a target in the test suite; a longer run (docs/threat-model.md):
//! `PROPTEST_CASES=20000 cargo test --release --lib io::fuzz`.

use std::io::Cursor;

use proptest::prelude::*;

use crate::io::metadata::png::chunk;
use crate::io::metadata::Metadata;
use crate::io::pnm::{decode_frame_unguarded, FrameSplitter};
use crate::io::{decode_unguarded, header_size, jpeg_check};

fn pixels(w: usize, h: usize) -> Vec<u8> {
    (0..w * h * 3)
        .map(|i| ((i * 37) % 251) as u8 ^ (i / 97) as u8)
        .collect()
}

fn jpeg(progressive: bool, restart: u16) -> Vec<u8> {
    let mut out = Vec::new();
    let mut enc = jpeg_encoder::Encoder::new(&mut out, 85);
    enc.set_progressive(progressive);
    enc.set_restart_interval(restart);
    let exif = b"Exif\0\0MM\0*\0\0\0\x08\0\x01\x01\x12\0\x03\0\0\0\x01\0\x06\0\0\0\0\0\0";
    enc.add_app_segment(1, exif.to_vec()).unwrap();
    enc.encode(&pixels(40, 24), 40, 24, jpeg_encoder::ColorType::Rgb)
        .unwrap();
    out
}

fn png() -> Vec<u8> {
    let img = image::RgbImage::from_raw(40, 24, pixels(40, 24)).unwrap();
    let mut plain = Vec::new();
    img.write_to(&mut Cursor::new(&mut plain), image::ImageFormat::Png)
        .unwrap();
    let z = |d: &[u8]| {
        use std::io::Write;
        let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        e.write_all(d).unwrap();
        e.finish().unwrap()
    };
    let mut extra = Vec::new();
    chunk(&mut extra, b"tEXt", b"Comment\0a survey photo");
    let note = [b"Note\0\0".as_slice(), &z(&[b'n'; 3000])].concat();
    chunk(&mut extra, b"zTXt", &note);
    let icc = [b"icc\0\0".as_slice(), &z(&[7u8; 600])].concat();
    chunk(&mut extra, b"iCCP", &icc);
    // After the 33 bytes of signature and IHDR.
    [&plain[..33], &extra, &plain[33..]].concat()
}

fn tiff() -> Vec<u8> {
    let img = image::RgbImage::from_raw(40, 24, pixels(40, 24)).unwrap();
    let mut out = Vec::new();
    img.write_to(&mut Cursor::new(&mut out), image::ImageFormat::Tiff)
        .unwrap();
    out
}

fn stream() -> Vec<u8> {
    let mut s = b"P6\n40 24\n255\n".to_vec();
    s.extend(pixels(40, 24));
    s.extend(png());
    s.extend(b"P5 # grey\n3 2\n65535\n");
    s.extend([1u8; 12]);
    s
}

/// One mutation of `seed`: `(kind, at, byte)`, positions taken modulo the length.
fn mutate(seed: &[u8], edits: &[(u8, usize, u8)]) -> Vec<u8> {
    let mut v = seed.to_vec();
    for &(kind, at, byte) in edits {
        if v.is_empty() {
            break;
        }
        let at = at % v.len();
        match kind % 8 {
            0..=3 => v[at] = byte,
            4 => v.insert(at, byte),
            5 => {
                v.remove(at);
            }
            6 => v.truncate(at),
            _ => v[at] ^= 1 << (byte % 8),
        }
    }
    v
}

/// Every reader of a photo file on `bytes`: the decoder, the header reader, the JPEG check and the survey's block
/// means, the metadata reader.
fn read_file(bytes: &[u8]) -> Result<(), TestCaseError> {
    let d = tempfile::tempdir().unwrap();
    for ext in ["jpg", "png", "tif"] {
        let p = d.path().join(format!("f.{ext}"));
        std::fs::write(&p, bytes).unwrap();
        let header = header_size(&p);
        if let Ok(photo) = decode_unguarded(&p) {
            let size = (photo.layout.width, photo.layout.height);
            prop_assert_eq!(
                header.ok(),
                Some(size),
                "accepted with another size than its header's"
            );
        }
        let _ = Metadata::read(&p);
    }
    let _ = jpeg_check::check(bytes);
    // The survey's block means: never a panic, and what they read the check accepts.
    if let Ok(Some(b)) = jpeg_check::block_means(bytes) {
        prop_assert!(
            jpeg_check::check(bytes).is_ok(),
            "block means of a JPEG the check refuses"
        );
        prop_assert_eq!(b.means.len(), b.blocks.0 * b.blocks.1 * b.channels);
    }
    let _ = Metadata::from_bytes(bytes);
    Ok(())
}

fn read_stream(bytes: &[u8]) {
    let mut frames = FrameSplitter::new(bytes);
    while let Some(f) = frames.next_frame() {
        if let Ok(f) = f {
            let _ = decode_frame_unguarded(&f);
        }
    }
}

fn edits() -> impl Strategy<Value = Vec<(u8, usize, u8)>> {
    prop::collection::vec((any::<u8>(), any::<usize>(), any::<u8>()), 1..6)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn mutated_jpegs(which in 0..3usize, e in edits()) {
        let seed = match which { 0 => jpeg(false, 0), 1 => jpeg(false, 2), _ => jpeg(true, 0) };
        read_file(&mutate(&seed, &e))?;
    }

    #[test]
    fn mutated_pngs_and_tiffs(tif in any::<bool>(), e in edits()) {
        let seed = if tif { tiff() } else { png() };
        read_file(&mutate(&seed, &e))?;
    }

    #[test]
    fn mutated_streams(e in edits()) {
        read_stream(&mutate(&stream(), &e));
    }
}
