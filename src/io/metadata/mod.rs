//! Metadata carried from each input photo into its corrected output: EXIF (camera, lens, exposure, timestamps,
//! GPS and navigation tags, orientation), XMP, the ICC colour profile, and what else the format stores beside the
//! pixels and still describes the corrected photo.
//!
//! [`Metadata::read`] reads it from a JPEG, PNG or TIFF file without decoding pixels; [`Metadata::embed`] puts it
//! into an encoded output; [`write_carrying`] does both for one photo of the pipeline.
//!
//! What is carried, by format (output format = input format):
//!
//! | | JPEG | PNG | TIFF |
//! |---|---|---|---|
//! | EXIF (IFD0, EXIF, GPS and interoperability IFDs) | APP1 `Exif`, bytes as stored | `eXIf` chunk, bytes as stored | tags of IFD0 and its EXIF/GPS sub-IFDs, rewritten |
//! | XMP | APP1 packet and extended-XMP segments | `iTXt` `XML:com.adobe.xmp` | tag 700 |
//! | ICC profile | APP2 `ICC_PROFILE` (any number of segments) | `iCCP` | tag 34675 |
//! | IPTC / Photoshop resources | APP13 `Photoshop 3.0` | — | tags 33723 and 34377 |
//! | comments, text | COM segments | `tEXt`, `zTXt`, `iTXt` (keyword and text) | ImageDescription, Artist, Copyright, ... (descriptive IFD0 tags) |
//! | colour space, pixel size | ICC; EXIF resolution | `gAMA`, `cHRM`, `sRGB`, `cICP`, `pHYs` | ICC; resolution tags |
//! | georeferencing | — | — | GeoTIFF tags (same pixel grid) |
//!
//! Deliberately not carried:
//! - the EXIF thumbnail (IFD1) and Photoshop's thumbnail resources: they are small copies of the *uncorrected*
//!   photo, and file browsers that show them would show the lighting abysslight removed. EXIF blocks keep their
//!   bytes otherwise (maker notes whose internal offsets count from the start of the block stay valid);
//! - in TIFF outputs, the tags that describe how the pixels are stored (size, bits, compression, strips, ...):
//!   those of the output are written by the encoder. A maker note moves in a TIFF output, and maker notes with
//!   absolute offsets (e.g. Canon's) may not be readable afterwards; when the input's byte order differs from the
//!   output's, it is left out;
//! - JPEG segments that describe the input's coding or other images (JFIF, whose pixel density the encoder writes
//!   afresh; Adobe APP14; MPF and other APPn),
//!   PNG `tIME` (it is the modification time) and `sBIT` (the significant bits of the input's samples), TIFF pages
//!   after the first, GDAL statistics and Photoshop layers (they describe the uncorrected pixels).
//!
//! Orientation: photos are decoded and corrected in stored (sensor) order, never rotated, and the EXIF (and XMP)
//! orientation tag is carried unchanged, so a viewer turns the output exactly as it turns the input.
//!
//! Limits of the formats: a JPEG APP1 segment holds at most 65 533 bytes, so an EXIF block or XMP packet larger
//! than that is not carried into a JPEG (reported by [`Metadata::embed`]).

pub(crate) mod ifd;
mod jpeg;
pub(crate) mod png;
#[cfg(test)]
mod round_trip;
mod tiff;

use std::fs::File;
use std::io::{BufReader, Seek, SeekFrom};
use std::path::Path;

use image::ImageFormat;

use crate::error::{Error, Result};
use crate::io::{self, EncodeSettings};
use crate::method::raster::Photo;

/// A text entry: a PNG text chunk, or a JPEG comment (keyword `Comment`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Text {
    /// The chunk's keyword (`Comment` for a JPEG comment).
    pub keyword: String,
    /// The text itself.
    pub text: String,
}

