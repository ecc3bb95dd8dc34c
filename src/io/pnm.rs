//! Image frames back to back on a byte stream (`--survey -`, `--out -`), as `ffmpeg -f image2pipe` reads and
//! writes them: binary PPM (`P6`) and PGM (`P5`) with 8- or 16-bit samples, and PNG.
//!
//! A stream has no index, so each frame is delimited by its own structure: a PNM frame by its header (magic,
//! width, height, maxval, with `#` comments allowed between the fields) followed by exactly
//! `width × height × channels × (1 or 2)` bytes; a PNG frame by its signature and chunks up to `IEND`. A frame
//! cut short by the end of the stream is an error naming the frame; the frames before it are not affected.
//! After a frame that cannot be delimited (bad magic, bad header) the stream cannot be resynchronised and
//! reading stops there.

use std::io::{BufRead, Read, Write};

use crate::io::{photo_from_dynamic, read_full};
use crate::method::raster::{Layout, Photo, Samples};

/// Container of a frame on the stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameFormat {
    /// Binary PGM/PPM (`P5`/`P6`).
    Pnm,
    /// PNG.
    Png,
}

impl FrameFormat {
    /// File name extension used for a frame of this format with `channels` channels.
    pub fn extension(self, channels: usize) -> &'static str {
        match (self, channels) {
            (FrameFormat::Png, _) => "png",
            (FrameFormat::Pnm, 1) => "pgm",
            (FrameFormat::Pnm, _) => "ppm",
        }
    }
}

/// One frame cut from the stream, not decoded yet.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawFrame {
    /// Which container the frame's bytes are in.
    pub format: FrameFormat,
    /// The frame's bytes, exactly as on the stream.
    pub bytes: Vec<u8>,
}

/// Name a frame gets in errors and in the report: `stdin frame 12` (0-based, the order on the stream).
pub fn frame_name(index: usize) -> String {
    format!("stdin frame {index}")
}

/// Read bytes until `buf` is full; returns how many were read (less only at the end of the stream).
/// Cuts frames off a byte stream.
pub struct FrameSplitter<R> {
    r: R,
    /// Frames cut so far.
    pub frames: usize,
    broken: bool,
    /// The last error left the stream at the start of the next frame (a frame passed over whole).
    resync: bool,
}

impl<R: BufRead> FrameSplitter<R> {
    /// A splitter reading frames from `r`.
    pub fn new(r: R) -> Self {
        FrameSplitter {
            r,
            frames: 0,
            broken: false,
            resync: false,
        }
    }

    /// The next frame, `None` at a clean end of the stream (between frames). An error means the stream cannot be
    /// read further (truncated or unrecognised frame); later calls return `None`.
    pub fn next_frame(&mut self) -> Option<std::result::Result<RawFrame, String>> {
        if self.broken {
            return None;
        }
        let r = self.read_frame();
        match &r {
            Ok(None) => return None,
            Ok(Some(_)) => self.frames += 1,
            Err(_) => {
                self.broken = !std::mem::take(&mut self.resync);
                self.frames += 1;
            }
        }
        r.transpose()
    }

    fn read_frame(&mut self) -> std::result::Result<Option<RawFrame>, String> {
        let io = |e: std::io::Error| format!("cannot read the stream: {e}");
        let mut magic = [0u8; 2];
        match read_full(&mut self.r, &mut magic).map_err(io)? {
            0 => return Ok(None),
            1 => return Err("truncated: the stream ends 1 byte into the frame".into()),
            _ => {}
        }
        match &magic {
            b"P5" | b"P6" => self.read_pnm(magic).map(Some),
            [0x89, b'P'] => self.read_png(magic).map(Some),
            b"P1" | b"P2" | b"P3" | b"P4" | b"P7" => Err(format!(
                "{} PNM frames are not supported: use binary PGM (P5) or PPM (P6), e.g. ffmpeg -vcodec ppm",
                String::from_utf8_lossy(&magic)
            )),
            _ => Err(format!(
                "not a PPM, PGM or PNG frame (starts with bytes {:02x} {:02x}); frames must be back to back, \
                 e.g. ffmpeg -f image2pipe -vcodec ppm",
                magic[0], magic[1]
            )),
        }
    }

    fn byte(&mut self) -> std::result::Result<Option<u8>, String> {
        let mut b = [0u8; 1];
        match read_full(&mut self.r, &mut b) {
            Ok(0) => Ok(None),
            Ok(_) => Ok(Some(b[0])),
            Err(e) => Err(format!("cannot read the stream: {e}")),
        }
    }

