//! How a JPEG input was coded, so the corrected photo can be written like it (issue 14): its chroma subsampling
//! (the sampling factors of its frame header, SOF) and its quality, estimated from its quantisation tables (DQT)
//! the way ImageMagick does: against the standard IJG tables (ITU-T T.81 Annex K) scaled by quality.
//!
//! Also the fast JPEG codec (libjpeg-turbo, cargo feature `turbojpeg`) when it is built in.

use std::io::Read;
use std::path::Path;

use crate::io::Subsampling;

impl Subsampling {
    /// Luma samples per chroma sample, across and down.
    pub fn factors(self) -> (u8, u8) {
        match self {
            Subsampling::S444 => (1, 1),
            Subsampling::S422 => (2, 1),
            Subsampling::S420 => (2, 2),
            Subsampling::S440 => (1, 2),
            Subsampling::S411 => (4, 1),
        }
    }

    fn from_factors(h: u8, v: u8) -> Option<Self> {
        [
            Subsampling::S444,
            Subsampling::S422,
            Subsampling::S420,
            Subsampling::S440,
            Subsampling::S411,
        ]
        .into_iter()
        .find(|s| s.factors() == (h, v))
    }

    /// `444`, `422`, ...
    pub fn name(self) -> &'static str {
        match self {
            Subsampling::S444 => "444",
            Subsampling::S422 => "422",
            Subsampling::S420 => "420",
            Subsampling::S440 => "440",
            Subsampling::S411 => "411",
        }
    }

    /// The same subsampling as the `libjpeg-turbo-rs` encoder names it.
    pub fn rust_encoder(self) -> libjpeg_turbo_rs::Subsampling {
        use libjpeg_turbo_rs::Subsampling as F;
        match self {
            Subsampling::S444 => F::S444,
            Subsampling::S422 => F::S422,
            Subsampling::S420 => F::S420,
            Subsampling::S440 => F::S440,
            Subsampling::S411 => F::S411,
        }
    }
}

impl std::fmt::Display for Subsampling {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Subsampling {
    type Err = String;
    /// `444`, `422` or `420` (also written `4:2:0`).
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().replace(':', "").as_str() {
            "444" => Ok(Subsampling::S444),
            "422" => Ok(Subsampling::S422),
            "420" => Ok(Subsampling::S420),
            _ => Err(format!(
                "invalid JPEG subsampling {s:?}: expected 444, 422 or 420"
            )),
        }
    }
}

/// What the headers of a JPEG say about how it was coded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JpegCoding {
    /// Colour components (1 grey, 3 YCbCr).
    pub components: u8,
    /// Chroma subsampling; `None` for grey or for factors abysslight cannot write.
    pub subsampling: Option<Subsampling>,
    /// Quality estimated from the quantisation tables; `None` if the tables are missing.
    pub quality: Option<u8>,
}

/// Annex K luminance table, natural (row-major) order.
pub const IJG_LUMA: [u16; 64] = [
    16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55, 14, 13, 16, 24, 40, 57, 69, 56,
    14, 17, 22, 29, 51, 87, 80, 62, 18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113,
    92, 49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99,
];

/// Annex K chrominance table, natural order.
pub const IJG_CHROMA: [u16; 64] = [
    17, 18, 24, 47, 99, 99, 99, 99, 18, 21, 26, 66, 99, 99, 99, 99, 24, 26, 56, 99, 99, 99, 99, 99,
    47, 66, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99,
    99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99,
];

/// Position in natural order of the k-th coefficient in zig-zag order (the order DQT stores them in).
const ZIGZAG: [usize; 64] = [
    0, 1, 8, 16, 9, 2, 3, 10, 17, 24, 32, 25, 18, 11, 4, 5, 12, 19, 26, 33, 40, 48, 41, 34, 27, 20,
    13, 6, 7, 14, 21, 28, 35, 42, 49, 56, 57, 50, 43, 36, 29, 22, 15, 23, 30, 37, 44, 51, 58, 59,
    52, 45, 38, 31, 39, 46, 53, 60, 61, 54, 47, 55, 62, 63,
];

/// A standard table scaled to `quality` (1–100) as libjpeg's `jpeg_set_quality` does (baseline: 1..=255).
pub fn ijg_scaled(table: &[u16; 64], quality: u8) -> [u16; 64] {
    let q = u32::from(quality.clamp(1, 100));
    let scale = if q < 50 { 5000 / q } else { 200 - 2 * q };
    table.map(|v| ((u32::from(v) * scale + 50) / 100).clamp(1, 255) as u16)
}