/// The metadata of one photo. Fields are `None` or empty when the photo has none.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Metadata {
    /// EXIF: a TIFF structure (starting `II*\0` or `MM\0*`) whose IFD0 holds camera, time and orientation tags and
    /// points to the EXIF and GPS IFDs. From JPEG and PNG inputs, the bytes as stored (no `Exif\0\0` prefix); from
    /// TIFF inputs, assembled from the file's descriptive tags and sub-IFDs.
    pub exif: Option<Vec<u8>>,
    /// XMP packet (UTF-8 XML).
    pub xmp: Option<Vec<u8>>,
    /// JPEG extended-XMP segments (the part after the `http://ns.adobe.com/xmp/extension/\0` identifier), as stored.
    pub xmp_extension: Vec<Vec<u8>>,
    /// ICC colour profile.
    pub icc: Option<Vec<u8>>,
    /// Photoshop image resources (JPEG APP13 `Photoshop 3.0`, TIFF tag 34377), which hold IPTC in JPEG files.
    pub photoshop: Option<Vec<u8>>,
    /// IPTC-IIM record (TIFF tag 33723).
    pub iptc: Option<Vec<u8>>,
    /// Text: PNG text chunks and JPEG comments.
    pub text: Vec<Text>,
    /// PNG chunks carried as stored: colour space (`gAMA`, `cHRM`, `sRGB`, `cICP`) and pixel size (`pHYs`).
    pub png_chunks: Vec<([u8; 4], Vec<u8>)>,
    /// What could not be read (malformed or cut-off blocks). Reading goes on past them.
    pub problems: Vec<String>,
}

/// Container format of a file, from its first bytes.
fn sniff(head: &[u8]) -> Option<ImageFormat> {
    if head.starts_with(&[0xff, 0xd8]) {
        Some(ImageFormat::Jpeg)
    } else if head.starts_with(b"\x89PNG\r\n\x1a\n") {
        Some(ImageFormat::Png)
    } else if [b"II\x2a\x00", b"MM\x00\x2a", b"II\x2b\x00", b"MM\x00\x2b"]
        .iter()
        .any(|m| head.starts_with(*m))
    {
        Some(ImageFormat::Tiff)
    } else {
        None
    }
}

impl Metadata {
    /// Read the metadata of a JPEG, PNG or TIFF file (recognised by its first bytes). Pixels are not decoded; only
    /// the blocks before the image data (JPEG), the chunks other than `IDAT` (PNG) or the first IFD (TIFF) are read.
    /// A malformed or cut-off block is not an error: what could be read is returned, and the rest is described in
    /// [`Metadata::problems`]. Errors: the file cannot be opened, or is not JPEG, PNG or TIFF.
    pub fn read(path: &Path) -> Result<Metadata> {
        let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
        let mut head = [0u8; 8];
        let n = crate::io::read_full(&mut file, &mut head).map_err(|e| Error::io(path, e))?;
        let format = sniff(&head[..n]).ok_or_else(|| Error::Decode {
            path: path.to_owned(),
            reason: "not a JPEG, PNG or TIFF file (reading metadata)".into(),
        })?;
        file.seek(SeekFrom::Start(0))
            .map_err(|e| Error::io(path, e))?;
        let mut meta = Metadata::default();
        match format {
            ImageFormat::Jpeg => jpeg::read(BufReader::new(file), &mut meta),
            ImageFormat::Png => png::read(file, &mut meta),
            _ => tiff::read(BufReader::new(file), &mut meta),
        }
        Ok(meta)
    }

    /// Read metadata from a file held in memory (as [`Metadata::read`]).
    pub fn from_bytes(bytes: &[u8]) -> Option<Metadata> {
        let mut meta = Metadata::default();
        match sniff(bytes)? {
            ImageFormat::Jpeg => jpeg::read(bytes, &mut meta),
            ImageFormat::Png => png::read(std::io::Cursor::new(bytes), &mut meta),
            _ => tiff::read(std::io::Cursor::new(bytes), &mut meta),
        }
        Some(meta)
    }

    /// True when there is nothing to carry.
    pub fn is_empty(&self) -> bool {
        self.exif.is_none()
            && self.xmp.is_none()
            && self.xmp_extension.is_empty()
            && self.icc.is_none()
            && self.photoshop.is_none()
            && self.iptc.is_none()
            && self.text.is_empty()
            && self.png_chunks.is_empty()
    }

