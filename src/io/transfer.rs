//! `--transfer auto`: the camera curve a photo file declares, read from its metadata, with the reason.
//!
//! In order (the first that applies):
//! 1. PNG `cICP`: transfer characteristics 8 (linear) or 13 (sRGB);
//! 2. PNG `sRGB` chunk: sRGB;
//! 3. PNG `gAMA`: 1.0 is linear, else a power law `1/gamma` (0.45455 is the sRGB-like 2.2);
//! 4. an ICC profile: linear when its description says so ("linear"), otherwise sRGB (sRGB, Adobe RGB, Display P3
//!    and camera profiles all have gamma-like curves; abysslight's sRGB is the closest of its curves);
//! 5. EXIF `ColorSpace` = 1: sRGB;
//! 6. nothing declared: a JPEG is sRGB (cameras write JPEGs sRGB-encoded); a 16-bit PNG or TIFF and any other file
//!    are linear — when the camera is unknown, linear is the wrong guess that costs less (docs/evaluation.md:
//!    sRGB assumed on a linear camera doubles the residual pattern, linear assumed on an sRGB camera barely
//!    changes it).

use std::path::Path;

use image::{ImageDecoder, ImageFormat};

use crate::error::{Error, Result};
use crate::io::metadata::{ifd, Metadata};
use crate::method::transfer::Transfer;

/// EXIF tag `ColorSpace` (in the EXIF sub-IFD).
const COLOR_SPACE: u16 = 0xA001;

/// The curve a file declares and why it was taken.
#[derive(Debug, Clone, PartialEq)]
pub struct Assumed {
    /// The curve.
    pub transfer: Transfer,
    /// Why, in a few words naming what the file says (for the run's messages and report).
    pub why: String,
}

/// The curve `path` declares (see the [module documentation](self)). Reads the file's header and metadata blocks
/// only, not its pixels. Errors: the file cannot be opened.
pub fn assume(path: &Path) -> Result<Assumed> {
    let reader = image::ImageReader::open(path)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| Error::io(path, e))?;
    let format = reader.format();
    let meta = match format {
        Some(ImageFormat::Jpeg | ImageFormat::Png | ImageFormat::Tiff) => {
            Metadata::read(path).unwrap_or_default()
        }
        _ => Metadata::default(),
    };
    // The sample depth from the decoder's header (a JPEG is 8-bit, and its rule does not need it).
    let sixteen = format != Some(ImageFormat::Jpeg)
        && reader.into_decoder().is_ok_and(|d| {
            let t = d.color_type();
            t.bytes_per_pixel() / t.channel_count() == 2
        });
    Ok(from_metadata(&meta, format, sixteen))
}

/// [`assume`] from the first of `paths` that can be read (an unreadable first photo is one skipped photo, not
/// the end of the mission); `None` when none of them can.
pub fn assume_first<'a>(paths: impl IntoIterator<Item = &'a Path>) -> Option<Assumed> {
    paths.into_iter().find_map(|p| {
        std::fs::File::open(p)
            .and_then(|mut f| std::io::Read::read(&mut f, &mut [0u8; 16]))
            .ok()
            .and_then(|_| assume(p).ok())
    })
}

/// [`assume`] from what was read: the metadata, the container format and whether the samples are 16-bit.
pub fn from_metadata(meta: &Metadata, format: Option<ImageFormat>, sixteen: bool) -> Assumed {
    let said = |transfer: Transfer, why: String| Assumed { transfer, why };
    let chunk = |name: &[u8; 4]| {
        meta.png_chunks
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, d)| d.as_slice())
    };
    if let Some(c) = chunk(b"cICP").filter(|c| c.len() >= 2) {
        match c[1] {
            8 => return said(Transfer::Linear, "PNG cICP: linear transfer".into()),
            13 => return said(Transfer::Srgb, "PNG cICP: sRGB transfer".into()),
            _ => {}
        }
    }
    if chunk(b"sRGB").is_some() {
        return said(Transfer::Srgb, "PNG sRGB chunk".into());
    }
    if let Some(g) = chunk(b"gAMA").filter(|g| g.len() == 4) {
        let gamma = u32::from_be_bytes([g[0], g[1], g[2], g[3]]) as f32 / 100_000.0;
        if (gamma - 1.0).abs() < 0.01 {
            return said(Transfer::Linear, "PNG gAMA 1.0".into());
        }
        if gamma > 0.05 && gamma < 1.5 {
            return said(
                Transfer::Gamma(1.0 / gamma),
                format!("PNG gAMA {gamma:.5}: power law {:.3}", 1.0 / gamma),
            );
        }
    }
    if let Some(icc) = &meta.icc {
        let text = String::from_utf8_lossy(icc).to_ascii_lowercase();
        if text.contains("linear") {
            return said(Transfer::Linear, "ICC profile described as linear".into());
        }
        return said(
            Transfer::Srgb,
            "ICC colour profile (a gamma-like curve)".into(),
        );
    }
    if meta.exif.as_deref().and_then(exif_colour_space) == Some(1) {
        return said(Transfer::Srgb, "EXIF ColorSpace sRGB".into());
    }
    match format {
        Some(ImageFormat::Jpeg) => said(
            Transfer::Srgb,
            "JPEG without colour information (cameras write JPEGs sRGB-encoded)".into(),
        ),
        _ if sixteen => said(
            Transfer::Linear,
            "16-bit samples without colour information".into(),
        ),
        _ => said(
            Transfer::Linear,
            "no colour information in the file (linear: the guess that costs less when wrong)"
                .into(),
        ),
    }
}