    /// One header field of a PNM frame (a decimal number), skipping whitespace and `#` comments before it.
    /// Consumes the single whitespace byte after it, which is part of `bytes`.
    fn pnm_field(&mut self, bytes: &mut Vec<u8>, what: &str) -> std::result::Result<u64, String> {
        let eof = || format!("truncated: the stream ends in the PNM header (before the {what})");
        let mut c = self.byte()?.ok_or_else(eof)?;
        loop {
            bytes.push(c);
            if c == b'#' {
                while c != b'\n' && c != b'\r' {
                    c = self.byte()?.ok_or_else(eof)?;
                    bytes.push(c);
                }
            } else if !c.is_ascii_whitespace() {
                break;
            }
            c = self.byte()?.ok_or_else(eof)?;
        }
        let mut v: u64 = 0;
        loop {
            if !c.is_ascii_digit() {
                return Err(format!(
                    "bad PNM header: the {what} is not a number (byte {c:#04x})"
                ));
            }
            v = v
                .checked_mul(10)
                .and_then(|v| v.checked_add((c - b'0') as u64))
                .ok_or_else(|| format!("bad PNM header: the {what} is too large"))?;
            c = self.byte()?.ok_or_else(eof)?;
            bytes.push(c);
            if c.is_ascii_whitespace() {
                return Ok(v);
            }
        }
    }

    fn read_pnm(&mut self, magic: [u8; 2]) -> std::result::Result<RawFrame, String> {
        let mut bytes = magic.to_vec();
        let width = self.pnm_field(&mut bytes, "width")?;
        let height = self.pnm_field(&mut bytes, "height")?;
        let maxval = self.pnm_field(&mut bytes, "maxval")?;
        if width == 0 || height == 0 {
            return Err(format!("bad PNM header: size {width}x{height}"));
        }
        if !(1..=65535).contains(&maxval) {
            return Err(format!(
                "bad PNM header: maxval {maxval} (must be 1 to 65535)"
            ));
        }
        let channels = if &magic == b"P6" { 3 } else { 1 };
        let per_sample = if maxval < 256 { 1 } else { 2 };
        let data = width
            .checked_mul(height)
            .and_then(|v| v.checked_mul(channels * per_sample))
            .ok_or_else(|| format!("bad PNM header: size {width}x{height} is too large"))?;
        if width.saturating_mul(height) > crate::io::MAX_PIXELS {
            // The header is well formed, so the frame's extent is known: pass over its pixel data without
            // holding it, and the frames after it are read as usual.
            let skipped = std::io::copy(&mut (&mut self.r).take(data), &mut std::io::sink())
                .map_err(|e| format!("cannot read the stream: {e}"))?;
            self.resync = skipped == data;
            return Err(format!(
                "PNM header declares {width}x{height} pixels, more than the {} abysslight decodes; frame skipped{}",
                crate::io::MAX_PIXELS,
                if self.resync {
                    ""
                } else {
                    " (and the stream ends inside its pixel data)"
                }
            ));
        }
        let data = data as usize;
        let head = bytes.len();
        // Grown as the data arrives: a stream that ends early never makes us hold what its header promised.
        let got = (&mut self.r)
            .take(data as u64)
            .read_to_end(&mut bytes)
            .map_err(|e| format!("cannot read the stream: {e}"))?;
        debug_assert_eq!(bytes.len(), head + got);
        if got < data {
            return Err(format!(
                "truncated: the stream ends {got} bytes into the {data} bytes of pixel data of a {width}x{height} \
                 {} frame",
                String::from_utf8_lossy(&magic)
            ));
        }
        Ok(RawFrame {
            format: FrameFormat::Pnm,
            bytes,
        })
    }

