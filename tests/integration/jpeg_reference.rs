//! Valid JPEG variants (tests/data/jpeg, made with libjpeg-turbo's cjpeg and jpegtran from one synthetic picture:
//! 4:4:4, 4:2:2, 4:2:0, 4:1:1, 4:4:0, restart intervals, optimised tables, progressive, grey, and non-interleaved
//! baseline — one scan per component) decoded by abysslight and by an independent decoder (libjpeg-turbo-rs, a
//! port of libjpeg-turbo's decoder) agree within 3 levels per sample and 0.5 on average (the chroma upsampling
//! filters of the two decoders differ by up to 3 levels on subsampled files; 4:4:4 and grey agree within 1).

use crate::common::png_chunk;

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

/// A CMYK JPEG (tests/data/cmyk/cmyk.jpg: Pillow's RGB → CMYK of a gradient, with an Adobe marker, quality 95)
/// decodes to the RGB it was made from: R = 255·x/63, G = 255·y/47, B = 255·(x+y)/110.
#[test]
fn a_cmyk_jpeg_decodes_to_the_rgb_it_was_made_from() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/cmyk/cmyk.jpg");
    let photo = abysslight::io::decode(&path).unwrap();
    assert_eq!(
        (
            photo.layout.width,
            photo.layout.height,
            photo.layout.channels
        ),
        (64, 48, 3)
    );
    let Samples::U8(got) = &photo.samples else {
        panic!("8-bit JPEG decoded to 16 bits")
    };
    let want: Vec<u8> = (0..48usize)
        .flat_map(|y| {
            (0..64usize).flat_map(move |x| [x * 255 / 63, y * 255 / 47, (x + y) * 255 / 110])
        })
        .map(|v| v as u8)
        .collect();
    let diffs: Vec<u8> = got.iter().zip(&want).map(|(a, b)| a.abs_diff(*b)).collect();
    let worst = *diffs.iter().max().unwrap();
    let mean = diffs.iter().map(|&d| d as f64).sum::<f64>() / diffs.len() as f64;
    assert!(
        worst <= 8 && mean <= 1.5,
        "differs by up to {worst}, {mean:.2} on average"
    );
}

/// A PNG written by hand (no encoder shared with the decoders): `rows` already packed, filter type 0 each.
fn png(w: u32, h: u32, depth: u8, colour: u8, plte: Option<&[u8]>, rows: &[Vec<u8>]) -> Vec<u8> {
    use std::io::Write;
    let mut ihdr = w.to_be_bytes().to_vec();
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[depth, colour, 0, 0, 0]);
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    for r in rows {
        z.write_all(&[0]).unwrap();
        z.write_all(r).unwrap();
    }
    let mut f = b"\x89PNG\r\n\x1a\n".to_vec();
    f.extend(png_chunk(b"IHDR", &ihdr));
    if let Some(p) = plte {
        f.extend(png_chunk(b"PLTE", p));
    }
    f.extend(png_chunk(b"IDAT", &z.finish().unwrap()));
    f.extend(png_chunk(b"IEND", b""));
    f
}

/// An uncompressed TIFF written by hand, little- or big-endian, one strip, `bits` per sample.
fn tiff(w: u32, h: u32, channels: u16, bits: u16, big: bool, data: &[u8]) -> Vec<u8> {
    let (u16b, u32b) = (
        |v: u16, big: bool| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        },
        |v: u32, big: bool| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        },
    );
    let mut t = if big {
        b"MM\0*".to_vec()
    } else {
        b"II*\0".to_vec()
    };
    t.extend_from_slice(&u32b(8, big));
    let photometric = if channels == 1 { 1 } else { 2 };
    let entries: [(u16, u16, u32, u32); 9] = [
        (256, 4, 1, w),
        (257, 4, 1, h),
        (258, 3, channels as u32, 0), // bits: inline (1 channel) or at `extra`
        (259, 3, 1, 1),
        (262, 3, 1, photometric),
        (273, 4, 1, 0), // strip offset: filled below
        (277, 3, 1, channels as u32),
        (278, 4, 1, h),
        (279, 4, 1, data.len() as u32),
    ];
    let extra = 8 + 2 + entries.len() as u32 * 12 + 4;
    let strip = extra + 2 * channels as u32;
    t.extend_from_slice(&u16b(entries.len() as u16, big));
    for (tag, kind, count, value) in entries {
        t.extend_from_slice(&u16b(tag, big));
        t.extend_from_slice(&u16b(kind, big));
        t.extend_from_slice(&u32b(count, big));
        let v = match tag {
            258 if channels == 1 => return_short(bits, big),
            258 => u32b(extra, big),
            273 => u32b(strip, big),
            _ if kind == 3 => return_short(value as u16, big),
            _ => u32b(value, big),
        };
        t.extend_from_slice(&v);
    }
    t.extend_from_slice(&[0; 4]);
    for _ in 0..channels {
        t.extend_from_slice(&u16b(bits, big));
    }
    t.extend_from_slice(data);
    t
}

