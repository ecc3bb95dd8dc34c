//! Valid JPEG variants (tests/data/jpeg, made with libjpeg-turbo's cjpeg and jpegtran from one synthetic picture:
//! 4:4:4, 4:2:2, 4:2:0, 4:1:1, 4:4:0, restart intervals, optimised tables, progressive, grey, and non-interleaved
//! baseline — one scan per component) decoded by abysslight and by an independent decoder (libjpeg-turbo-rs, a
//! port of libjpeg-turbo's decoder) agree within 3 levels per sample and 0.5 on average (the chroma upsampling
//! filters of the two decoders differ by up to 3 levels on subsampled files; 4:4:4 and grey agree within 1).

use std::path::Path;

use abysslight::Samples;

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
