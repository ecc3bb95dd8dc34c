//! Where survey photos come from ([`Source`]) and where corrected photos go ([`Sink`]).
//!
//! The pipeline reads one source in order and does not care whether it is a folder listed up front, a folder
//! watched during a dive, or frames on a pipe.

use std::path::Path;
use std::time::Instant;

use std::io::Write;

use crate::error::{Error, Result};
use crate::io::{decode, EncodeSettings, Entry};
use crate::raster::Photo;

/// What to do with a survey photo the stream reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Correct and write it.
    Write,
    /// Its output exists (`--resume`): read it for its neighbours' windows only.
    Done,
    /// Another shard's photo, read for this shard's windows only.
    Halo,
}

/// A survey photo in stream order.
#[derive(Debug, Clone)]
pub struct Item {
    /// Position in the stream (0-based, counting failed photos too).
    pub index: usize,
    pub entry: Entry,
    pub role: Role,
}

/// A stream of survey photos, in the order the window sees them.
pub trait Source: Send {
    /// The next photo with its decoding result and decoding time in ms; blocks until one is available, `None`
    /// at the end of the stream.
    fn next_photo(&mut self) -> Option<(Item, Result<Photo>, f64)>;
}

/// Photos listed up front (a folder scan), decoded one by one.
pub struct FileList {
    items: std::vec::IntoIter<Item>,
}

impl FileList {
    pub fn new(items: Vec<Item>) -> Self {
        FileList {
            items: items.into_iter(),
        }
    }
}

impl Source for FileList {
    fn next_photo(&mut self) -> Option<(Item, Result<Photo>, f64)> {
        let item = self.items.next()?;
        let t = Instant::now();
        let photo = decode(&item.entry.path);
        Some((item, photo, t.elapsed().as_secs_f64() * 1000.0))
    }
}

/// Where corrected photos go.
pub enum Sink {
    /// Files, written atomically at the output path of each photo, carrying the metadata of their input file if
    /// `carry_metadata` (inputs from a stream have no file to carry it from).
    Folder { carry_metadata: bool },
    /// Frames back to back on stdout (`--out -`), each in the format its output path names (`.ppm`, `.pgm`:
    /// binary PNM; `.png`). The caller writes them in stream order.
    Stdout,
}

impl Sink {
    /// Write one corrected photo, with the metadata (EXIF, XMP, ICC, ...) of the file `input` it was corrected
    /// from; `warn` hears what of it could not be read or carried (see [`crate::metadata`]).
    pub fn write(
        &self,
        photo: &Photo,
        input: &Path,
        output: &Path,
        settings: EncodeSettings,
        warn: &dyn Fn(&str),
    ) -> Result<()> {
        match self {
            Sink::Folder {
                carry_metadata: true,
            } => crate::metadata::write_carrying(photo, input, output, settings, warn),
            Sink::Folder {
                carry_metadata: false,
            } => crate::io::write_atomic(photo, output, settings),
            Sink::Stdout => {
                let format = crate::io::format_of(output).unwrap_or(image::ImageFormat::Pnm);
                let mut bytes = Vec::new();
                crate::io::encode_to(photo, format, settings, &mut bytes).map_err(|reason| {
                    Error::Encode {
                        path: output.to_owned(),
                        reason,
                    }
                })?;
                let mut out = std::io::stdout().lock();
                out.write_all(&bytes)
                    .and_then(|()| out.flush())
                    .map_err(|e| {
                        let name = output.file_name().unwrap_or_default().to_string_lossy();
                        Error::io(format!("stdout ({name})"), e)
                    })
            }
        }
    }
}
