//! Finding, decoding and writing photos. Outputs are written atomically: a temp file in the target folder, synced,
//! then renamed over the final name, so an interrupted run never leaves a half-written image.

pub(crate) mod buffers;
#[cfg(test)]
mod fuzz;
pub(crate) mod gate;
pub(crate) mod jpeg;
pub(crate) mod jpeg_check;
pub(crate) mod mask;
pub(crate) mod metadata;
pub mod navigation;
pub(crate) mod paths;
pub(crate) mod pnm;
pub(crate) mod scatter;
pub(crate) mod transfer;
pub(crate) mod whole;

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use image::{DynamicImage, ImageFormat};

use crate::error::{Error, Result};
// The readers' parts that the command, the Python binding and the project's tests reach: public for them, not part
// of the documented interface (which is `decode`, `find_photos`, `encode_to` and `write_atomic`).
#[doc(hidden)]
pub use crate::io::jpeg::{parse as jpeg_coding, JpegCoding};
#[doc(hidden)]
pub use crate::io::jpeg_check::{check as check_jpeg, BlockMeans};
#[doc(hidden)]
pub use crate::io::paths::check_outputs;
#[doc(hidden)]
pub use crate::io::pnm::{decode_frame, FrameSplitter};
use crate::method::raster::{Layout, Photo, Raster, Samples};

/// Chroma subsampling of a colour JPEG: how many luma samples share one chroma sample, across and down.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum Subsampling {
    /// No subsampling.
    #[default]
    #[serde(rename = "444")]
    S444,
    /// Half the chroma columns (most video, many cameras).
    #[serde(rename = "422")]
    S422,
    /// Half the chroma columns and rows (most cameras).
    #[serde(rename = "420")]
    S420,
    /// Half the chroma rows (read from inputs only).
    #[serde(rename = "440")]
    S440,
    /// A quarter of the chroma columns (read from inputs only).
    #[serde(rename = "411")]
    S411,
}

/// File name extensions taken as photos (case-insensitive).
pub(crate) const PHOTO_EXTENSIONS: &[&str] = &["jpg", "jpeg", "png", "tif", "tiff"];

/// Name of the folder inside the output folder that holds the report and the estimates.
pub(crate) const WORK_DIR: &str = "_abysslight";

/// A photo found in an input folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Entry {
    /// Full path.
    pub path: PathBuf,
    /// Path relative to the input folder (mirrored into the output folder).
    pub relative: PathBuf,
}

/// What a folder scan found.
#[derive(Debug, Default)]
pub struct Found {
    /// Photos, in natural order of their relative paths (`img2` before `img10`).
    pub photos: Vec<Entry>,
    /// Files passed over because their name does not end in a photo extension.
    pub ignored: Vec<PathBuf>,
    /// Entries that could not be taken (unreadable folder, symbolic link loop, dangling link, a name that is not
    /// valid UTF-8, a link into the output folder), each named with its reason. A run reports them as failed
    /// files (exit 1); they never stop the scan.
    pub skipped: Vec<Skipped>,
}

/// An entry of a folder scan that could not be taken.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skipped {
    /// The entry's path; a name that is not valid UTF-8 is shown with U+FFFD in place of the bad bytes.
    pub path: PathBuf,
    /// Why it was skipped, in words for the log.
    pub reason: String,
}

impl Skipped {
    /// As an error naming the entry (for the run report).
    pub fn to_error(&self) -> Error {
        Error::io(&self.path, std::io::Error::other(self.reason.clone()))
    }
}

fn is_photo_name(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| PHOTO_EXTENSIONS.iter().any(|p| e.eq_ignore_ascii_case(p)))
}

fn lossy(p: &Path) -> PathBuf {
    PathBuf::from(p.to_string_lossy().into_owned())
}

/// Find the photos below `dir`, recursively, in natural order. Hidden files and folders (names starting with `.`)
/// and abysslight's own `_abysslight` folders are skipped. Only `dir` itself missing or not being a folder is an
/// error; every entry below it that cannot be taken is a [`Skipped`] entry in [`Found::skipped`].
pub fn find_photos(dir: &Path) -> Result<Found> {
    find_photos_excluding(dir, &[])
}

/// Record a folder-walk entry as skipped (with `reason`), and do not descend into it if it is a folder.
fn skip_entry(
    found: &mut Found,
    walker: &mut walkdir::FilterEntry<walkdir::IntoIter, impl FnMut(&walkdir::DirEntry) -> bool>,
    item: &walkdir::DirEntry,
    reason: &str,
) {
    found.skipped.push(Skipped {
        path: lossy(item.path()),
        reason: reason.into(),
    });
    if item.file_type().is_dir() {
        walker.skip_current_dir();
    }
}

/// Why a walk error skips its entry, for the report.
fn walk_error_reason(e: &walkdir::Error) -> String {
    if let Some(ancestor) = e.loop_ancestor() {
        format!(
            "symbolic link loop (leads back to {}); skipped",
            ancestor.display()
        )
    } else if e
        .io_error()
        .is_some_and(|i| i.kind() == std::io::ErrorKind::NotFound)
    {
        "dangling symbolic link (its target does not exist); skipped".to_string()
    } else {
        format!(
            "{}; skipped",
            e.io_error()
                .map_or_else(|| e.to_string(), |i| i.to_string())
        )
    }
}

