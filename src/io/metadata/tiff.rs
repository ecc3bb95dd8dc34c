//! Metadata in TIFF files: the descriptive tags of the first IFD, its EXIF and GPS sub-IFDs, and the XMP, ICC,
//! IPTC and Photoshop tags.

use std::io::{Read, Seek};

use super::ifd::{
    self, read_header, read_ifd, write_ifd, write_tiff, Entry, Ifd, Reader, EXIF_IFD,
};
use super::{photoshop_for_output, Metadata};

const XMP: u16 = 700;
const IPTC: u16 = 33723;
const PHOTOSHOP: u16 = 34377;
const ICC: u16 = 34675;
const MAKER_NOTE: u16 = 37500;
/// Resolution tags: the encoder writes placeholders (1 pixel per unit, no unit) that the input's values replace.
const RESOLUTION: [u16; 3] = [282, 283, 296];

/// Tags of a first IFD that describe the photo rather than how its pixels are stored. They are what a TIFF input
/// contributes to the EXIF block, and what an EXIF block's IFD0 contributes to a TIFF output.
fn descriptive(tag: u16) -> bool {
    match tag {
        // DocumentName, ImageDescription, Make, Model, Orientation, X/YResolution, PageName, ResolutionUnit,
        // Software, DateTime, Artist, HostComputer, WhitePoint, PrimaryChromaticities; Windows rating.
        269..=272
        | 274
        | 282
        | 283
        | 285
        | 296
        | 305
        | 306
        | 315
        | 316
        | 318
        | 319
        | 18246
        | 18249 => true,
        // Left out of the range below: IPTC, Photoshop, ICC (carried in their own fields), ImageLayer, Photoshop
        // layers (ImageSourceData) and GDAL statistics / no-data (they describe the uncorrected pixels).
        IPTC | PHOTOSHOP | ICC | 34732 | 37724 | 42112 | 42113 => false,
        // Copyright, TIFF/EP and EXIF tags, GeoTIFF georeferencing, the EXIF and GPS IFD pointers, Windows XP tags.
        33432..=42999 => true,
        _ => false,
    }
}

/// Read the metadata of a TIFF file: only its first IFD and what that points to are read.
pub(super) fn read(r: impl Read + Seek, meta: &mut Metadata) {
    let mut src = Reader { inner: r, base: 0 };
    let (order, at) = match read_header(&mut src) {
        Ok(h) => h,
        Err(e) => {
            meta.problems.push(format!("TIFF: {e}; metadata not read"));
            return;
        }
    };
    let keep = |depth: usize, tag: u16| {
        depth > 0 || descriptive(tag) || matches!(tag, XMP | IPTC | PHOTOSHOP | ICC)
    };
    let mut problems = Vec::new();
    let read = read_ifd(&mut src, order, at, &keep, &mut problems);
    meta.problems
        .extend(problems.into_iter().map(|p| format!("TIFF: {p}")));
    let mut ifd0 = match read {
        Ok((ifd0, _)) => ifd0,
        Err(e) => {
            meta.problems.push(format!("TIFF: {e}; metadata not read"));
            return;
        }
    };
    meta.xmp = ifd0.remove(XMP).map(|e| e.value);
    meta.icc = ifd0.remove(ICC).map(|e| e.value);
    meta.iptc = ifd0.remove(IPTC).map(|e| e.value);
    meta.photoshop = ifd0.remove(PHOTOSHOP).map(|e| e.value);
    if !ifd0.entries.is_empty() {
        match write_tiff(order, &ifd0) {
            Ok(blob) => meta.exif = Some(blob),
            Err(e) => meta.problems.push(format!("TIFF: EXIF tags not read: {e}")),
        }
    }
}

/// The descriptive tags of an EXIF block's IFD0, with its sub-IFDs, in byte order `order`.
fn exif_tags(blob: &[u8], order: ifd::Order, dropped: &mut Vec<String>) -> Result<Ifd, String> {
    let mut src: &[u8] = blob;
    let (from, at) = read_header(&mut src)?;
    let mut problems = Vec::new();
    let (mut tags, _) = read_ifd(
        &mut src,
        from,
        at,
        &|depth, tag| depth > 0 || descriptive(tag),
        &mut problems,
    )?;
    dropped.extend(problems.into_iter().map(|p| format!("EXIF {p}")));
    if from != order {
        tags.convert(from, order);
        let exif = tags
            .entries
            .iter_mut()
            .find(|e| e.tag == EXIF_IFD)
            .and_then(|e| e.sub.as_mut());
        if exif.and_then(|exif| exif.remove(MAKER_NOTE)).is_some() {
            dropped.push(
                "EXIF maker note is in the other byte order than the TIFF output and cannot be converted; not carried"
                    .into(),
            );
        }
    }
    Ok(tags)
}

