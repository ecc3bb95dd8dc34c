//! Survey photos from standard input (`--survey -`): image frames back to back, split by [`crate::io::pnm`].

use std::io::BufRead;
use std::path::PathBuf;
use std::time::Instant;

use crate::error::{Error, Result};
use crate::io::pnm::{decode_frame, frame_name, FrameSplitter};
use crate::io::Entry;
use crate::method::raster::Photo;
use crate::run::source::{Item, Role, Source};

/// Survey photos read as frames from a stream (stdin for `--survey -`). Frame `i` is named
/// `frame-<i>.<ppm|pgm|png>` (6 digits, 0-based), the name its output gets in an output folder.
pub struct StreamFrames<R> {
    splitter: FrameSplitter<R>,
}

impl<R: BufRead> StreamFrames<R> {
    /// Frames read from `r`.
    pub fn new(r: R) -> Self {
        StreamFrames {
            splitter: FrameSplitter::new(r),
        }
    }
}

impl<R: BufRead + Send> Source for StreamFrames<R> {
    fn next_photo(&mut self) -> Option<(Item, Result<Photo>, f64)> {
        let t = Instant::now();
        let index = self.splitter.frames;
        let frame = self.splitter.next_frame()?;
        let path = PathBuf::from(frame_name(index));
        let (relative, photo) = match frame {
            Ok(f) => {
                let photo = decode_frame(&f);
                let channels = photo.as_ref().map_or(3, |p| p.layout.channels);
                let name = format!("frame-{index:06}.{}", f.format.extension(channels));
                (PathBuf::from(name), photo)
            }
            Err(e) => (PathBuf::from(format!("frame-{index:06}")), Err(e)),
        };
        let photo = photo.map_err(|reason| Error::Decode {
            path: path.clone(),
            reason,
        });
        let item = Item {
            index,
            entry: Entry { path, relative },
            role: Role::Write,
        };
        Some((item, photo, t.elapsed().as_secs_f64() * 1000.0))
    }
}