/// Why an entry of the walk is skipped (a link into `exclude`, a name not UTF-8), if it is.
fn skip_reason(item: &walkdir::DirEntry, dir: &Path, exclude: &[&Path]) -> Option<&'static str> {
    if item.path_is_symlink()
        && exclude
            .iter()
            .any(|x| crate::io::paths::is_within(item.path(), x))
    {
        return Some(
            "a symbolic link into the output folder: outputs are never read back as inputs; skipped",
        );
    }
    if item.depth() > 0
        && item
            .path()
            .strip_prefix(dir)
            .ok()
            .and_then(|r| r.to_str())
            .is_none()
    {
        return Some(
            "name is not valid UTF-8 (cannot be named in the report or mirrored reliably); rename it; skipped",
        );
    }
    None
}

/// [`find_photos`], and entries reached through symbolic links that lead into one of `exclude` (the output
/// folder: a survey link pointing at `--out` must not read old outputs back as photos) are skipped entries.
pub(crate) fn find_photos_excluding(dir: &Path, exclude: &[&Path]) -> Result<Found> {
    let meta = std::fs::metadata(dir).map_err(|e| Error::io(dir, e))?;
    if !meta.is_dir() {
        return Err(Error::Usage(format!("{}: not a folder", dir.display())));
    }
    let mut found = Found::default();
    let mut walker = walkdir::WalkDir::new(dir)
        .follow_links(true)
        .into_iter()
        .filter_entry(|e| {
            e.depth() == 0
                || !(e.file_name().to_string_lossy().starts_with('.') || e.file_name() == WORK_DIR)
        });
    while let Some(item) = walker.next() {
        let item = match item {
            Ok(i) => i,
            Err(e) => {
                let path = e.path().unwrap_or(dir);
                let reason = walk_error_reason(&e);
                found.skipped.push(Skipped {
                    path: lossy(path),
                    reason,
                });
                continue;
            }
        };
        if let Some(reason) = skip_reason(&item, dir, exclude) {
            skip_entry(&mut found, &mut walker, &item, reason);
            continue;
        }
        if !item.file_type().is_file() {
            continue;
        }
        let path = item.into_path();
        if is_photo_name(&path) {
            let relative = path.strip_prefix(dir).unwrap_or(&path).to_owned();
            found.photos.push(Entry { path, relative });
        } else {
            found.ignored.push(path);
        }
    }
    found
        .photos
        .sort_by(|a, b| alphanumeric_sort::compare_path(&a.relative, &b.relative));
    Ok(found)
}

/// Largest photo abysslight decodes, in pixels (2^28 = 268 MP, e.g. 16384 × 16384). A header declaring more is
/// an error before anything is allocated; the Python binding refuses larger arrays the same way.
pub const MAX_PIXELS: u64 = 1 << 28;

/// Longest side of a photo abysslight decodes, in pixels.
pub const MAX_SIDE: usize = 1 << 20;

/// Width and height from a photo's header, reading only the header.
pub(crate) fn header_size(path: &Path) -> Result<(usize, usize)> {
    let reader = image::ImageReader::open(path)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| Error::io(path, e))?;
    if reader.format() == Some(ImageFormat::Jpeg) {
        return jpeg_header_size(path);
    }
    let (w, h) = reader.into_dimensions().map_err(|e| Error::Decode {
        path: path.to_owned(),
        reason: e.to_string(),
    })?;
    Ok((w as usize, h as usize))
}

/// [`header_size`] of a JPEG: the marker segments up to the frame header, nothing after it.
fn jpeg_header_size(path: &Path) -> Result<(usize, usize)> {
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    crate::io::jpeg_check::dimensions(std::io::BufReader::new(file)).map_err(|reason| {
        Error::Decode {
            path: path.to_owned(),
            reason,
        }
    })
}

fn check_size(width: usize, height: usize) -> std::result::Result<(), String> {
    if width == 0 || height == 0 {
        return Err(format!("header declares an empty image ({width}x{height})"));
    }
    if (width as u64).saturating_mul(height as u64) > MAX_PIXELS {
        return Err(format!(
            "header declares {width}x{height} pixels, more than the {MAX_PIXELS} abysslight decodes (damaged or not a survey photo)"
        ));
    }
    Ok(())
}

#[doc(hidden)]
/// The mission's photo size chosen robustly: the size most of the first `sample` photos (header only) have; ties
/// go to the earlier photo. Photos whose header cannot be read do not vote. `None` when no header could be read.
/// One odd photo (a thumbnail sorting first) is then the only one of its size, and the only one skipped.
pub fn majority_size(photos: &[Entry], sample: usize) -> Option<(usize, usize)> {
    let mut votes: Vec<((usize, usize), usize)> = Vec::new();
    for e in photos.iter().take(sample) {
        let Ok(size) = header_size(&e.path) else {
            continue;
        };
        match votes.iter_mut().find(|(s, _)| *s == size) {
            Some((_, n)) => *n += 1,
            None => votes.push((size, 1)),
        }
    }
    // `max_by_key` keeps the last of equal maxima; iterate in reverse so that ties go to the earlier photo.
    votes.iter().rev().max_by_key(|(_, n)| *n).map(|(s, _)| *s)
}