/// Give `encoded` (a TIFF file with one image, as the `tiff` crate writes it) the metadata: a new first IFD is
/// appended, holding the encoder's tags plus the metadata tags, and the header is pointed at it.
pub(super) fn embed(meta: &Metadata, encoded: Vec<u8>, dropped: &mut Vec<String>) -> Vec<u8> {
    let Some((order, mut ifd0, next)) = reread(&encoded, dropped) else {
        return encoded;
    };
    let before = ifd0.clone();
    if let Some(blob) = &meta.exif {
        match exif_tags(blob, order, dropped) {
            Ok(tags) => {
                for e in tags.entries {
                    if before.get(e.tag).is_none() || RESOLUTION.contains(&e.tag) {
                        ifd0.set(e);
                    }
                }
            }
            Err(e) => dropped.push(format!("EXIF block not carried: {e}")),
        }
    }
    set_metadata_tags(&mut ifd0, meta);
    note_not_carried(meta, dropped);
    if ifd0 == before {
        return encoded;
    }
    let mut out = encoded;
    let len = out.len();
    match write_ifd(&mut out, order, &ifd0, next) {
        Ok(at) => {
            out[4..8].copy_from_slice(&order.put_u32(at));
            out
        }
        Err(e) => {
            out.truncate(len);
            dropped.push(format!("metadata not carried: {e}"));
            out
        }
    }
}

/// The byte order, first IFD and next-IFD offset of the encoder's output, read back. `None` (the reason in
/// `dropped`) when it cannot be read whole.
fn reread(encoded: &[u8], dropped: &mut Vec<String>) -> Option<(ifd::Order, Ifd, u32)> {
    let mut src: &[u8] = encoded;
    let mut problems = Vec::new();
    let parsed = read_header(&mut src).and_then(|(order, at)| {
        let (ifd0, next) = read_ifd(&mut src, order, at, &|_, _| true, &mut problems)?;
        Ok((order, ifd0, next))
    });
    match parsed {
        Ok(p) if problems.is_empty() => Some(p),
        Ok(_) => {
            dropped.push(format!(
                "output TIFF could not be re-read ({}); metadata not carried",
                problems.join("; ")
            ));
            None
        }
        Err(e) => {
            dropped.push(format!(
                "output TIFF could not be re-read ({e}); metadata not carried"
            ));
            None
        }
    }
}

/// Set the XMP, ICC, IPTC and Photoshop tags of `ifd0` from `meta` (those it has).
fn set_metadata_tags(ifd0: &mut Ifd, meta: &Metadata) {
    let photoshop = meta.photoshop.as_deref().map(photoshop_for_output);
    // IPTC as Photoshop and ExifTool write it: LONGs holding the record's bytes, zero-padded to a multiple of 4.
    let iptc = meta.iptc.as_ref().map(|v| {
        let mut v = v.clone();
        v.resize(v.len().div_ceil(4) * 4, 0);
        v
    });
    for (tag, kind, value) in [
        (XMP, 1, &meta.xmp),
        (ICC, 7, &meta.icc),
        (IPTC, ifd::TYPE_LONG, &iptc),
        (PHOTOSHOP, 1, &photoshop),
    ] {
        if let Some(v) = value {
            ifd0.set(Entry::new(tag, kind, v.clone()));
        }
    }
}

/// Say in `dropped` which parts of `meta` a TIFF file has no place for: text entries, PNG chunks, extended XMP.
fn note_not_carried(meta: &Metadata, dropped: &mut Vec<String>) {
    if !meta.text.is_empty() {
        dropped.push(format!(
            "{} text entr{} (PNG text, JPEG comments) have no place in TIFF; not carried",
            meta.text.len(),
            if meta.text.len() == 1 { "y" } else { "ies" }
        ));
    }
    if !meta.png_chunks.is_empty() {
        dropped.push("PNG colour and pixel-size chunks have no place in TIFF; not carried".into());
    }
    if !meta.xmp_extension.is_empty() {
        dropped.push("JPEG extended-XMP segments have no place in TIFF; not carried".into());
    }
}
