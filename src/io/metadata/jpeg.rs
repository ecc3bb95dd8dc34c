//! Metadata in JPEG files: the marker segments before the first scan.

use std::io::Read;

use super::{exif_for_output, photoshop_for_output, Metadata, Text};

const EXIF_ID: &[u8] = b"Exif\0\0";
const XMP_ID: &[u8] = b"http://ns.adobe.com/xap/1.0/\0";
const XMP_EXT_ID: &[u8] = b"http://ns.adobe.com/xmp/extension/\0";
const ICC_ID: &[u8] = b"ICC_PROFILE\0";
const PHOTOSHOP_ID: &[u8] = b"Photoshop 3.0\0";

/// Largest payload of one marker segment (its 16-bit length counts itself).
const MAX_PAYLOAD: usize = 65533;

const APP1: u8 = 0xe1;
const APP2: u8 = 0xe2;
const APP13: u8 = 0xed;
const COM: u8 = 0xfe;
const SOS: u8 = 0xda;
const EOI: u8 = 0xd9;

/// Text from bytes: UTF-8 when valid, else Latin-1 (what JPEG comments and PNG `tEXt` hold).
pub(super) fn decode_text(bytes: &[u8]) -> String {
    match std::str::from_utf8(bytes) {
        Ok(s) => s.to_owned(),
        Err(_) => bytes.iter().map(|&b| b as char).collect(),
    }
}

/// Read the segments of a JPEG stream up to its first scan.
pub(super) fn read(mut r: impl Read, meta: &mut Metadata) {
    let mut soi = [0u8; 2];
    if r.read_exact(&mut soi).is_err() || soi != [0xff, 0xd8] {
        meta.problems.push("JPEG: no start-of-image marker".into());
        return;
    }
    let mut pieces = Pieces::default();
    while let Some(marker) = read_marker(&mut r, meta) {
        match marker {
            SOS | EOI | 0xff => break,
            0x01 | 0xd0..=0xd8 => continue,
            _ => {}
        }
        let Some(payload) = read_payload(&mut r, marker, meta) else {
            break;
        };
        take_segment(marker, &payload, meta, &mut pieces);
    }
    pieces.finish(meta);
}

/// The next marker: `0xff`, any fill bytes, then the marker code (`0xff` when the stream ends inside the fill).
/// `None` (the reason in `problems`) when the stream ends or holds stray bytes where a marker belongs.
fn read_marker(r: &mut impl Read, meta: &mut Metadata) -> Option<u8> {
    let mut b = [0u8; 1];
    if r.read_exact(&mut b).is_err() {
        meta.problems
            .push("JPEG: file ends before the image data".into());
        return None;
    }
    if b[0] != 0xff {
        meta.problems
            .push("JPEG: stray bytes between segments; stopped reading metadata there".into());
        return None;
    }
    let mut marker = 0xff;
    while marker == 0xff {
        if r.read_exact(&mut b).is_err() {
            break;
        }
        marker = b[0];
    }
    Some(marker)
}

/// The payload of the segment with marker `marker`: its 16-bit length, then that many bytes less two. `None` (the
/// reason in `problems`) when the length is invalid or the payload cut off.
fn read_payload(r: &mut impl Read, marker: u8, meta: &mut Metadata) -> Option<Vec<u8>> {
    let mut len = [0u8; 2];
    if r.read_exact(&mut len).is_err() || u16::from_be_bytes(len) < 2 {
        meta.problems
            .push(format!("JPEG: segment {marker:#04x} has no valid length"));
        return None;
    }
    let mut payload = vec![0u8; u16::from_be_bytes(len) as usize - 2];
    if r.read_exact(&mut payload).is_err() {
        meta.problems
            .push(format!("JPEG: segment {marker:#04x} is cut off"));
        return None;
    }
    Some(payload)
}

/// Metadata that comes in pieces over several segments, put together after the last one.
#[derive(Default)]
struct Pieces {
    /// ICC profile chunks: (sequence number, count, bytes).
    icc_chunks: Vec<(u8, u8, Vec<u8>)>,
    /// Photoshop resource blocks, in file order.
    photoshop: Vec<u8>,
}

/// Take what one segment holds: EXIF, XMP and comments into `meta`, ICC and Photoshop pieces into `pieces`; other
/// segments are skipped.
fn take_segment(marker: u8, payload: &[u8], meta: &mut Metadata, pieces: &mut Pieces) {
    match marker {
        APP1 if payload.starts_with(EXIF_ID) => {
            if meta.exif.is_none() {
                meta.exif = Some(payload[EXIF_ID.len()..].to_vec());
            } else {
                meta.problems
                    .push("JPEG: a second EXIF segment was ignored".into());
            }
        }
        APP1 if payload.starts_with(XMP_ID) => {
            if meta.xmp.is_none() {
                meta.xmp = Some(payload[XMP_ID.len()..].to_vec());
            } else {
                meta.problems
                    .push("JPEG: a second XMP segment was ignored".into());
            }
        }
        APP1 if payload.starts_with(XMP_EXT_ID) => meta
            .xmp_extension
            .push(payload[XMP_EXT_ID.len()..].to_vec()),
        APP2 if payload.starts_with(ICC_ID) && payload.len() >= ICC_ID.len() + 2 => {
            let at = ICC_ID.len();
            pieces
                .icc_chunks
                .push((payload[at], payload[at + 1], payload[at + 2..].to_vec()));
        }
        APP13 if payload.starts_with(PHOTOSHOP_ID) => pieces
            .photoshop
            .extend_from_slice(&payload[PHOTOSHOP_ID.len()..]),
        COM => meta.text.push(Text {
            keyword: "Comment".into(),
            text: decode_text(payload),
        }),
        _ => {}
    }
}