#[doc(hidden)]
/// [`decode`], after checking the header against the size the mission's photos have (`expected`, when known):
/// a photo of another size is a mismatch error before it is decoded.
pub fn decode_expecting(path: &Path, expected: Option<(usize, usize)>) -> Result<Photo> {
    // A header that cannot be read: `decode` names what is wrong with the file.
    if let (Some(expected), Ok(got)) = (expected, header_size(path)) {
        if got != expected {
            return Err(size_mismatch(path, got, expected));
        }
    }
    decode(path)
}

/// The error for a photo whose header says `got` where the mission's photos are `expected` (width, height).
fn size_mismatch(path: &Path, got: (usize, usize), expected: (usize, usize)) -> Error {
    Error::Mismatch {
        path: path.to_owned(),
        reason: format!(
            "size {}x{} differs from the mission's {}x{}; skipped",
            got.0, got.1, expected.0, expected.1
        ),
    }
}

#[doc(hidden)]
/// The survey's look at a photo without decoding it: a baseline JPEG's 8×8 block means from its DC coefficients
/// ([`crate::io::jpeg_check::block_means`]), after the same header checks as [`decode_expecting`] and the same
/// completeness check as the decoder (whose verdict the decode of these bytes later in the run takes). `Ok(None)`:
/// not a JPEG, or one whose block means are not read this way (progressive, 12-bit, several scans, RGB or CMYK
/// components): decode it. `Err`: the photo the decode would refuse (too big, cut short, another size).
pub fn survey_block_means(
    path: &Path,
    expected: Option<(usize, usize)>,
) -> Result<Option<crate::io::jpeg_check::BlockMeans>> {
    guarded(path, || {
        let mut head = [0u8; 3];
        let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        if read_full(&mut file, &mut head).map_err(|e| Error::io(path, e))? < 3
            || head != [0xFF, 0xD8, 0xFF]
        {
            return Ok(None);
        }
        let decode_error = |reason: String| Error::Decode {
            path: path.to_owned(),
            reason,
        };
        let (w, h) = jpeg_header_size(path)?;
        check_size(w, h).map_err(decode_error)?;
        if let Some(e) = expected.filter(|&e| e != (w, h)) {
            return Err(size_mismatch(path, (w, h), e));
        }
        let data = read_within_budget(path, len, jpeg_byte_budget(w, h))?;
        crate::io::jpeg_check::block_means_remembered(&data)
            .map_err(|why| decode_error(format!("incomplete JPEG: {why}")))
    })
}

/// Read into `buf` until it is full or the reader ends (retrying interrupted reads); returns the bytes read.
pub(crate) fn read_full(r: &mut impl std::io::Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(k) => got += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// Image format of a path, from its extension.
pub(crate) fn format_of(path: &Path) -> Option<ImageFormat> {
    ImageFormat::from_path(path).ok()
}

/// Decode a photo into its native 8- or 16-bit samples. JPEGs are decoded strictly: damaged or truncated data is
/// an error (lenient decoders fill the missing part with grey). A decoder that panics costs this photo only: the
/// panic is caught and reported as this file's error.
pub fn decode(path: &Path) -> Result<Photo> {
    guarded(path, || decode_unguarded(path))
}

/// Run a decoder call, turning a panic inside it into a decode error naming `path`.
pub(crate) fn guarded<T>(path: &Path, f: impl FnOnce() -> Result<T>) -> Result<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|panic| {
        let what = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        Err(Error::Decode {
            path: path.to_owned(),
            reason: format!("the decoder failed on this file ({what}); skipped"),
        })
    })
}

fn decode_unguarded(path: &Path) -> Result<Photo> {
    let decode_error = |reason: String| Error::Decode {
        path: path.to_owned(),
        reason,
    };
    let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    if len == 0 {
        return Err(decode_error("empty file (0 bytes)".into()));
    }
    let mut head = [0u8; 32];
    let got = read_full(&mut file, &mut head).map_err(|e| Error::io(path, e))?;
    let format = image::guess_format(&head[..got])
        .ok()
        .or_else(|| format_of(path))
        .ok_or_else(|| decode_error("unknown image format".into()))?;
    // Header first: an absurd size is refused before the decoder allocates for it.
    let open = || -> Result<image::ImageReader<std::io::BufReader<File>>> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        let mut reader = image::ImageReader::with_format(std::io::BufReader::new(file), format);
        reader.limits(decode_limits());
        Ok(reader)
    };
    if format == ImageFormat::Jpeg {
        // A header the quick reader cannot take: the strict decoder names what is wrong (from the first 64 MiB).
        let (w, h) = jpeg_header_size(path).unwrap_or((0, 0));
        if w > 0 {
            check_size(w, h).map_err(decode_error)?;
        }
        let data = read_within_budget(path, len, jpeg_byte_budget(w, h))?;
        return decode_jpeg_strict(&data).map_err(|reason| {
            decode_error(if (data.len() as u64) < len {
                format!(
                    "{reason} (only the first {} of its {len} bytes were read: more than a {w}x{h} JPEG can \
                     need)",
                    data.len()
                )
            } else {
                reason
            })
        });
    }
    let (w, h) = open()?
        .into_dimensions()
        .map_err(|e| decode_error(e.to_string()))?;
    check_size(w as usize, h as usize).map_err(decode_error)?;
    // PNG and TIFF decoders read what their chunks and strips point to: a tail after the image is never read.
    let img = open()?.decode().map_err(|e| decode_error(e.to_string()))?;
    photo_from_dynamic(img).map_err(decode_error)
}

