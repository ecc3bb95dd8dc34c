//! Valid JPEG variants (tests/data/jpeg, made with libjpeg-turbo's cjpeg and jpegtran from one synthetic picture:
//! 4:4:4, 4:2:2, 4:2:0, 4:1:1, 4:4:0, restart intervals, optimised tables, progressive, grey, and non-interleaved
//! baseline — one scan per component) decoded by abysslight and by an independent decoder (libjpeg-turbo-rs, a
//! port of libjpeg-turbo's decoder) agree within 3 levels per sample and 0.5 on average (the chroma upsampling
//! filters of the two decoders differ by up to 3 levels on subsampled files; 4:4:4 and grey agree within 1).

use std::path::Path;

use abysslight::method::raster::Samples;

fn reference(data: &[u8], channels: usize) -> Vec<u8> {
    let format = if channels == 1 {
        libjpeg_turbo_rs::PixelFormat::Grayscale
    } else {
        libjpeg_turbo_rs::PixelFormat::Rgb
    };
    libjpeg_turbo_rs::decompress_to(data, format).unwrap().data
}

#[test]
fn every_valid_variant_decodes_as_the_reference_decoder_does() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/jpeg");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    files.sort();
    assert!(files.len() >= 14, "the corpus is missing");
    let mut bad = Vec::new();
    for f in &files {
        let photo = match abysslight::io::decode(f) {
            Ok(p) => p,
            Err(e) => {
                bad.push(format!("{}: refused: {e}", f.display()));
                continue;
            }
        };
        let Samples::U8(got) = &photo.samples else {
            panic!("8-bit JPEG decoded to 16 bits")
        };
        let want = reference(&std::fs::read(f).unwrap(), photo.layout.channels);
        assert_eq!(got.len(), want.len(), "{}", f.display());
        let worst = got
            .iter()
            .zip(&want)
            .map(|(a, b)| a.abs_diff(*b))
            .max()
            .unwrap();
        let mean = |v: &[u8]| v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64;
        let mean_diff = got
            .iter()
            .zip(&want)
            .map(|(a, b)| a.abs_diff(*b) as f64)
            .sum::<f64>()
            / got.len() as f64;
        if worst > 3 || mean_diff > 0.5 {
            bad.push(format!(
                "{}: differs by up to {worst} levels, {mean_diff:.2} on average (mean {:.1} against {:.1})",
                f.display(),
                mean(got),
                mean(&want)
            ));
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

/// A progressive JPEG cut inside any of its scans and closed with an end-of-image marker is refused (before:
/// accepted at almost every cut point, the rows after the cut left coarse or grey); the uncut file decodes.
#[test]
fn a_progressive_jpeg_cut_inside_a_scan_is_refused() {
    let (w, h) = (64u16, 48u16);
    let px: Vec<u8> = (0..w as u32 * h as u32 * 3)
        .map(|i| ((i * 2654435761u32) >> 24) as u8 / 2 + (i % 97) as u8)
        .collect();
    let mut full = Vec::new();
    let mut enc = jpeg_encoder::Encoder::new(&mut full, 90);
    enc.set_progressive(true);
    enc.encode(&px, w, h, jpeg_encoder::ColorType::Rgb).unwrap();
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("p.jpg");
    std::fs::write(&path, &full).unwrap();
    abysslight::io::decode(&path).expect("the uncut progressive JPEG must decode");
    // Each scan's compressed data: from the end of its header to the next marker (not a stuffed byte or a restart).
    let sos: Vec<usize> = (0..full.len() - 1)
        .filter(|&i| full[i] == 0xFF && full[i + 1] == 0xDA)
        .collect();
    assert!(sos.len() >= 4, "not progressive: {} scans", sos.len());
    let mut accepted = Vec::new();
    for &s in &sos {
        let start = s + 2 + u16::from_be_bytes([full[s + 2], full[s + 3]]) as usize;
        let end = (start..full.len() - 1)
            .find(|&i| full[i] == 0xFF && full[i + 1] != 0 && !(0xD0..=0xD7).contains(&full[i + 1]))
            .unwrap();
        for k in 1..4 {
            let cut = start + (end - start) * k / 4;
            if cut <= start {
                continue;
            }
            let mut bytes = full[..cut].to_vec();
            bytes.extend_from_slice(&[0xFF, 0xD9]);
            std::fs::write(&path, &bytes).unwrap();
            if abysslight::io::decode(&path).is_ok() {
                accepted.push(format!("scan at byte {s}, cut at {cut} of {start}..{end}"));
            }
        }
    }
    assert!(accepted.is_empty(), "accepted:\n{}", accepted.join("\n"));
}