/// EXIF `ColorSpace` (1 = sRGB, 0xFFFF = uncalibrated) from an EXIF block (a TIFF structure).
pub fn exif_colour_space(exif: &[u8]) -> Option<u32> {
    let mut src: &[u8] = exif;
    let (order, at) = ifd::read_header(&mut src).ok()?;
    let keep = |depth: usize, tag: u16| match depth {
        0 => tag == ifd::EXIF_IFD,
        _ => tag == COLOR_SPACE,
    };
    let (ifd0, _) = ifd::read_ifd(&mut src, order, at, &keep, &mut Vec::new()).ok()?;
    ifd0.get(ifd::EXIF_IFD)?
        .sub
        .as_ref()?
        .get(COLOR_SPACE)?
        .uint(order)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meta_with_chunk(name: &[u8; 4], data: &[u8]) -> Metadata {
        Metadata {
            png_chunks: vec![(*name, data.to_vec())],
            ..Metadata::default()
        }
    }

    #[test]
    fn the_rules_in_order() {
        let png = Some(ImageFormat::Png);
        let t = |m: &Metadata, f, s| from_metadata(m, f, s).transfer;
        assert_eq!(
            t(&meta_with_chunk(b"cICP", &[1, 8, 0, 1]), png, false),
            Transfer::Linear
        );
        assert_eq!(
            t(&meta_with_chunk(b"cICP", &[1, 13, 0, 1]), png, true),
            Transfer::Srgb
        );
        assert_eq!(
            t(&meta_with_chunk(b"sRGB", &[0]), png, true),
            Transfer::Srgb
        );
        assert_eq!(
            t(
                &meta_with_chunk(b"gAMA", &100_000u32.to_be_bytes()),
                png,
                false
            ),
            Transfer::Linear
        );
        match t(
            &meta_with_chunk(b"gAMA", &45_455u32.to_be_bytes()),
            png,
            false,
        ) {
            Transfer::Gamma(g) => assert!((g - 2.2).abs() < 0.01, "{g}"),
            other => panic!("{other:?}"),
        }
        let icc = |desc: &str| Metadata {
            icc: Some(format!("....desc {desc}").into_bytes()),
            ..Metadata::default()
        };
        assert_eq!(t(&icc("Linear Rec709"), png, false), Transfer::Linear);
        assert_eq!(t(&icc("sRGB IEC61966-2.1"), png, true), Transfer::Srgb);
        // Nothing declared.
        let none = Metadata::default();
        assert_eq!(t(&none, Some(ImageFormat::Jpeg), false), Transfer::Srgb);
        assert_eq!(t(&none, png, true), Transfer::Linear);
        assert_eq!(t(&none, png, false), Transfer::Linear);
        assert!(from_metadata(&none, png, false)
            .why
            .contains("no colour information"));
    }

    #[test]
    fn undeclared_files_by_depth_and_format() {
        use crate::io::{write_atomic, EncodeSettings};
        use crate::method::raster::{Layout, Photo, Samples};
        let d = tempfile::tempdir().unwrap();
        let layout = Layout {
            width: 8,
            height: 8,
            channels: 3,
        };
        let photo = |samples| Photo {
            layout,
            samples,
            alpha: None,
        };
        let cases = [
            (
                "a.png",
                Samples::U16(vec![1000; 192]),
                Transfer::Linear,
                "16-bit",
            ),
            (
                "b.tif",
                Samples::U16(vec![1000; 192]),
                Transfer::Linear,
                "16-bit",
            ),
            (
                "c.png",
                Samples::U8(vec![100; 192]),
                Transfer::Linear,
                "no colour information",
            ),
            ("d.jpg", Samples::U8(vec![100; 192]), Transfer::Srgb, "JPEG"),
        ];
        for (name, samples, want, why) in cases {
            let p = d.path().join(name);
            write_atomic(&photo(samples), &p, EncodeSettings::default()).unwrap();
            let a = assume(&p).unwrap();
            assert_eq!(a.transfer, want, "{name}: {a:?}");
            assert!(a.why.contains(why), "{name}: {a:?}");
        }
        assert!(assume(&d.path().join("missing.png")).is_err());
    }

    #[test]
    fn exif_colour_space_from_a_tiff_structure() {
        // Little-endian TIFF: IFD0 at 8 with one entry (EXIF pointer -> 26), the EXIF IFD with ColorSpace = 1.
        let mut b = Vec::new();
        b.extend_from_slice(b"II\x2a\x00");
        b.extend_from_slice(&8u32.to_le_bytes());
        b.extend_from_slice(&1u16.to_le_bytes());
        b.extend_from_slice(&ifd::EXIF_IFD.to_le_bytes());
        b.extend_from_slice(&4u16.to_le_bytes()); // LONG
        b.extend_from_slice(&1u32.to_le_bytes());
        b.extend_from_slice(&26u32.to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes()); // next IFD
        assert_eq!(b.len(), 26);
        b.extend_from_slice(&1u16.to_le_bytes());
        b.extend_from_slice(&COLOR_SPACE.to_le_bytes());
        b.extend_from_slice(&3u16.to_le_bytes()); // SHORT
        b.extend_from_slice(&1u32.to_le_bytes());
        b.extend_from_slice(&[1, 0, 0, 0]);
        b.extend_from_slice(&0u32.to_le_bytes());
        assert_eq!(exif_colour_space(&b), Some(1));
        let meta = Metadata {
            exif: Some(b),
            ..Metadata::default()
        };
        assert_eq!(
            from_metadata(&meta, Some(ImageFormat::Png), false).transfer,
            Transfer::Srgb
        );
        assert_eq!(exif_colour_space(b"not a tiff"), None);
    }
}