/// The most bytes a JPEG of `width × height` pixels is read from: 8 bytes a pixel (a JPEG at the highest quality
/// of pure noise takes about 3) plus 64 MiB of metadata segments. A file longer than that (a valid JPEG followed
/// by gigabytes of garbage) is read only that far: the decoder stops at the end marker anyway.
pub(crate) fn jpeg_byte_budget(width: usize, height: usize) -> u64 {
    (width as u64 * height as u64).saturating_mul(8) + (64 << 20)
}

/// The first `budget` bytes of the file at `path` (of `len` bytes).
fn read_within_budget(path: &Path, len: u64, budget: u64) -> Result<Vec<u8>> {
    use std::io::Read;
    let mut data = Vec::with_capacity(len.min(budget) as usize);
    File::open(path)
        .and_then(|f| f.take(budget).read_to_end(&mut data))
        .map_err(|e| Error::io(path, e))?;
    Ok(data)
}

/// Limits for the `image` decoders: the largest photo of [`MAX_PIXELS`] at 16-bit RGBA, and no side longer than
/// that many pixels.
pub(crate) fn decode_limits() -> image::Limits {
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_SIDE as u32);
    limits.max_image_height = Some(MAX_SIDE as u32);
    limits.max_alloc = Some(MAX_PIXELS * 8 + (64 << 20));
    limits
}

fn decode_jpeg_strict(data: &[u8]) -> std::result::Result<Photo, String> {
    // libjpeg-turbo when built in (its warnings, e.g. a truncated file, are errors); anything it refuses goes to
    // the strict Rust decoder, whose reason is the one reported.
    #[cfg(feature = "turbojpeg")]
    if let Ok((width, height, channels, pixels)) = crate::io::jpeg::turbo::decode(data) {
        return Ok(Photo {
            layout: Layout {
                width,
                height,
                channels,
            },
            samples: Samples::U8(pixels),
            alpha: None,
        });
    }
    decode_jpeg_zune(data, crate::io::buffers::take)
}

/// zune-jpeg's decode of `data` into a buffer from `buffer(len)` (the pool of src/io/buffers.rs: its old contents
/// are all overwritten).
fn decode_jpeg_zune(
    data: &[u8],
    buffer: impl FnOnce(usize) -> Vec<u8>,
) -> std::result::Result<Photo, String> {
    use zune_core::bytestream::ZCursor;
    use zune_core::colorspace::ColorSpace;
    use zune_core::options::DecoderOptions;
    let options = DecoderOptions::default()
        .set_strict_mode(true)
        .set_max_width(usize::MAX)
        .set_max_height(usize::MAX);
    let mut dec = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(data), options);
    let damaged = |e: zune_jpeg::errors::DecodeErrors| format!("damaged or truncated JPEG: {e}");
    dec.decode_headers().map_err(damaged)?;
    let (width, height) = dec.dimensions().ok_or("JPEG without dimensions")?;
    check_size(width, height)?;
    // zune-jpeg, even strict, fills data missing at the end with grey: check that it is all there first.
    let non_interleaved = crate::io::jpeg_check::check_all_remembered(data)
        .map_err(|why| format!("incomplete JPEG: {why}"))?;
    let grey = matches!(
        dec.input_colorspace(),
        Some(ColorSpace::Luma | ColorSpace::LumaA)
    );
    let channels = if grey { 1 } else { 3 };
    dec.set_options(dec.options().jpeg_set_out_colorspace(if grey {
        ColorSpace::Luma
    } else {
        ColorSpace::RGB
    }));
    // zune-jpeg decodes a non-interleaved JPEG with subsampled chroma (one scan per component) into garbage
    // (green); libjpeg-turbo's decoder, ported to Rust, reads it right (tests/integration/jpeg_reference.rs).
    let pixels = if non_interleaved {
        let format = if grey {
            libjpeg_turbo_rs::PixelFormat::Grayscale
        } else {
            libjpeg_turbo_rs::PixelFormat::Rgb
        };
        libjpeg_turbo_rs::decompress_to(data, format)
            .map_err(|e| format!("damaged JPEG: {e}"))?
            .data
    } else {
        // Into a buffer of an earlier photo of the same size when there is one (src/io/buffers.rs).
        let size = dec.output_buffer_size().ok_or("JPEG without dimensions")?;
        let mut pixels = buffer(size);
        if let Err(e) = dec.decode_into(&mut pixels) {
            return Err(damaged(e));
        }
        pixels
    };
    if pixels.len() != width * height * channels {
        return Err(format!(
            "damaged JPEG: decoded {} samples for {width}x{height}x{channels}",
            pixels.len()
        ));
    }
    Ok(Photo {
        layout: Layout {
            width,
            height,
            channels,
        },
        samples: Samples::U8(pixels),
        alpha: None,
    })
}