/// The quality (1–100) of the quantisation tables `luma` (and `chroma`, if given), in natural order, estimated as
/// ImageMagick does (`coders/jpeg.c`): two measures of how coarse tables are, the sum of all their entries and the
/// sum of four of them (luma 2 and 53, chroma 0 and 63), are compared with those of the IJG tables scaled to each
/// quality from the coarsest up; the first quality the tables are not finer than in both measures is taken when it
/// matches in both (exact for libjpeg-style encoders) or is above 50. ImageMagick's reference values are those of
/// the scaled IJG tables, computed here. Where that rule gives nothing (unusual tables below quality 51), the
/// quality whose scaled tables are nearest entry by entry.
pub fn estimate_quality(luma: &[u16; 64], chroma: Option<&[u16; 64]>) -> u8 {
    let measures = |l: &[u16; 64], c: Option<&[u16; 64]>| -> (u32, u32) {
        let mut hash = u32::from(l[2]) + u32::from(l[53]);
        let mut sum: u32 = l.iter().map(|&v| u32::from(v)).sum();
        if let Some(c) = c {
            hash += u32::from(c[0]) + u32::from(c[63]);
            sum += c.iter().map(|&v| u32::from(v)).sum::<u32>();
        }
        (hash, sum)
    };
    let (hash, sum) = measures(luma, chroma);
    for q in 1..=100u8 {
        let l = ijg_scaled(&IJG_LUMA, q);
        let c = chroma.map(|_| ijg_scaled(&IJG_CHROMA, q));
        let (h, s) = measures(&l, c.as_ref());
        if hash < h && sum < s {
            continue;
        }
        if (hash <= h && sum <= s) || q > 50 {
            return q;
        }
        break;
    }
    nearest_quality(luma, chroma)
}

/// The quality whose scaled IJG tables are nearest to `luma` (and `chroma`): the smallest sum of absolute
/// differences over all entries, the higher quality on a tie.
pub fn nearest_quality(luma: &[u16; 64], chroma: Option<&[u16; 64]>) -> u8 {
    let dist = |a: &[u16; 64], b: &[u16; 64]| -> u64 {
        a.iter()
            .zip(b)
            .map(|(&x, &y)| u64::from(x.abs_diff(y)))
            .sum()
    };
    let mut best = (u64::MAX, 0u8);
    for q in (1..=100u8).rev() {
        let mut d = dist(luma, &ijg_scaled(&IJG_LUMA, q));
        if let Some(c) = chroma {
            d += dist(c, &ijg_scaled(&IJG_CHROMA, q));
        }
        if d < best.0 {
            best = (d, q);
        }
    }
    best.1
}

/// Store the quantisation tables of a DQT segment `seg` (in natural order) into `tables`.
fn read_dqt(seg: &[u8], tables: &mut [Option<[u16; 64]>; 4]) {
    let mut s = seg;
    while let Some((&pq_tq, rest)) = s.split_first() {
        let (precision, id) = (pq_tq >> 4, usize::from(pq_tq & 15));
        let size = if precision == 0 { 64 } else { 128 };
        let Some(values) = rest.get(..size) else {
            break;
        };
        let mut t = [0u16; 64];
        for (k, &pos) in ZIGZAG.iter().enumerate() {
            t[pos] = if precision == 0 {
                u16::from(values[k])
            } else {
                u16::from_be_bytes([values[2 * k], values[2 * k + 1]])
            };
        }
        if id < 4 {
            tables[id] = Some(t);
        }
        s = &rest[size..];
    }
}

/// The (component id, h, v, table id) of each component of a frame header segment `seg`.
fn read_sof(seg: &[u8]) -> Option<Vec<(u8, u8, u8, u8)>> {
    let n = usize::from(*seg.get(5)?);
    (0..n)
        .map(|i| {
            let c = seg.get(6 + 3 * i..9 + 3 * i)?;
            Some((c[0], c[1] >> 4, c[1] & 15, c[2] & 3))
        })
        .collect::<Option<Vec<_>>>()
}