/// A SHORT value in a directory entry's 4-byte field (left-justified).
fn return_short(v: u16, big: bool) -> [u8; 4] {
    let b = if big {
        v.to_be_bytes()
    } else {
        v.to_le_bytes()
    };
    [b[0], b[1], 0, 0]
}

/// Lossless variants made by hand from known samples decode to exactly those samples: palette PNG (8- and 4-bit
/// indices), 16-bit RGB and grey PNG, 16-bit RGB TIFF (both byte orders) and 8-bit grey TIFF.
#[test]
fn lossless_variants_decode_to_their_samples() {
    let (w, h) = (37u32, 23u32);
    let v16 = |x: u32, y: u32, c: u32| ((x * 1733 + y * 977 + c * 20011) % 65536) as u16;
    let rgb16: Vec<u16> = (0..h)
        .flat_map(|y| (0..w).flat_map(move |x| (0..3).map(move |c| v16(x, y, c))))
        .collect();
    let grey16: Vec<u16> = (0..h)
        .flat_map(|y| (0..w).map(move |x| v16(x, y, 1)))
        .collect();
    let be = |v: &[u16]| v.iter().flat_map(|s| s.to_be_bytes()).collect::<Vec<u8>>();
    let le = |v: &[u16]| v.iter().flat_map(|s| s.to_le_bytes()).collect::<Vec<u8>>();
    let rows = |bytes: &[u8], per_row: usize| {
        bytes
            .chunks(per_row)
            .map(<[u8]>::to_vec)
            .collect::<Vec<_>>()
    };
    let palette: Vec<u8> = (0..256u32)
        .flat_map(|i| [i as u8, (255 - i) as u8, (i * 7) as u8])
        .collect();
    let index = |x: u32, y: u32| ((x * 5 + y * 11) % 256) as u8;
    let idx8: Vec<u8> = (0..h)
        .flat_map(|y| (0..w).map(move |x| index(x, y)))
        .collect();
    let via = |i: u8, n: usize| {
        palette[3 * i as usize..3 * i as usize + 3]
            .iter()
            .copied()
            .take(n)
    };
    let pal8: Vec<u8> = idx8.iter().flat_map(|&i| via(i, 3)).collect();
    let idx4: Vec<Vec<u8>> = (0..h)
        .map(|y| {
            (0..w.div_ceil(2))
                .map(|k| ((index(2 * k, y) % 16) << 4) | (index(2 * k + 1, y) % 16))
                .collect()
        })
        .collect();
    let pal4: Vec<u8> = (0..h)
        .flat_map(|y| (0..w).flat_map(move |x| via(index(x, y) % 16, 3)))
        .collect();
    let grey8: Vec<u8> = (0..h)
        .flat_map(|y| (0..w).map(move |x| ((x * 7 + y * 3) % 256) as u8))
        .collect();
    let cases: Vec<(&str, Vec<u8>, usize, Samples)> = vec![
        (
            "palette8.png",
            png(w, h, 8, 3, Some(&palette), &rows(&idx8, w as usize)),
            3,
            Samples::U8(pal8),
        ),
        (
            "palette4.png",
            png(w, h, 4, 3, Some(&palette[..48]), &idx4),
            3,
            Samples::U8(pal4),
        ),
        (
            "rgb16.png",
            png(w, h, 16, 2, None, &rows(&be(&rgb16), 6 * w as usize)),
            3,
            Samples::U16(rgb16.clone()),
        ),
        (
            "grey16.png",
            png(w, h, 16, 0, None, &rows(&be(&grey16), 2 * w as usize)),
            1,
            Samples::U16(grey16),
        ),
        (
            "rgb16-le.tif",
            tiff(w, h, 3, 16, false, &le(&rgb16)),
            3,
            Samples::U16(rgb16.clone()),
        ),
        (
            "rgb16-be.tif",
            tiff(w, h, 3, 16, true, &be(&rgb16)),
            3,
            Samples::U16(rgb16),
        ),
        (
            "grey8.tif",
            tiff(w, h, 1, 8, false, &grey8),
            1,
            Samples::U8(grey8),
        ),
    ];
    let d = tempfile::tempdir().unwrap();
    let mut bad = Vec::new();
    for (name, bytes, channels, want) in cases {
        let p = d.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        match abysslight::io::decode(&p) {
            Ok(photo) if photo.layout.channels == channels && photo.samples == want => {}
            Ok(photo) => bad.push(format!(
                "{name}: decoded to other samples ({} channels)",
                photo.layout.channels
            )),
            Err(e) => bad.push(format!("{name}: refused: {e}")),
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}