impl Pieces {
    /// Put the pieces into `meta`: the ICC profile when its chunks are complete and consistent (else a problem),
    /// the Photoshop blocks when there are any.
    fn finish(self, meta: &mut Metadata) {
        let Pieces {
            mut icc_chunks,
            photoshop,
        } = self;
        if !icc_chunks.is_empty() {
            icc_chunks.sort_by_key(|c| c.0);
            let count = icc_chunks[0].1 as usize;
            let complete = count == icc_chunks.len()
                && icc_chunks
                    .iter()
                    .enumerate()
                    .all(|(i, c)| c.0 as usize == i + 1 && c.1 as usize == count);
            if complete {
                meta.icc = Some(icc_chunks.into_iter().flat_map(|c| c.2).collect());
            } else {
                meta.problems.push(format!(
                    "JPEG: ICC profile chunks are incomplete or inconsistent ({} found, numbered {:?}); profile left out",
                    icc_chunks.len(),
                    icc_chunks.iter().map(|c| (c.0, c.1)).collect::<Vec<_>>()
                ));
            }
        }
        if !photoshop.is_empty() {
            meta.photoshop = Some(photoshop);
        }
    }
}

fn segment(out: &mut Vec<u8>, marker: u8, parts: &[&[u8]]) {
    let len: usize = parts.iter().map(|p| p.len()).sum();
    debug_assert!(len <= MAX_PAYLOAD);
    out.extend_from_slice(&[0xff, marker]);
    out.extend_from_slice(&((len + 2) as u16).to_be_bytes());
    for p in parts {
        out.extend_from_slice(p);
    }
}

/// The metadata segments, in the order they go into the file.
fn segments(meta: &Metadata, dropped: &mut Vec<String>) -> Vec<u8> {
    let mut out = Vec::new();
    if let Some(exif) = &meta.exif {
        match exif_for_output(exif) {
            Ok(e) if EXIF_ID.len() + e.len() <= MAX_PAYLOAD => segment(&mut out, APP1, &[EXIF_ID, &e]),
            Ok(e) => dropped.push(format!(
                "EXIF block of {} bytes is larger than a JPEG APP1 segment holds ({} bytes); not carried",
                e.len(),
                MAX_PAYLOAD - EXIF_ID.len()
            )),
            Err(e) => dropped.push(format!("EXIF block not carried: {e}")),
        }
    }
    if let Some(xmp) = &meta.xmp {
        if XMP_ID.len() + xmp.len() <= MAX_PAYLOAD {
            segment(&mut out, APP1, &[XMP_ID, xmp]);
        } else {
            dropped.push(format!(
                "XMP packet of {} bytes is larger than a JPEG APP1 segment holds ({} bytes); not carried",
                xmp.len(),
                MAX_PAYLOAD - XMP_ID.len()
            ));
        }
    }
    for ext in &meta.xmp_extension {
        if XMP_EXT_ID.len() + ext.len() <= MAX_PAYLOAD {
            segment(&mut out, APP1, &[XMP_EXT_ID, ext]);
        }
    }
    if let Some(icc) = &meta.icc {
        let chunk = MAX_PAYLOAD - ICC_ID.len() - 2;
        let count = icc.len().div_ceil(chunk).max(1);
        if count <= 255 {
            for (i, part) in icc.chunks(chunk).enumerate() {
                segment(&mut out, APP2, &[ICC_ID, &[i as u8 + 1, count as u8], part]);
            }
        } else {
            dropped.push(format!(
                "ICC profile of {} bytes is too large for JPEG; not carried",
                icc.len()
            ));
        }
    }
    if let Some(ps) = &meta.photoshop {
        for part in photoshop_for_output(ps).chunks(MAX_PAYLOAD - PHOTOSHOP_ID.len()) {
            segment(&mut out, APP13, &[PHOTOSHOP_ID, part]);
        }
    }
    for t in &meta.text {
        let text = if t.keyword == "Comment" {
            t.text.clone()
        } else {
            format!("{}: {}", t.keyword, t.text)
        };
        if text.len() <= MAX_PAYLOAD {
            segment(&mut out, COM, &[text.as_bytes()]);
        } else {
            dropped.push(format!(
                "comment of {} bytes is too long for a JPEG COM segment; not carried",
                text.len()
            ));
        }
    }
    if meta.iptc.is_some() && meta.photoshop.is_none() {
        dropped.push(
            "IPTC record outside Photoshop resources has no place in JPEG; not carried".into(),
        );
    }
    if !meta.png_chunks.is_empty() {
        dropped.push("PNG colour and pixel-size chunks have no place in JPEG; not carried".into());
    }
    out
}

/// Insert the metadata segments into `encoded` (a JPEG file), after the start-of-image marker and any APP0 (JFIF)
/// segment.
pub(super) fn embed(meta: &Metadata, encoded: Vec<u8>, dropped: &mut Vec<String>) -> Vec<u8> {
    if !encoded.starts_with(&[0xff, 0xd8]) {
        dropped.push("output is not a JPEG stream; metadata not carried".into());
        return encoded;
    }
    let mut at = 2;
    while encoded.len() >= at + 4 && encoded[at] == 0xff && encoded[at + 1] == 0xe0 {
        at += 2 + u16::from_be_bytes([encoded[at + 2], encoded[at + 3]]) as usize;
    }
    let at = at.min(encoded.len());
    let segs = segments(meta, dropped);
    let mut out = Vec::with_capacity(encoded.len() + segs.len());
    out.extend_from_slice(&encoded[..at]);
    out.extend_from_slice(&segs);
    out.extend_from_slice(&encoded[at..]);
    out
}