    /// Drop the ICC profile when it does not describe an output with `channels` colour channels (a CMYK or
    /// grey profile on an RGB output, an RGB profile on a grey one, or no valid ICC header at all): a viewer
    /// would interpret the pixels with the wrong colour space. Returns why it was dropped.
    pub fn drop_mismatched_icc(&mut self, channels: usize) -> Option<String> {
        let icc = self.icc.as_deref()?;
        let want: &[u8; 4] = if channels == 1 { b"GRAY" } else { b"RGB " };
        let why = match icc_colour_space(icc) {
            None => "the ICC profile has no valid header".to_string(),
            Some(space) if &space == want => return None,
            Some(space) => format!(
                "the ICC profile is for {:?} data, the output is {}",
                String::from_utf8_lossy(&space).trim_end(),
                if channels == 1 { "grey" } else { "RGB" }
            ),
        };
        self.icc = None;
        Some(format!("{why}; profile dropped"))
    }

    /// The EXIF orientation (1–8), if the EXIF block has one.
    pub fn orientation(&self) -> Option<u16> {
        let blob = self.exif.as_deref()?;
        let mut src: &[u8] = blob;
        let (order, at) = ifd::read_header(&mut src).ok()?;
        let (ifd0, _) = ifd::read_ifd(
            &mut src,
            order,
            at,
            &|d, t| d == 0 && t == 274,
            &mut Vec::new(),
        )
        .ok()?;
        ifd0.get(274)?.uint(order).map(|v| v as u16)
    }

    /// When the photo was taken, in seconds since 1970-01-01 00:00 UTC: EXIF `DateTimeOriginal` (else IFD0's
    /// `DateTime`) with `SubSecTimeOriginal`, less `OffsetTimeOriginal` where the camera wrote its time zone (a
    /// time without one is taken as UTC). `None` without such a tag or with one that does not read as a time.
    pub fn time_taken(&self) -> Option<f64> {
        const DATE_TIME: u16 = 306;
        const DATE_TIME_ORIGINAL: u16 = 36867;
        const OFFSET_TIME_ORIGINAL: u16 = 36881;
        const SUB_SEC_TIME_ORIGINAL: u16 = 37521;
        let blob = self.exif.as_deref()?;
        let mut src: &[u8] = blob;
        let (order, at) = ifd::read_header(&mut src).ok()?;
        let wanted = [
            DATE_TIME,
            ifd::EXIF_IFD,
            DATE_TIME_ORIGINAL,
            OFFSET_TIME_ORIGINAL,
            SUB_SEC_TIME_ORIGINAL,
        ];
        let (ifd0, _) = ifd::read_ifd(
            &mut src,
            order,
            at,
            &|d, t| d <= 1 && wanted.contains(&t),
            &mut Vec::new(),
        )
        .ok()?;
        let text = |ifd: &ifd::Ifd, tag: u16| {
            let v = &ifd.get(tag)?.value;
            let v = v.split(|&b| b == 0).next().unwrap_or(v);
            Some(String::from_utf8_lossy(v).trim().to_string())
        };
        let exif = ifd0.get(ifd::EXIF_IFD).and_then(|e| e.sub.as_ref());
        let (time, sub, offset) = match exif.and_then(|e| text(e, DATE_TIME_ORIGINAL)) {
            Some(t) => {
                let e = exif?;
                (
                    t,
                    text(e, SUB_SEC_TIME_ORIGINAL),
                    text(e, OFFSET_TIME_ORIGINAL),
                )
            }
            None => (text(&ifd0, DATE_TIME)?, None, None),
        };
        let mut seconds = crate::io::navigation::parse_time(&time)?;
        if let Some(sub) = sub.filter(|s| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit())) {
            seconds += format!("0.{sub}").parse::<f64>().ok()?;
        }
        if let Some(offset) = offset {
            seconds -= crate::io::navigation::parse_offset(&offset)?;
        }
        Some(seconds)
    }

    /// Put this metadata into `encoded`, a complete file in `format` (JPEG, PNG or TIFF) as abysslight's encoders
    /// write it. Returns the new file and what could not be carried (each a short sentence). Never fails: what
    /// does not fit is left out and reported.
    pub fn embed(&self, format: ImageFormat, encoded: Vec<u8>) -> (Vec<u8>, Vec<String>) {
        let mut dropped = Vec::new();
        let bytes = match format {
            ImageFormat::Jpeg => jpeg::embed(self, encoded, &mut dropped),
            ImageFormat::Png => png::embed(self, encoded, &mut dropped),
            ImageFormat::Tiff => tiff::embed(self, encoded, &mut dropped),
            other => {
                dropped.push(format!("{other:?} outputs carry no metadata"));
                encoded
            }
        };
        (bytes, dropped)
    }
}