    fn read_png(&mut self, magic: [u8; 2]) -> std::result::Result<RawFrame, String> {
        const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
        let mut bytes = magic.to_vec();
        bytes.resize(8, 0);
        let got = read_full(&mut self.r, &mut bytes[2..]).map_err(|e| e.to_string())?;
        if got < 6 {
            return Err("truncated: the stream ends in the PNG signature".into());
        }
        if bytes[..8] != SIGNATURE {
            return Err("bad PNG signature".into());
        }
        // What the frame may hold, from its IHDR (the first chunk): 8 bytes a pixel (raw 16-bit RGBA, more than
        // any compressed PNG needs) and 64 MiB of other chunks. A frame beyond it is passed over, not held.
        let mut budget: u64 = 64 << 20;
        let mut chunks = 0;
        loop {
            let (kind, len) = self.png_chunk_head(&mut bytes, chunks)?;
            if bytes.len() as u64 + len + 4 > budget {
                return Err(self.pass_over_png(kind, len, chunks, budget));
            }
            let body = bytes.len();
            // Grown as the data arrives: a stream that ends early never makes us hold what a chunk declares.
            let got = (&mut self.r)
                .take(len + 4)
                .read_to_end(&mut bytes)
                .map_err(|e| e.to_string())?;
            if (got as u64) < len + 4 {
                return Err(format!(
                    "truncated: the stream ends inside PNG chunk {chunks} ({}, {got} of {} bytes)",
                    String::from_utf8_lossy(&kind),
                    len + 4
                ));
            }
            if chunks == 0 && &kind == b"IHDR" && len >= 8 {
                let dim =
                    |at: usize| u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap()) as u64;
                let pixels = dim(body) * dim(body + 4);
                // Too many pixels: the decoder refuses the frame by its header; nothing more is needed for that.
                budget += if pixels > crate::io::MAX_PIXELS {
                    0
                } else {
                    pixels * 8
                };
            }
            chunks += 1;
            if &kind == b"IEND" {
                return Ok(RawFrame {
                    format: FrameFormat::Png,
                    bytes,
                });
            }
        }
    }

    /// Read a PNG chunk's length and type (appended to `bytes`); an error for a bad one.
    fn png_chunk_head(
        &mut self,
        bytes: &mut Vec<u8>,
        chunks: usize,
    ) -> std::result::Result<([u8; 4], u64), String> {
        let mut head = [0u8; 8];
        let got = read_full(&mut self.r, &mut head).map_err(|e| e.to_string())?;
        if got < 8 {
            return Err(format!(
                "truncated: the stream ends in PNG chunk {chunks} (before IEND)"
            ));
        }
        bytes.extend_from_slice(&head);
        let len = u32::from_be_bytes(head[..4].try_into().unwrap()) as u64;
        let kind: [u8; 4] = head[4..].try_into().unwrap();
        if len > 0x7fff_ffff || !kind.iter().all(|b| b.is_ascii_alphabetic()) {
            return Err(format!(
                "bad PNG chunk {chunks} (type {:?}, length {len})",
                String::from_utf8_lossy(&kind)
            ));
        }
        Ok((kind, len))
    }

    /// A PNG frame larger than its header allows: read over the rest of it (chunk `chunks`, of type `kind` and
    /// `len` bytes, and those after it up to IEND) without holding it, so that the frames after it are read.
    fn pass_over_png(&mut self, kind: [u8; 4], len: u64, chunks: usize, budget: u64) -> String {
        let skip = |n: u64, r: &mut R| {
            std::io::copy(&mut r.take(n), &mut std::io::sink()).is_ok_and(|k| k == n)
        };
        let (mut kind, mut len, mut whole) = (kind, len, true);
        loop {
            if !skip(len + 4, &mut self.r) {
                whole = false;
                break;
            }
            if &kind == b"IEND" {
                break;
            }
            let mut head = Vec::new();
            match self.png_chunk_head(&mut head, chunks) {
                Ok((k, l)) => (kind, len) = (k, l),
                Err(_) => {
                    whole = false;
                    break;
                }
            }
        }
        self.resync = whole;
        format!(
            "PNG frame larger than its header allows ({budget} bytes; chunk {chunks} declares {len} bytes): frame \
             skipped{}",
            if whole { "" } else { " (and the stream ends or breaks inside it)" }
        )
    }
}

