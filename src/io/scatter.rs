//! `S` from and to files: the water-column frames of a folder, and the 16-bit scatter image of `--save-scatter`
//! and `--scatter`.

use std::path::Path;

use crate::error::{Error, Result};
use crate::io::{decode_expecting, load_raster, majority_size, save_raster_png16, Entry};
use crate::method::scatter::{estimate_banded, Scatter};

impl Scatter {
    /// Estimate `S` from water-column frames on disk, holding at most `memory_budget` bytes of them at once (row
    /// bands beyond that, each frame decoded once per band). The frames' size is the one most of them have (read
    /// from the headers, [`majority_size`]): frames that cannot be read or are of another size (never decoded)
    /// are passed to `on_error` and left out. `None` when no frame could be used.
    pub fn from_files(
        frames: &[Entry],
        memory_budget: usize,
        on_error: impl FnMut(Error),
    ) -> Result<Option<Scatter>> {
        let size = majority_size(frames, 15);
        Scatter::from_files_sized(frames, size, memory_budget, on_error)
    }

    /// [`Scatter::from_files`] of frames that must be `size` (when known) to be decoded.
    pub fn from_files_sized(
        frames: &[Entry],
        size: Option<(usize, usize)>,
        memory_budget: usize,
        on_error: impl FnMut(Error),
    ) -> Result<Option<Scatter>> {
        estimate_banded(
            frames,
            memory_budget,
            |e| decode_expecting(&e.path, size),
            |e| e.path.clone(),
            on_error,
        )
    }

    /// A scatter image saved by an earlier run (`--scatter`): a regular file (a FIFO would block the run until
    /// something writes to it, a device might never end).
    pub fn load(path: &Path) -> Result<Scatter> {
        crate::io::whole::check_regular(path, "scatter image")?;
        Ok(Scatter::from_raster(&load_raster(path)?))
    }

    /// Save as a 16-bit PNG (exactly what [`Scatter::load`] reads back).
    pub fn save_png(&self, path: &Path) -> Result<()> {
        save_raster_png16(&self.to_raster(), path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{write_atomic, EncodeSettings};
    use crate::method::raster::Photo;
    use crate::method::scatter::tests::frame;

    fn write_frames(dir: &Path, photos: &[Photo]) -> Vec<Entry> {
        photos
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let path = dir.join(format!("{i}.png"));
                write_atomic(p, &path, EncodeSettings::default()).unwrap();
                Entry {
                    relative: path.clone(),
                    path,
                }
            })
            .collect()
    }

    #[test]
    fn files_give_the_same_s_as_the_frames_in_memory() {
        let d = tempfile::tempdir().unwrap();
        let photos: Vec<Photo> = (0..5).map(|i| frame(i + 11, 13, 9)).collect();
        let entries = write_frames(d.path(), &photos);
        let from_files = Scatter::from_files(&entries, 13 * 3 * 2 * 5 * 2, |e| panic!("{e}"))
            .unwrap()
            .unwrap();
        assert!(from_files.passes > 1, "a small budget must band");
        assert_eq!(
            from_files.q,
            Scatter::from_frames(&photos).unwrap().unwrap().q
        );
    }

    #[test]
    fn bad_and_mismatched_frames_are_reported_and_left_out() {
        let d = tempfile::tempdir().unwrap();
        let mut entries = write_frames(d.path(), &[frame(1, 6, 4), frame(2, 5, 4), frame(3, 6, 4)]);
        let junk = d.path().join("junk.png");
        std::fs::write(&junk, b"nope").unwrap();
        entries.push(Entry {
            relative: junk.clone(),
            path: junk,
        });
        let mut errors = Vec::new();
        let s = Scatter::from_files(&entries, 1 << 20, |e| errors.push(e.to_string()))
            .unwrap()
            .unwrap();
        assert_eq!(s.frames, 2);
        assert_eq!(errors.len(), 2, "{errors:?}");
        assert!(errors
            .iter()
            .any(|e| e.contains("1.png") && e.contains("5x4")));
        assert!(errors.iter().any(|e| e.contains("junk.png")));
    }

    #[test]
    fn saved_scatter_reloads_identically() {
        let d = tempfile::tempdir().unwrap();
        let photos: Vec<Photo> = (0..4).map(|i| frame(i + 1, 7, 5)).collect();
        let s = Scatter::from_frames(&photos).unwrap().unwrap();
        let p = d.path().join("scatter.png");
        s.save_png(&p).unwrap();
        assert_eq!(Scatter::load(&p).unwrap().q, s.q);
    }
}