/// Read the headers of a JPEG held in memory (at least up to its first scan): frame components, their sampling
/// factors and quantisation tables. `None` if it does not start like a JPEG or has no frame header before its
/// first scan.
pub fn parse(bytes: &[u8]) -> Option<JpegCoding> {
    if !bytes.starts_with(&[0xff, 0xd8]) {
        return None;
    }
    let mut tables: [Option<[u16; 64]>; 4] = [None; 4];
    // (component id, h, v, table id) of the frame header.
    let mut frame: Option<Vec<(u8, u8, u8, u8)>> = None;
    let mut at = 2;
    loop {
        // Skip fill bytes; a marker is 0xff then a code.
        while bytes.get(at) == Some(&0xff) && bytes.get(at + 1) == Some(&0xff) {
            at += 1;
        }
        if bytes.get(at) != Some(&0xff) {
            break;
        }
        let marker = *bytes.get(at + 1)?;
        at += 2;
        if matches!(marker, 0x01 | 0xd0..=0xd7) {
            continue;
        }
        if matches!(marker, 0xd9 | 0xda) {
            break;
        }
        let len = usize::from(u16::from_be_bytes([*bytes.get(at)?, *bytes.get(at + 1)?]));
        let seg = bytes.get(at + 2..at + len.max(2))?;
        at += len.max(2);
        match marker {
            0xdb => read_dqt(seg, &mut tables),
            // SOF0..SOF15 except DHT (c4), JPG (c8) and DAC (cc).
            0xc0..=0xcf if !matches!(marker, 0xc4 | 0xc8 | 0xcc) => {
                frame = Some(read_sof(seg)?);
            }
            _ => {}
        }
    }
    let comps = frame?;
    let (first, rest) = comps.split_first()?;
    let subsampling = match rest {
        [cb, cr] if (cb.1, cb.2) == (cr.1, cr.2) && cb.1 > 0 && cb.2 > 0 => {
            if first.1 % cb.1 == 0 && first.2 % cb.2 == 0 {
                Subsampling::from_factors(first.1 / cb.1, first.2 / cb.2)
            } else {
                None
            }
        }
        _ => None,
    };
    let luma = tables[usize::from(first.3)];
    let chroma = rest.first().and_then(|c| tables[usize::from(c.3)]);
    let quality = luma.map(|l| estimate_quality(&l, chroma.as_ref()));
    Some(JpegCoding {
        components: comps.len() as u8,
        subsampling,
        quality,
    })
}

/// The bytes of the JPEG file at `path` up to and including its first scan header (metadata, tables, frame
/// header), read without the compressed image data. `Ok(None)` when the file does not start like a JPEG.
pub fn read_head(path: &Path) -> std::io::Result<Option<Vec<u8>>> {
    let file = std::fs::File::open(path)?;
    let mut r = std::io::BufReader::with_capacity(64 << 10, file);
    let mut head = vec![0u8; 2];
    if r.read_exact(&mut head).is_err() || head != [0xff, 0xd8] {
        return Ok(None);
    }
    let mut b = [0u8; 1];
    loop {
        if r.read_exact(&mut b).is_err() || b[0] != 0xff {
            return Ok(Some(head));
        }
        head.push(0xff);
        let mut marker = 0xff;
        while marker == 0xff {
            if r.read_exact(&mut b).is_err() {
                return Ok(Some(head));
            }
            marker = b[0];
        }
        head.push(marker);
        if matches!(marker, 0x01 | 0xd0..=0xd9) {
            if marker == 0xd9 {
                return Ok(Some(head));
            }
            continue;
        }
        let mut len = [0u8; 2];
        if r.read_exact(&mut len).is_err() {
            return Ok(Some(head));
        }
        head.extend_from_slice(&len);
        let n = usize::from(u16::from_be_bytes(len)).saturating_sub(2);
        let at = head.len();
        head.resize(at + n, 0);
        let got = crate::io::read_full(&mut r, &mut head[at..])?;
        head.truncate(at + got);
        if got < n || marker == 0xda {
            return Ok(Some(head));
        }
    }
}

/// `abysslight --version`: the version and the JPEG codec built in.
#[cfg(feature = "turbojpeg")]
pub const VERSION: &str = concat!(env!("CARGO_PKG_VERSION"), " (JPEG codec: libjpeg-turbo)");
/// `abysslight --version`: the version and the JPEG codec built in.
#[cfg(not(feature = "turbojpeg"))]
pub const VERSION: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    " (JPEG codec: libjpeg-turbo-rs encoder + zune-jpeg decoder, pure Rust; build with --features turbojpeg for C libjpeg-turbo)"
);

/// The JPEG codec abysslight is built with, for `--version` and `bench`.
pub fn codec_name() -> &'static str {
    if cfg!(feature = "turbojpeg") {
        "libjpeg-turbo (turbojpeg feature)"
    } else {
        "libjpeg-turbo-rs + zune-jpeg (pure Rust)"
    }
}