/// The data colour space of an ICC profile (header bytes 16–19, e.g. `RGB `, `GRAY`, `CMYK`), when the profile
/// has a valid header (at least 128 bytes, signature `acsp` at byte 36).
pub fn icc_colour_space(icc: &[u8]) -> Option<[u8; 4]> {
    if icc.len() < 128 || &icc[36..40] != b"acsp" {
        return None;
    }
    icc[16..20].try_into().ok()
}

/// The EXIF block as it goes into a JPEG or PNG output: without the thumbnail (IFD1), which shows the uncorrected
/// photo. IFD0's link to IFD1 is cut, and the thumbnail's bytes are cut off when they end the block (as cameras
/// write it); all other bytes stay where they are. `Err` when the block is not a TIFF structure.
fn exif_for_output(blob: &[u8]) -> std::result::Result<Vec<u8>, String> {
    let cut = || "EXIF block is cut off".to_string();
    let mut src: &[u8] = blob;
    let (order, at) = ifd::read_header(&mut src)?;
    let at = at as usize;
    let n = blob.get(at..at + 2).ok_or_else(cut)?;
    let link = at + 2 + 12 * order.u16(n) as usize;
    let ifd1 = order.u32(blob.get(link..link + 4).ok_or_else(cut)?);
    let mut out = blob.to_vec();
    if ifd1 == 0 {
        return Ok(out);
    }
    out[link..link + 4].fill(0);
    let keep = |_: usize, t: u16| t == 0x0201 || t == 0x0202;
    if let Ok((thumb, _)) = ifd::read_ifd(&mut src, order, ifd1, &keep, &mut Vec::new()) {
        if let (Some(start), Some(len)) = (
            thumb.get(0x0201).and_then(|e| e.uint(order)),
            thumb.get(0x0202).and_then(|e| e.uint(order)),
        ) {
            let (start, end) = (start as usize, start as usize + len as usize);
            // Cut the thumbnail off when it ends the block (allowing one byte of padding), as cameras write it;
            // elsewhere, blank it, so that no copy of the uncorrected photo stays in the file.
            if start > link + 4 && end <= blob.len() {
                if end + 1 >= blob.len() {
                    out.truncate(start);
                } else {
                    out[start..end].fill(0);
                }
            }
        }
    }
    Ok(out)
}

/// Photoshop image resources as they go into an output: without the thumbnail resources (1033, 1036), which
/// show the uncorrected photo. Resources are `8BIM`, id, padded Pascal name, size, padded data. A block that does not
/// parse is kept as it is.
fn photoshop_for_output(irb: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(irb.len());
    let mut at = 0;
    while at < irb.len() {
        let Some(head) = irb.get(at..at + 7) else {
            return irb.to_vec();
        };
        let id = u16::from_be_bytes([head[4], head[5]]);
        let name = 1 + head[6] as usize;
        let size_at = at + 6 + name + name % 2;
        let Some(size) = irb.get(size_at..size_at + 4) else {
            return irb.to_vec();
        };
        let size = u32::from_be_bytes([size[0], size[1], size[2], size[3]]) as usize;
        let end = size_at + 4 + size + size % 2;
        if !matches!(&head[..4], b"8BIM" | b"MeSa" | b"PHUT" | b"AgHg" | b"DCSR")
            || end > irb.len() + size % 2
        {
            return irb.to_vec();
        }
        let end = end.min(irb.len());
        if id != 1033 && id != 1036 {
            out.extend_from_slice(&irb[at..end]);
        }
        at = end;
    }
    out
}