fn split_alpha<T: Copy>(v: Vec<T>, colour: usize) -> (Vec<T>, Vec<T>) {
    let stride = colour + 1;
    let mut c = Vec::with_capacity(v.len() / stride * colour);
    let mut a = Vec::with_capacity(v.len() / stride);
    for px in v.chunks_exact(stride) {
        c.extend_from_slice(&px[..colour]);
        a.push(px[colour]);
    }
    (c, a)
}

#[doc(hidden)]
/// Convert an `image` buffer into a [`Photo`] (colour samples plus optional alpha).
pub fn photo_from_dynamic(img: DynamicImage) -> std::result::Result<Photo, String> {
    let (width, height) = (img.width() as usize, img.height() as usize);
    let (channels, samples, alpha) = match img {
        DynamicImage::ImageLuma8(b) => (1, Samples::U8(b.into_raw()), None),
        DynamicImage::ImageRgb8(b) => (3, Samples::U8(b.into_raw()), None),
        DynamicImage::ImageLuma16(b) => (1, Samples::U16(b.into_raw()), None),
        DynamicImage::ImageRgb16(b) => (3, Samples::U16(b.into_raw()), None),
        DynamicImage::ImageLumaA8(b) => {
            let (c, a) = split_alpha(b.into_raw(), 1);
            (1, Samples::U8(c), Some(Samples::U8(a)))
        }
        DynamicImage::ImageRgba8(b) => {
            let (c, a) = split_alpha(b.into_raw(), 3);
            (3, Samples::U8(c), Some(Samples::U8(a)))
        }
        DynamicImage::ImageLumaA16(b) => {
            let (c, a) = split_alpha(b.into_raw(), 1);
            (1, Samples::U16(c), Some(Samples::U16(a)))
        }
        DynamicImage::ImageRgba16(b) => {
            let (c, a) = split_alpha(b.into_raw(), 3);
            (3, Samples::U16(c), Some(Samples::U16(a)))
        }
        other => {
            return Err(format!(
                "unsupported sample type {:?}: abysslight reads 8- and 16-bit grey or RGB photos",
                other.color()
            ))
        }
    };
    Ok(Photo {
        layout: Layout {
            width,
            height,
            channels,
        },
        samples,
        alpha,
    })
}

fn merge_alpha<T: Copy>(c: &[T], a: &[T], colour: usize) -> Vec<T> {
    let mut v = Vec::with_capacity(c.len() + a.len());
    for (px, &al) in c.chunks_exact(colour).zip(a) {
        v.extend_from_slice(px);
        v.push(al);
    }
    v
}

/// Convert a [`Photo`] back into an `image` buffer.
pub(crate) fn photo_to_dynamic(photo: &Photo) -> DynamicImage {
    let (w, h) = (photo.layout.width as u32, photo.layout.height as u32);
    let ch = photo.layout.channels;
    let bad = "photo buffer does not match its layout";
    match (&photo.samples, &photo.alpha, ch) {
        (Samples::U8(c), None, 1) => {
            DynamicImage::ImageLuma8(image::ImageBuffer::from_raw(w, h, c.clone()).expect(bad))
        }
        (Samples::U8(c), None, _) => {
            DynamicImage::ImageRgb8(image::ImageBuffer::from_raw(w, h, c.clone()).expect(bad))
        }
        (Samples::U16(c), None, 1) => {
            DynamicImage::ImageLuma16(image::ImageBuffer::from_raw(w, h, c.clone()).expect(bad))
        }
        (Samples::U16(c), None, _) => {
            DynamicImage::ImageRgb16(image::ImageBuffer::from_raw(w, h, c.clone()).expect(bad))
        }
        (Samples::U8(c), Some(Samples::U8(a)), 1) => DynamicImage::ImageLumaA8(
            image::ImageBuffer::from_raw(w, h, merge_alpha(c, a, 1)).expect(bad),
        ),
        (Samples::U8(c), Some(Samples::U8(a)), _) => DynamicImage::ImageRgba8(
            image::ImageBuffer::from_raw(w, h, merge_alpha(c, a, 3)).expect(bad),
        ),
        (Samples::U16(c), Some(Samples::U16(a)), 1) => DynamicImage::ImageLumaA16(
            image::ImageBuffer::from_raw(w, h, merge_alpha(c, a, 1)).expect(bad),
        ),
        (Samples::U16(c), Some(Samples::U16(a)), _) => DynamicImage::ImageRgba16(
            image::ImageBuffer::from_raw(w, h, merge_alpha(c, a, 3)).expect(bad),
        ),
        _ => unreachable!("alpha and colour samples always share a bit depth"),
    }
}