/// The libjpeg-turbo codec (cargo feature `turbojpeg`, linking the system's `libturbojpeg`). One compressor and one
/// decompressor per thread, kept for the thread's life. Its output depends only on the pixels and the settings,
/// never on the thread.
#[cfg(feature = "turbojpeg")]
pub mod turbo {
    use std::cell::RefCell;

    use super::Subsampling;

    thread_local! {
        static COMPRESSOR: RefCell<Option<turbojpeg::Compressor>> = const { RefCell::new(None) };
        static DECOMPRESSOR: RefCell<Option<turbojpeg::Decompressor>> = const { RefCell::new(None) };
    }

    fn subsamp(s: Subsampling) -> turbojpeg::Subsamp {
        match s {
            Subsampling::S444 => turbojpeg::Subsamp::None,
            Subsampling::S422 => turbojpeg::Subsamp::Sub2x1,
            Subsampling::S420 => turbojpeg::Subsamp::Sub2x2,
            Subsampling::S440 => turbojpeg::Subsamp::Sub1x2,
            Subsampling::S411 => turbojpeg::Subsamp::Sub4x1,
        }
    }

    /// Encode 8-bit grey (`channels` 1) or RGB samples, row after row.
    pub fn encode(
        samples: &[u8],
        width: usize,
        height: usize,
        channels: usize,
        quality: u8,
        subsampling: Subsampling,
    ) -> Result<Vec<u8>, String> {
        COMPRESSOR.with(|c| {
            let mut c = c.borrow_mut();
            if c.is_none() {
                *c = Some(turbojpeg::Compressor::new().map_err(|e| e.to_string())?);
            }
            let comp = c.as_mut().expect("just made");
            let (format, sub) = if channels == 1 {
                (turbojpeg::PixelFormat::GRAY, turbojpeg::Subsamp::Gray)
            } else {
                (turbojpeg::PixelFormat::RGB, subsamp(subsampling))
            };
            comp.set_quality(i32::from(quality));
            comp.set_subsamp(sub);
            let image = turbojpeg::Image {
                pixels: samples,
                width,
                pitch: width * channels,
                height,
                format,
            };
            comp.compress_to_vec(image).map_err(|e| e.to_string())
        })
    }