/// Decode a binary PGM/PPM frame. Maxval 255 and 65535 give 8- and 16-bit samples as they are; other maxvals
/// are scaled to the full 8- (maxval < 256) or 16-bit range.
pub fn decode_pnm(bytes: &[u8]) -> std::result::Result<Photo, String> {
    let mut s = FrameSplitter::new(bytes);
    let mut magic = [0u8; 2];
    read_full(&mut s.r, &mut magic).map_err(|e| e.to_string())?;
    let mut head = Vec::new();
    let width = s.pnm_field(&mut head, "width")? as usize;
    let height = s.pnm_field(&mut head, "height")? as usize;
    let maxval = s.pnm_field(&mut head, "maxval")? as u32;
    let channels = if &magic == b"P6" { 3 } else { 1 };
    let data = s.r;
    if (width as u64).saturating_mul(height as u64) > crate::io::MAX_PIXELS
        || width == 0
        || height == 0
    {
        return Err(format!("PNM header declares {width}x{height} pixels"));
    }
    let count = width * height * channels;
    let samples = if maxval < 256 {
        let v = data.get(..count).ok_or("truncated pixel data")?;
        Samples::U8(if maxval == 255 {
            v.to_vec()
        } else {
            v.iter()
                .map(|&x| ((x.min(maxval as u8) as u32 * 255 + maxval / 2) / maxval) as u8)
                .collect()
        })
    } else {
        let v = data.get(..count * 2).ok_or("truncated pixel data")?;
        Samples::U16(
            v.chunks_exact(2)
                .map(|b| {
                    let x = u16::from_be_bytes([b[0], b[1]]) as u32;
                    if maxval == 65535 {
                        x as u16
                    } else {
                        ((x.min(maxval) * 65535 + maxval / 2) / maxval) as u16
                    }
                })
                .collect(),
        )
    };
    Ok(Photo {
        layout: Layout {
            width,
            height,
            channels,
        },
        samples,
        alpha: None,
    })
}

/// Decode a frame cut by [`FrameSplitter`].
pub fn decode_frame(frame: &RawFrame) -> std::result::Result<Photo, String> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        decode_frame_unguarded(frame)
    }))
    .unwrap_or_else(|_| Err("the decoder failed on this frame; skipped".into()))
}

pub(crate) fn decode_frame_unguarded(frame: &RawFrame) -> std::result::Result<Photo, String> {
    match frame.format {
        FrameFormat::Pnm => decode_pnm(&frame.bytes),
        FrameFormat::Png => {
            let mut reader = image::ImageReader::with_format(
                std::io::Cursor::new(&frame.bytes),
                image::ImageFormat::Png,
            );
            reader.limits(crate::io::decode_limits());
            let img = reader.decode().map_err(|e| e.to_string())?;
            photo_from_dynamic(img)
        }
    }
}