/// How hard the PNG writer compresses. Measured on 12 MP RGB 8-bit photos (docs/performance.md): `fast` writes
/// about 13× quicker than `default` for files about 29 % larger; `best` is slower still for almost nothing less.
/// Lossless either way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PngCompression {
    /// Fastest deflate (the default): about 13× quicker than `default`, files about 29 % larger.
    #[default]
    Fast,
    /// The encoder's balanced setting.
    Default,
    /// Strongest compression; slowest.
    Best,
}

impl std::str::FromStr for PngCompression {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "fast" => Ok(PngCompression::Fast),
            "default" => Ok(PngCompression::Default),
            "best" => Ok(PngCompression::Best),
            _ => Err(format!(
                "invalid PNG compression {s:?}: expected fast, default or best"
            )),
        }
    }
}

/// Encoder settings.
#[derive(Debug, Clone, Copy)]
pub struct EncodeSettings {
    /// JPEG quality, 1–100 (unless taken from a JPEG input, see `jpeg_like_input`).
    pub jpeg_quality: u8,
    /// PNG compression effort (TIFF is written uncompressed, the fastest).
    pub png_compression: PngCompression,
    /// JPEG chroma subsampling (unless taken from a JPEG input, see `jpeg_like_input`).
    pub jpeg_subsampling: Subsampling,
    /// Which JPEG settings a JPEG output takes from its JPEG input instead of the two fields above (see
    /// [`EncodeSettings::like`]); the fields stay what non-JPEG inputs get.
    pub jpeg_like_input: LikeInput,
}

/// JPEG settings taken from a JPEG input (issue 14): outputs about the size of their inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LikeInput {
    /// Quality estimated from the input's quantisation tables.
    pub quality: bool,
    /// The input's chroma subsampling.
    pub subsampling: bool,
}

impl Default for EncodeSettings {
    fn default() -> Self {
        EncodeSettings {
            jpeg_quality: 95,
            png_compression: PngCompression::Fast,
            jpeg_subsampling: Subsampling::S444,
            jpeg_like_input: LikeInput {
                quality: true,
                subsampling: true,
            },
        }
    }
}

impl EncodeSettings {
    /// The settings for the output of an input coded as `input` (`None`: not a JPEG, or unreadable headers):
    /// quality and subsampling taken from it where `jpeg_like_input` says so and it has them.
    pub fn like(self, input: Option<&crate::io::jpeg::JpegCoding>) -> Self {
        let mut s = self;
        if let Some(c) = input {
            if s.jpeg_like_input.quality {
                s.jpeg_quality = c.quality.unwrap_or(s.jpeg_quality);
            }
            if s.jpeg_like_input.subsampling {
                s.jpeg_subsampling = c.subsampling.unwrap_or(s.jpeg_subsampling);
            }
        }
        s
    }
}

/// Encode `photo` (8-bit samples) as JPEG into `w`.
fn encode_jpeg<W: Write>(
    photo: &Photo,
    settings: EncodeSettings,
    w: W,
) -> std::result::Result<(), String> {
    let l = photo.layout;
    let Samples::U8(c) = &photo.samples else {
        return Err("JPEG holds 8-bit samples only".into());
    };
    if l.width > u16::MAX as usize || l.height > u16::MAX as usize {
        return Err("too large for JPEG (65535 pixels a side at most)".into());
    }
    #[cfg(feature = "turbojpeg")]
    {
        let bytes = crate::io::jpeg::turbo::encode(
            c,
            l.width,
            l.height,
            l.channels,
            settings.jpeg_quality,
            settings.jpeg_subsampling,
        )?;
        let mut w = w;
        w.write_all(&bytes).map_err(|e| e.to_string())
    }
    #[cfg(not(feature = "turbojpeg"))]
    {
        let (format, subsampling) = if l.channels == 1 {
            (
                libjpeg_turbo_rs::PixelFormat::Grayscale,
                libjpeg_turbo_rs::Subsampling::S444,
            )
        } else {
            (
                libjpeg_turbo_rs::PixelFormat::Rgb,
                settings.jpeg_subsampling.rust_encoder(),
            )
        };
        let bytes = libjpeg_turbo_rs::compress(
            c,
            l.width,
            l.height,
            format,
            settings.jpeg_quality,
            subsampling,
        )
        .map_err(|e| e.to_string())?;
        let mut w = w;
        w.write_all(&bytes).map_err(|e| e.to_string())
    }
}

/// Encode `photo` in `format` into `w`.
pub fn encode_to<W: Write>(
    photo: &Photo,
    format: ImageFormat,
    settings: EncodeSettings,
    w: W,
) -> std::result::Result<(), String> {
    match format {
        ImageFormat::Jpeg => encode_jpeg(photo, settings, w),
        ImageFormat::Png => {
            let enc = image::codecs::png::PngEncoder::new_with_quality(
                w,
                match settings.png_compression {
                    PngCompression::Fast => image::codecs::png::CompressionType::Fast,
                    PngCompression::Default => image::codecs::png::CompressionType::Default,
                    PngCompression::Best => image::codecs::png::CompressionType::Best,
                },
                image::codecs::png::FilterType::Adaptive,
            );
            photo_to_dynamic(photo)
                .write_with_encoder(enc)
                .map_err(|e| e.to_string())
        }
        ImageFormat::Tiff => {
            let mut buf = std::io::Cursor::new(Vec::new());
            photo_to_dynamic(photo)
                .write_to(&mut buf, ImageFormat::Tiff)
                .map_err(|e| e.to_string())?;
            let mut w = w;
            w.write_all(buf.get_ref()).map_err(|e| e.to_string())
        }
        ImageFormat::Pnm => {
            let mut w = w;
            crate::io::pnm::write_pnm(photo, &mut w).map_err(|e| e.to_string())
        }
        other => Err(format!("writing {other:?} is not supported")),
    }
}

