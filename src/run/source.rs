//! Where survey photos come from ([`Source`]) and where corrected photos go ([`Sink`]).
//!
//! The pipeline reads one source in order and does not care whether it is a folder listed up front, a folder
//! watched during a dive, or frames on a pipe.

use std::path::Path;
use std::time::Instant;

use std::io::Write;

use crate::error::{Error, Result};
use crate::io::{decode_expecting, EncodeSettings, Entry};
use crate::method::raster::Photo;

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
    /// The photo's input: full path and path relative to the input folder.
    pub entry: Entry,
    /// Whether to write it or only read it for its neighbours' windows.
    pub role: Role,
}

/// A stream of survey photos, in the order the window sees them.
pub trait Source: Send {
    /// The next photo with its decoding result and decoding time in ms; blocks until one is available, `None`
    /// at the end of the stream.
    fn next_photo(&mut self) -> Option<(Item, Result<Photo>, f64)>;
}

/// Photos listed up front (a folder scan), decoded ahead by one or more threads and handed out in order.
///
/// With `w` decoders, decoder `j` decodes items `j`, `j + w`, `j + 2w`, … in turn and hands each over through
/// its own rendezvous channel; `next_photo` takes item `i` from decoder `i mod w`. The order is the list's
/// whatever the timing, and at most `w` decoded photos wait here (one in each decoder's hands).
pub struct FileList {
    decoders: Vec<crossbeam_channel::Receiver<(Item, Result<Photo>, f64)>>,
    next: usize,
    total: usize,
}

impl FileList {
    /// `decoders` decoder threads (at least one).
    #[cfg(test)]
    pub fn parallel(items: Vec<Item>, decoders: usize) -> Self {
        Self::expecting(items, decoders, None)
    }

    /// `decoders` decoder threads; photos whose header says another size than `expected` (width, height) are
    /// refused as mismatches before they are decoded.
    pub fn expecting(items: Vec<Item>, decoders: usize, expected: Option<(usize, usize)>) -> Self {
        let w = decoders.max(1);
        let total = items.len();
        let items = std::sync::Arc::new(items);
        let decoders = (0..w)
            .map(|j| {
                let (tx, rx) = crossbeam_channel::bounded(0);
                let items = std::sync::Arc::clone(&items);
                std::thread::spawn(move || {
                    for item in items.iter().skip(j).step_by(w) {
                        let t = Instant::now();
                        let photo = decode_expecting(&item.entry.path, expected);
                        let ms = t.elapsed().as_secs_f64() * 1000.0;
                        // The reader stopped (end of a shard, an error): stop decoding.
                        if tx.send((item.clone(), photo, ms)).is_err() {
                            break;
                        }
                    }
                });
                rx
            })
            .collect();
        FileList {
            decoders,
            next: 0,
            total,
        }
    }
}

impl Source for FileList {
    fn next_photo(&mut self) -> Option<(Item, Result<Photo>, f64)> {
        if self.next >= self.total {
            return None;
        }
        let got = self.decoders[self.next % self.decoders.len()].recv().ok()?;
        self.next += 1;
        Some(got)
    }
}

/// Where corrected photos go.
pub enum Sink {
    /// Files, written atomically at the output path of each photo, carrying the metadata of their input file if
    /// `carry_metadata` (inputs from a stream have no file to carry it from).
    Folder {
        /// Copy each input file's metadata into its output.
        carry_metadata: bool,
    },
    /// Frames back to back on stdout (`--out -`), each in the format its output path names (`.ppm`, `.pgm`:
    /// binary PNM; `.png`). The caller writes them in stream order.
    Stdout,
}

impl Sink {
    /// Write one corrected photo, with the metadata (EXIF, XMP, ICC, ...) of the file `input` it was corrected
    /// from; `warn` hears what of it could not be read or carried (see [`crate::io::metadata`]).
    pub fn write(
        &self,
        photo: &Photo,
        input: &Path,
        output: &Path,
        settings: EncodeSettings,
        warn: &dyn Fn(&str),
    ) -> Result<()> {
        // A JPEG output is written like its JPEG input (issue 14); the input's head (metadata, tables, frame
        // header) is read once, for both.
        let jpeg_out = crate::io::format_of(output) == Some(image::ImageFormat::Jpeg);
        let head = match self {
            Sink::Folder {
                carry_metadata: true,
            } => crate::io::jpeg::read_head(input).ok().flatten(),
            _ if jpeg_out => crate::io::jpeg::read_head(input).ok().flatten(),
            _ => None,
        };
        let settings = if jpeg_out {
            settings.like(head.as_deref().and_then(crate::io::jpeg::parse).as_ref())
        } else {
            settings
        };
        match self {
            Sink::Folder {
                carry_metadata: true,
            } => crate::io::metadata::write_carrying(
                photo,
                input,
                head.as_deref(),
                output,
                settings,
                warn,
            ),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parallel_file_list_keeps_the_order() {
        let d = tempfile::tempdir().unwrap();
        let mut items = Vec::new();
        for i in 0..11usize {
            let path = d.path().join(format!("p{i}.png"));
            // Sizes differ, so decoding times differ too; one file is damaged.
            if i == 4 {
                std::fs::write(&path, b"not a png").unwrap();
            } else {
                let img = image::RgbImage::from_pixel(
                    3 + 7 * (i as u32 % 3),
                    2,
                    image::Rgb([i as u8; 3]),
                );
                img.save(&path).unwrap();
            }
            items.push(Item {
                index: i,
                entry: Entry {
                    relative: path.file_name().unwrap().into(),
                    path,
                },
                role: Role::Write,
            });
        }
        for w in [1, 2, 3, 5, 16] {
            let mut list = FileList::parallel(items.clone(), w);
            let mut seen = Vec::new();
            while let Some((item, photo, _)) = list.next_photo() {
                assert_eq!(photo.is_err(), item.index == 4);
                if let Ok(p) = photo {
                    assert_eq!(p.layout.width, 3 + 7 * (item.index % 3));
                }
                seen.push(item.index);
            }
            assert_eq!(seen, (0..11).collect::<Vec<_>>(), "{w} decoders");
        }
        // Dropped half-way: the decoders stop.
        let mut list = FileList::parallel(items, 2);
        assert!(list.next_photo().is_some());
        drop(list);
    }
}