    /// Decode a JPEG into 8-bit grey (1 channel) or RGB samples: (width, height, channels, samples). Warnings
    /// (a truncated or damaged file) are errors, as in the strict Rust decoder.
    pub fn decode(data: &[u8]) -> Result<(usize, usize, usize, Vec<u8>), String> {
        DECOMPRESSOR.with(|d| {
            let mut d = d.borrow_mut();
            if d.is_none() {
                *d = Some(turbojpeg::Decompressor::new().map_err(|e| e.to_string())?);
            }
            let dec = d.as_mut().expect("just made");
            let header = dec.read_header(data).map_err(|e| e.to_string())?;
            let (format, channels) = if header.subsamp == turbojpeg::Subsamp::Gray {
                (turbojpeg::PixelFormat::GRAY, 1)
            } else {
                (turbojpeg::PixelFormat::RGB, 3)
            };
            let mut pixels = crate::io::buffers::take(header.width * header.height * channels);
            let image = turbojpeg::Image {
                pixels: pixels.as_mut_slice(),
                width: header.width,
                pitch: header.width * channels,
                height: header.height,
                format,
            };
            dec.decompress(data, image).map_err(|e| e.to_string())?;
            Ok((header.width, header.height, channels, pixels))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{encode_to, EncodeSettings};
    use crate::method::raster::{Layout, Photo, Samples};

    fn photo(w: usize, h: usize, channels: usize) -> Photo {
        let mut s = 7u32;
        let samples = (0..w * h * channels)
            .map(|_| {
                s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                (s >> 24) as u8
            })
            .collect();
        Photo {
            layout: Layout {
                width: w,
                height: h,
                channels,
            },
            samples: Samples::U8(samples),
            alpha: None,
        }
    }

    fn encoded(p: &Photo, quality: u8, sub: Subsampling) -> Vec<u8> {
        let mut v = Vec::new();
        let settings = EncodeSettings {
            jpeg_quality: quality,
            jpeg_subsampling: sub,
            ..EncodeSettings::default()
        };
        encode_to(p, image::ImageFormat::Jpeg, settings, &mut v).unwrap();
        v
    }

    #[test]
    fn scaled_tables_match_libjpeg_at_known_points() {
        // Quality 50 is Annex K itself, 100 is all ones; 75 halves (rounded), as jpeg_set_quality does.
        assert_eq!(ijg_scaled(&IJG_LUMA, 50), IJG_LUMA);
        assert_eq!(ijg_scaled(&IJG_CHROMA, 100), [1; 64]);
        assert_eq!(ijg_scaled(&IJG_LUMA, 75)[0], 8);
        assert_eq!(ijg_scaled(&IJG_LUMA, 75)[1], 6); // (11·50 + 50) / 100
        assert_eq!(ijg_scaled(&IJG_LUMA, 10)[63], 255); // 99·500/100 clamped
    }

    #[test]
    fn quality_round_trips_through_an_encoded_file() {
        let p = photo(40, 24, 3);
        let g = photo(16, 16, 1);
        for q in 50..=100u8 {
            for sub in [Subsampling::S444, Subsampling::S422, Subsampling::S420] {
                let c = parse(&encoded(&p, q, sub)).unwrap();
                let got = c.quality.unwrap();
                assert!(got.abs_diff(q) <= 1, "quality {q} {sub}: estimated {got}");
                assert_eq!(c.subsampling, Some(sub), "quality {q}");
                assert_eq!(c.components, 3);
            }
            let c = parse(&encoded(&g, q, Subsampling::S444)).unwrap();
            assert!(c.quality.unwrap().abs_diff(q) <= 1, "grey quality {q}");
            assert_eq!((c.components, c.subsampling), (1, None));
        }
    }

    #[test]
    fn estimate_of_tables_between_two_qualities_is_one_of_them() {
        // Halfway between the tables of 80 and 84: the estimate must land in 80..=84, not elsewhere.
        let (a, b) = (ijg_scaled(&IJG_LUMA, 80), ijg_scaled(&IJG_LUMA, 84));
        let mid: [u16; 64] = std::array::from_fn(|i| (a[i] + b[i]) / 2);
        let q = estimate_quality(&mid, None);
        assert!((80..=84).contains(&q), "{q}");
        assert!((80..=84).contains(&nearest_quality(&mid, None)));
    }

    #[test]
    fn exact_tables_give_their_quality_for_every_quality() {
        // Both rules, every quality: the tables libjpeg writes at q are recognised as q (±1 where two qualities
        // round to the same tables).
        for q in 1..=100u8 {
            let (l, c) = (ijg_scaled(&IJG_LUMA, q), ijg_scaled(&IJG_CHROMA, q));
            let got = estimate_quality(&l, Some(&c));
            assert!(got.abs_diff(q) <= 1, "{q}: {got}");
            assert_eq!(ijg_scaled(&IJG_LUMA, got), l, "{q}: {got}");
            assert!(nearest_quality(&l, Some(&c)).abs_diff(q) <= 1);
        }
    }

    #[test]
    fn the_head_stops_at_the_scan_and_parses_like_the_whole_file() {
        let d = tempfile::tempdir().unwrap();
        let bytes = encoded(&photo(64, 48, 3), 88, Subsampling::S422);
        let path = d.path().join("a.jpg");
        std::fs::write(&path, &bytes).unwrap();
        let head = read_head(&path).unwrap().unwrap();
        assert!(head.len() < bytes.len() && bytes.starts_with(&head));
        // The head ends with the scan header: SOS then its length's worth of bytes.
        let sos = head.windows(2).rposition(|w| w == [0xff, 0xda]).unwrap();
        let len = u16::from_be_bytes([head[sos + 2], head[sos + 3]]) as usize;
        assert_eq!(head.len(), sos + 2 + len);
        assert_eq!(parse(&head), parse(&bytes));
        assert_eq!(parse(&head).unwrap().quality, Some(88));
        std::fs::write(&path, b"\x89PNG not a jpeg").unwrap();
        assert_eq!(read_head(&path).unwrap(), None);
        // Cut inside a segment: what was read comes back, and parsing fails cleanly.
        std::fs::write(&path, &bytes[..30]).unwrap();
        let cut = read_head(&path).unwrap().unwrap();
        assert_eq!(cut, &bytes[..30]);
        assert_eq!(parse(&cut), None);
    }

    #[test]
    fn subsampling_names_parse() {
        assert_eq!("4:2:0".parse::<Subsampling>(), Ok(Subsampling::S420));
        assert_eq!("422".parse::<Subsampling>(), Ok(Subsampling::S422));
        assert!("411".parse::<Subsampling>().is_err());
    }
}