/// Write `photo` to `path` atomically in the format given by `path`'s extension: encode into a temp file in the
/// same folder, sync it, then rename it over `path`. Parent folders are created.
pub fn write_atomic(photo: &Photo, path: &Path, settings: EncodeSettings) -> Result<()> {
    let format = format_of(path).ok_or_else(|| Error::Encode {
        path: path.to_owned(),
        reason: "unknown output format (file name extension)".into(),
    })?;
    write_with(path, |w| {
        encode_to(photo, format, settings, w).map_err(|reason| Error::Encode {
            path: path.to_owned(),
            reason,
        })
    })
}

/// Like [`write_atomic`], and carries `meta` into the output as far as its format allows (see
/// [`crate::io::metadata`]). Returns what could not be carried, each a short sentence; that never fails the write.
pub(crate) fn write_atomic_with_metadata(
    photo: &Photo,
    path: &Path,
    settings: EncodeSettings,
    meta: &crate::io::metadata::Metadata,
) -> Result<Vec<String>> {
    if meta.is_empty() {
        return write_atomic(photo, path, settings).map(|()| Vec::new());
    }
    let format = format_of(path).ok_or_else(|| Error::Encode {
        path: path.to_owned(),
        reason: "unknown output format (file name extension)".into(),
    })?;
    let mut encoded = Vec::new();
    encode_to(photo, format, settings, &mut encoded).map_err(|reason| Error::Encode {
        path: path.to_owned(),
        reason,
    })?;
    let (bytes, dropped) = meta.embed(format, encoded);
    write_with(path, |w| {
        w.write_all(&bytes).map_err(|e| Error::io(path, e))
    })?;
    Ok(dropped)
}