/// Write `photo` to `output` atomically (as [`io::write_atomic`]) with the metadata of `input` (see the module
/// documentation). Metadata never fails the photo: what cannot be read from `input` or carried into `output` is
/// told to `warn`, in one message naming the input, and the photo is written without it.
pub fn write_carrying(
    photo: &Photo,
    input: &Path,
    jpeg_head: Option<&[u8]>,
    output: &Path,
    settings: EncodeSettings,
    warn: &dyn Fn(&str),
) -> Result<()> {
    // `jpeg_head`: the input's bytes up to its first scan when it is a JPEG and the caller read them already
    // (`crate::io::jpeg::read_head`), which is all its metadata.
    let read = match jpeg_head {
        Some(h) => Ok(Metadata::from_bytes(h).unwrap_or_default()),
        None => Metadata::read(input),
    };
    let (meta, mut notes) = match read {
        Ok(mut m) => {
            let problems = std::mem::take(&mut m.problems);
            (m, problems)
        }
        Err(e) => (Metadata::default(), vec![e.to_string()]),
    };
    let mut meta = meta;
    notes.extend(meta.drop_mismatched_icc(photo.layout.channels));
    notes.extend(io::write_atomic_with_metadata(
        photo, output, settings, &meta,
    )?);
    if !notes.is_empty() {
        warn(&format!(
            "{}: metadata not fully carried into {}: {}",
            input.display(),
            output.display(),
            notes.join("; ")
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ifd::{Entry, Ifd, Order};

    fn icc_profile(space: &[u8; 4]) -> Vec<u8> {
        let mut p = vec![0u8; 132];
        p[..4].copy_from_slice(&132u32.to_be_bytes());
        p[16..20].copy_from_slice(space);
        p[36..40].copy_from_slice(b"acsp");
        p
    }

    #[test]
    fn icc_profiles_of_another_colour_space_are_dropped() {
        for (space, channels, kept) in [
            (b"RGB ", 3, true),
            (b"GRAY", 1, true),
            (b"CMYK", 3, false),
            (b"GRAY", 3, false),
            (b"RGB ", 1, false),
            (b"Lab ", 3, false),
        ] {
            let mut m = Metadata {
                icc: Some(icc_profile(space)),
                ..Metadata::default()
            };
            let note = m.drop_mismatched_icc(channels);
            assert_eq!(m.icc.is_some(), kept, "{space:?} on {channels}");
            assert_eq!(note.is_none(), kept);
            if let Some(n) = note {
                assert!(n.contains("dropped"), "{n}");
            }
        }
        let mut junk = Metadata {
            icc: Some(b"not a profile".to_vec()),
            ..Metadata::default()
        };
        assert!(junk.drop_mismatched_icc(3).is_some() && junk.icc.is_none());
        assert!(Metadata::default().drop_mismatched_icc(3).is_none());
    }

    /// An EXIF block with IFD0 (Model), IFD1 and a thumbnail at its end, laid out as cameras do.
    fn exif_with_thumbnail(order: Order) -> (Vec<u8>, usize) {
        let mut ifd0 = Ifd::default();
        ifd0.set(Entry::new(272, 2, b"SeaCam\0".to_vec()));
        let mut out = ifd::write_tiff(order, &ifd0).unwrap();
        let link = 8 + 2 + 12;
        let thumb = b"\xff\xd8thumbnail-jpeg-bytes\xff\xd9".to_vec();
        // IFD1 with JPEGInterchangeFormat / Length; the thumbnail follows it.
        if out.len() % 2 == 1 {
            out.push(0);
        }
        let ifd1_at = out.len();
        let thumb_at = ifd1_at + 2 + 2 * 12 + 4;
        let mut ifd1 = Ifd::default();
        ifd1.set(Entry::new(
            0x0201,
            4,
            order.put_u32(thumb_at as u32).to_vec(),
        ));
        ifd1.set(Entry::new(
            0x0202,
            4,
            order.put_u32(thumb.len() as u32).to_vec(),
        ));
        let at = ifd::write_ifd(&mut out, order, &ifd1, 0).unwrap() as usize;
        assert_eq!(at, ifd1_at);
        assert_eq!(out.len(), thumb_at);
        out.extend_from_slice(&thumb);
        out[link..link + 4].copy_from_slice(&order.put_u32(ifd1_at as u32));
        (out, thumb_at)
    }

    #[test]
    fn thumbnail_is_unlinked_and_cut_off() {
        for order in [Order::Little, Order::Big] {
            let (blob, thumb_at) = exif_with_thumbnail(order);
            let out = exif_for_output(&blob).unwrap();
            assert_eq!(out.len(), thumb_at);
            assert!(!out.windows(2).any(|w| w == [0xff, 0xd8]));
            // IFD0 is unchanged apart from its link, which is now 0.
            assert_eq!(out[..8 + 2 + 12], blob[..8 + 2 + 12]);
            assert_eq!(out[22..26], [0, 0, 0, 0]);
            // kamadak-exif (an independent reader) finds the model and no thumbnail.
            let exif = exif::Reader::new().read_raw(out).unwrap();
            assert!(exif
                .get_field(exif::Tag::Model, exif::In::PRIMARY)
                .is_some());
            assert!(exif.fields().all(|f| f.ifd_num == exif::In::PRIMARY));
        }
        // A thumbnail that does not end the block is blanked in place.
        let (mut blob, thumb_at) = exif_with_thumbnail(Order::Little);
        let thumb_end = blob.len();
        blob.extend_from_slice(b"trailing data");
        let out = exif_for_output(&blob).unwrap();
        assert_eq!(out.len(), blob.len());
        assert!(out[thumb_at..thumb_end].iter().all(|&b| b == 0));
        assert_eq!(out[thumb_end..], blob[thumb_end..]);
        // A block without IFD1 is unchanged; a block that is not TIFF is refused.
        let plain = ifd::write_tiff(Order::Little, &Ifd::default()).unwrap();
        assert_eq!(exif_for_output(&plain).unwrap(), plain);
        assert!(exif_for_output(b"Exif\0\0II*\0").is_err());
        assert!(exif_for_output(b"II*\0\x08\0\0\0\x05").is_err());
    }

    /// One Photoshop image resource: `8BIM`, id, Pascal name padded to even length, size, data padded to even.
    pub(super) fn resource(id: u16, name: &str, data: &[u8]) -> Vec<u8> {
        let mut r = b"8BIM".to_vec();
        r.extend_from_slice(&id.to_be_bytes());
        r.push(name.len() as u8);
        r.extend_from_slice(name.as_bytes());
        if name.len().is_multiple_of(2) {
            r.push(0);
        }
        r.extend_from_slice(&(data.len() as u32).to_be_bytes());
        r.extend_from_slice(data);
        if data.len() % 2 == 1 {
            r.push(0);
        }
        r
    }

    #[test]
    fn photoshop_thumbnails_are_taken_out() {
        let iptc = resource(0x0404, "", b"\x1c\x02\x05\x00\x04Dive");
        let res = resource(0x03ed, "res", &[0, 72, 0, 0, 0, 1, 0, 1]);
        let thumb = resource(0x040c, "", b"\xff\xd8uncorrected\xff\xd9");
        let old_thumb = resource(0x0409, "t", b"\xff\xd8old\xff\xd9");
        let irb = [iptc.clone(), thumb, res.clone(), old_thumb].concat();
        assert_eq!(photoshop_for_output(&irb), [iptc.clone(), res].concat());
        // A block that does not parse is kept as it is.
        let bad = [&iptc[..], b"junk"].concat();
        assert_eq!(photoshop_for_output(&bad), bad);
    }

    #[test]
    fn unknown_and_missing_files_are_errors_naming_the_file() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("notes.jpg");
        std::fs::write(&p, b"hello").unwrap();
        let e = Metadata::read(&p).unwrap_err().to_string();
        assert!(
            e.contains("notes.jpg") && e.contains("not a JPEG, PNG or TIFF"),
            "{e}"
        );
        let e = Metadata::read(&d.path().join("gone.png"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("gone.png"), "{e}");
    }
}