/// Write `photo` as a binary PGM (grey) or PPM (RGB) with maxval 255 or 65535 (alpha is dropped).
pub fn write_pnm(photo: &Photo, w: &mut impl Write) -> std::io::Result<()> {
    let l = photo.layout;
    let magic = if l.channels == 1 { "P5" } else { "P6" };
    match &photo.samples {
        Samples::U8(v) => {
            write!(w, "{magic}\n{} {}\n255\n", l.width, l.height)?;
            w.write_all(v)
        }
        Samples::U16(v) => {
            write!(w, "{magic}\n{} {}\n65535\n", l.width, l.height)?;
            let mut buf = Vec::with_capacity(v.len() * 2);
            for s in v {
                buf.extend_from_slice(&s.to_be_bytes());
            }
            w.write_all(&buf)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn split(bytes: &[u8]) -> Vec<std::result::Result<RawFrame, String>> {
        let mut s = FrameSplitter::new(bytes);
        std::iter::from_fn(|| s.next_frame()).collect()
    }

    #[test]
    fn pnm_headers_with_comments_and_both_depths() {
        let mut stream = Vec::new();
        stream.extend_from_slice(b"P6\n# made by hand\n2 1\n# another\n255\n");
        stream.extend_from_slice(&[1, 2, 3, 4, 5, 6]);
        stream.extend_from_slice(b"P5 2\t2 65535\r");
        stream.extend_from_slice(&[0, 1, 0, 2, 255, 255, 1, 0]);
        let frames = split(&stream);
        assert_eq!(frames.len(), 2);
        let a = decode_frame(frames[0].as_ref().unwrap()).unwrap();
        assert_eq!(
            (a.layout.width, a.layout.height, a.layout.channels),
            (2, 1, 3)
        );
        assert_eq!(a.samples, Samples::U8(vec![1, 2, 3, 4, 5, 6]));
        let b = decode_frame(frames[1].as_ref().unwrap()).unwrap();
        assert_eq!(b.layout.channels, 1);
        assert_eq!(b.samples, Samples::U16(vec![1, 2, 65535, 256]));
        let mut back = Vec::new();
        write_pnm(&b, &mut back).unwrap();
        let again = split(&back);
        assert_eq!(decode_frame(again[0].as_ref().unwrap()).unwrap(), b);
    }

    #[test]
    fn odd_maxval_is_scaled() {
        let frames = split(b"P5 2 1 15\n\x00\x0f");
        let p = decode_frame(frames[0].as_ref().unwrap()).unwrap();
        assert_eq!(p.samples, Samples::U8(vec![0, 255]));
    }

    #[test]
    fn truncated_pnm_is_an_error_after_the_good_frames() {
        let mut stream = b"P5 1 1 255\n\x07".to_vec();
        stream.extend_from_slice(b"P5 2 2 255\n\x01\x02");
        let frames = split(&stream);
        assert_eq!(frames.len(), 2);
        assert!(frames[0].is_ok());
        let e = frames[1].as_ref().unwrap_err();
        assert!(
            e.contains("truncated") && e.contains("2 bytes into the 4"),
            "{e}"
        );
        let e = split(b"P6 4 ").pop().unwrap().unwrap_err();
        assert!(e.contains("PNM header"), "{e}");
    }

    #[test]
    fn garbage_and_ascii_pnm_are_refused() {
        let e = split(b"GIF89a").pop().unwrap().unwrap_err();
        assert!(e.contains("not a PPM, PGM or PNG"), "{e}");
        let e = split(b"P3 1 1 255 0 0 0").pop().unwrap().unwrap_err();
        assert!(e.contains("P3"), "{e}");
        assert!(split(b"").is_empty());
    }

    #[test]
    fn huge_pnm_header_is_one_failed_frame_not_an_abort() {
        // The header of issue 13 alone: one failed frame, nothing allocated for it.
        let r = split(b"P5 1000000 1000000 255\n");
        assert_eq!(r.len(), 1);
        let e = r[0].as_ref().unwrap_err();
        assert!(e.contains("1000000x1000000"), "{e}");
        // A declared size just over the limit, with its data present (generated, not held), followed by a good
        // frame: the good frame is still read.
        let (w, h) = (1u64 << 14, (1u64 << 14) + 1);
        let stream = std::io::Cursor::new(format!("P5 {w} {h} 255\n").into_bytes())
            .chain(std::io::repeat(7).take(w * h))
            .chain(std::io::Cursor::new(b"P5 2 1 255\n\x01\x02".to_vec()));
        let mut s = FrameSplitter::new(std::io::BufReader::new(stream));
        let r: Vec<_> = std::iter::from_fn(|| s.next_frame()).collect();
        assert_eq!(r.len(), 2);
        assert!(r[0].as_ref().unwrap_err().contains("more than"));
        let good = decode_frame(r[1].as_ref().unwrap()).unwrap();
        assert_eq!(good.samples, Samples::U8(vec![1, 2]));
    }

    fn png(w: u32, h: u32, sixteen: bool) -> Vec<u8> {
        let mut out = Vec::new();
        let img: image::DynamicImage = if sixteen {
            image::ImageBuffer::<image::Rgb<u16>, _>::from_fn(w, h, |x, y| {
                image::Rgb([x as u16 * 1000, y as u16 * 3000, 65535])
            })
            .into()
        } else {
            image::ImageBuffer::<image::Luma<u8>, _>::from_fn(w, h, |x, y| {
                image::Luma([(x * 10 + y) as u8])
            })
            .into()
        };
        img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
            .unwrap();
        out
    }

    #[test]
    fn png_chunks_are_walked_to_iend() {
        let (a, b) = (png(5, 4, false), png(3, 3, true));
        let mut stream = a.clone();
        stream.extend_from_slice(&b);
        stream.extend_from_slice(b"P5 1 1 255\n\x09");
        let frames = split(&stream);
        assert_eq!(frames.len(), 3);
        assert_eq!(frames[0].as_ref().unwrap().bytes, a);
        assert_eq!(frames[1].as_ref().unwrap().bytes, b);
        let p = decode_frame(frames[1].as_ref().unwrap()).unwrap();
        assert_eq!(p.layout.channels, 3);
        assert!(matches!(p.samples, Samples::U16(_)));
        assert_eq!(frames[2].as_ref().unwrap().format, FrameFormat::Pnm);
        let cut = &b[..b.len() - 6];
        let e = split(cut).pop().unwrap().unwrap_err();
        assert!(e.contains("truncated") && e.contains("IEND"), "{e}");
    }
}