/// Atomically create `path` from what `fill` writes: temp file in the same folder, sync, rename.
pub(crate) fn write_with(
    path: &Path,
    fill: impl FnOnce(&mut BufWriter<&File>) -> Result<()>,
) -> Result<()> {
    // The one gate (src/io/gate.rs): no link, special file, input or path through a link below an output folder.
    gate::check_target(path)?;
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let prefix = format!(".{name}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".abysslight-tmp");
    // tempfile creates 0600 files by default; outputs get the mode a plain `File::create` would give them (0666
    // less the umask, usually 0644), so the rest of the team can read the corrected photos.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let tmp = builder.tempfile_in(dir).map_err(|e| Error::io(dir, e))?;
    {
        let mut w = BufWriter::new(tmp.as_file());
        fill(&mut w)?;
        w.flush().map_err(|e| Error::io(path, e))?;
    }
    tmp.as_file().sync_all().map_err(|e| Error::io(path, e))?;
    // Again just before the rename: the name may have been replaced while the file was written.
    gate::check_target(path)?;
    tmp.persist(path).map_err(|e| Error::io(path, e.error))?;
    Ok(())
}

/// Save a raster in `[0, 1]` as a 16-bit PNG (atomically).
pub(crate) fn save_raster_png16(raster: &Raster, path: &Path) -> Result<()> {
    let photo = Photo {
        layout: raster.layout(),
        samples: Samples::U16(raster.to_u16()),
        alpha: None,
    };
    write_atomic(&photo, path, EncodeSettings::default())
}

/// Load an image as a normalised raster (for a saved scatter image).
pub(crate) fn load_raster(path: &Path) -> Result<Raster> {
    let photo = decode(path)?;
    Ok(Raster::from_photo(&photo))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_jpeg_decoded_into_a_used_buffer_is_the_one_decoded_into_a_new_one() {
        use jpeg_encoder::{ColorType, Encoder, SamplingFactor};
        // Every sample of the pool's buffer is overwritten, for each layout zune-jpeg decodes (src/io/buffers.rs).
        let cases = [
            (37, 23, SamplingFactor::R_4_2_0, false, 0, ColorType::Rgb),
            (64, 48, SamplingFactor::R_4_2_0, false, 3, ColorType::Rgb),
            (41, 30, SamplingFactor::R_4_2_2, false, 0, ColorType::Rgb),
            (33, 17, SamplingFactor::R_4_4_4, true, 0, ColorType::Rgb),
            (50, 21, SamplingFactor::R_4_2_0, true, 2, ColorType::Rgb),
            (29, 19, SamplingFactor::R_4_4_4, false, 0, ColorType::Luma),
        ];
        for (w, h, sampling, progressive, restart, colour) in cases {
            let channels = if colour == ColorType::Luma { 1 } else { 3 };
            let px: Vec<u8> = (0..w * h * channels)
                .map(|i| ((i * 53) % 241) as u8 ^ (i / 71) as u8)
                .collect();
            let mut data = Vec::new();
            let mut enc = Encoder::new(&mut data, 90);
            enc.set_sampling_factor(sampling);
            enc.set_progressive(progressive);
            enc.set_restart_interval(restart);
            enc.encode(&px, w as u16, h as u16, colour).unwrap();
            let fresh = decode_jpeg_zune(&data, |n| vec![0; n]).unwrap();
            for fill in [0xA5, 0xFF] {
                let used = decode_jpeg_zune(&data, |n| vec![fill; n]).unwrap();
                assert_eq!(used.layout, fresh.layout);
                assert!(
                    used.samples == fresh.samples,
                    "{w}x{h} {sampling:?} progressive {progressive} restart {restart}: a sample of the used buffer was left"
                );
            }
            assert_eq!(fresh.layout.channels, channels);
        }
    }

    #[test]
    fn a_decoder_panic_is_that_files_error() {
        let p = Path::new("IMG_0001.jpg");
        let e = guarded::<()>(p, || panic!("index out of bounds")).unwrap_err();
        let e = e.to_string();
        assert!(
            e.contains("IMG_0001.jpg") && e.contains("index out of bounds"),
            "{e}"
        );
        assert_eq!(guarded(p, || Ok(3)).unwrap(), 3);
    }

    #[test]
    fn natural_order_recursive_and_hidden_skipped() {
        let d = tempfile::tempdir().unwrap();
        for name in [
            "img10.jpg",
            "img2.jpg",
            "img1.PNG",
            "a/img3.tif",
            "notes.txt",
            ".hidden.jpg",
            "_abysslight/x.png",
        ] {
            let p = d.path().join(name);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, b"x").unwrap();
        }
        let f = find_photos(d.path()).unwrap();
        let names: Vec<String> = f
            .photos
            .iter()
            .map(|e| e.relative.to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["a/img3.tif", "img1.PNG", "img2.jpg", "img10.jpg"]);
        assert_eq!(f.ignored.len(), 1);
    }

    #[cfg(unix)]
    #[test]
    fn atomic_output_has_the_mode_a_plain_create_gives() {
        use std::os::unix::fs::PermissionsExt;
        let d = tempfile::tempdir().unwrap();
        let plain = d.path().join("plain");
        std::fs::File::create(&plain).unwrap();
        let ours = d.path().join("ours.bin");
        write_with(&ours, |w| {
            w.write_all(b"x").map_err(|e| Error::io(&ours, e))
        })
        .unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&ours), mode(&plain));
        if mode(&plain) == 0o600 {
            eprintln!("umask 077 here: tempfile's default mode would pass this test too");
        }
    }

    #[test]
    fn round_trip_each_format_and_depth() {
        let d = tempfile::tempdir().unwrap();
        let rgb8 = Photo {
            layout: Layout {
                width: 5,
                height: 3,
                channels: 3,
            },
            samples: Samples::U8((0..45).map(|i| (i * 5) as u8).collect()),
            alpha: None,
        };
        let grey16 = Photo {
            layout: Layout {
                width: 4,
                height: 2,
                channels: 1,
            },
            samples: Samples::U16((0..8).map(|i| i * 8000 + 7).collect()),
            alpha: Some(Samples::U16(vec![65535; 8])),
        };
        let grey16_opaque = Photo {
            alpha: None,
            ..grey16.clone()
        };
        for (photo, name) in [
            (&rgb8, "a.png"),
            (&rgb8, "a.tif"),
            (&grey16, "g.png"),
            (&grey16_opaque, "g.tiff"),
        ] {
            let p = d.path().join(name);
            write_atomic(photo, &p, EncodeSettings::default()).unwrap();
            assert_eq!(&decode(&p).unwrap(), photo, "{name}");
        }
        let j = d.path().join("a.jpg");
        write_atomic(
            &rgb8,
            &j,
            EncodeSettings {
                jpeg_quality: 100,
                ..EncodeSettings::default()
            },
        )
        .unwrap();
        let back = decode(&j).unwrap();
        assert_eq!(back.layout, rgb8.layout);
        assert!(write_atomic(&grey16, &d.path().join("g.jpg"), EncodeSettings::default()).is_err());
        // No temp files are left behind.
        let leftovers: Vec<_> = std::fs::read_dir(d.path())
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .contains("abysslight-tmp")
            })
            .collect();
        assert!(leftovers.is_empty());
    }

    #[test]
    fn bad_files_name_the_file_and_reason() {
        let d = tempfile::tempdir().unwrap();
        let empty = d.path().join("empty.jpg");
        std::fs::write(&empty, b"").unwrap();
        let e = decode(&empty).unwrap_err().to_string();
        assert!(e.contains("empty.jpg") && e.contains("0 bytes"), "{e}");
        let junk = d.path().join("junk.png");
        std::fs::write(&junk, b"this is not a png").unwrap();
        let e = decode(&junk).unwrap_err().to_string();
        assert!(e.contains("junk.png") && e.contains("decode"), "{e}");
        let e = decode(&d.path().join("missing.jpg"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.jpg"), "{e}");
    }
}
