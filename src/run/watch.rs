//! `--watch`: survey photos taken from a folder while a dive is still writing them.
//!
//! Rules (also in docs/live.md):
//!
//! - **Complete files only.** The folder is scanned every `poll_interval`. A photo is taken once its size and
//!   modification time are unchanged between two scans in a row (and it is not empty). If it is taken but does not
//!   decode (a writer that paused longer than a poll), it is not reported yet: it is taken again when it changes,
//!   and reported as failed only if it is still undecodable when the watch stops. Writers should write to a hidden
//!   or non-photo name (`.img.jpg.part`, `img.tmp`) and rename it into place: a rename is atomic, so the photo is
//!   complete the first time it is seen.
//! - **Order.** Photos enter the sliding window in the order they become complete; photos that become complete in
//!   the same scan are taken in natural name order. When files arrive in name order (as cameras write them) this
//!   is the order of a batch run over the final folder, and the outputs are identical to it. A photo that arrives
//!   late, with a name before photos already taken, is processed where it arrived, next to the photos taken at
//!   the same time (it is not lost, and nothing already written is redone).
//! - **Latency.** A photo is corrected as soon as the `n/2` photos after it are complete (`n − 1 − i` for the
//!   first photos `i < n/2`, whose window cannot be centred, as in a batch run).
//! - **Stopping.** The watch ends when [`stop_flag`] is raised (the CLI raises it on SIGINT/SIGTERM) or when no
//!   file in the folder has appeared or changed for `idle_timeout`. Then the photos still waiting for their
//!   window are corrected with windows shifted back, as at the end of a mission, and the report is written.

use std::collections::{HashMap, HashSet, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant, SystemTime};

use crate::error::{Error, Result};
use crate::io::{decode, find_photos_excluding, Entry};
use crate::method::raster::Photo;
use crate::run::source::{Item, Role, Source};

/// Raised to end a watch cleanly (photos waiting for their window are finished, the report is written).
pub fn stop_flag() -> Arc<AtomicBool> {
    static STOP: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    STOP.get_or_init(|| Arc::new(AtomicBool::new(false)))
        .clone()
}

type Stamp = (u64, Option<SystemTime>);

/// Bytes at the end of a file that, all zero, mark it as possibly still being written ([`ends_in_zeros`]).
const ZERO_TAIL: u64 = 4096;

/// Whether the last [`ZERO_TAIL`] bytes of the file at `path` are all zero: what a preallocated file (the full
/// size reserved first, then filled) shows while it is being written. An uncompressed TIFF decodes then, its
/// missing rows black. A complete JPEG or PNG never ends so (an end marker, a checksum); a complete TIFF only if
/// its last rows are black (then it is taken when the watch ends).
fn ends_in_zeros(path: &Path) -> bool {
    use std::io::{Read, Seek, SeekFrom};
    let Ok(mut f) = std::fs::File::open(path) else {
        return false;
    };
    let mut tail = vec![0u8; ZERO_TAIL as usize];
    f.seek(SeekFrom::End(-(ZERO_TAIL as i64)))
        .and_then(|_| f.read_exact(&mut tail))
        .is_ok_and(|_| tail.iter().all(|&b| b == 0))
}

/// Watches a folder (recursively, as a batch run scans it) and yields photos once they are complete.
pub struct WatchFolder {
    dir: PathBuf,
    /// Folders whose photos are never taken, even through a link in `dir` (the output folder).
    exclude: Vec<PathBuf>,
    poll: Duration,
    idle: Option<Duration>,
    stop: Arc<AtomicBool>,
    /// Size and mtime at the last scan, for files not taken yet.
    seen: HashMap<PathBuf, Stamp>,
    /// Taken and decoded (or reported).
    taken: HashSet<PathBuf>,
    /// Taken but undecodable at this stamp; retried when it changes.
    undecodable: HashMap<PathBuf, (Stamp, Entry, Error)>,
    /// Those of `undecodable` that decode but end in zeros ([`ends_in_zeros`]): taken when the watch ends if they
    /// have not changed by then.
    zero_tailed: HashSet<PathBuf>,
    ready: VecDeque<(Entry, Photo, f64)>,
    /// Errors left to report at the end.
    leftover: VecDeque<(Entry, Error)>,
    last_change: Instant,
    index: usize,
    ended: bool,
}

impl WatchFolder {
    /// Watch `dir`, scanning every `poll`; end after `idle` without a new or changed file (never if `None`) or
    /// once `stop` is raised.
    pub fn new(dir: &Path, poll: Duration, idle: Option<Duration>, stop: Arc<AtomicBool>) -> Self {
        WatchFolder {
            dir: dir.to_owned(),
            exclude: Vec::new(),
            poll,
            idle,
            stop,
            seen: HashMap::new(),
            taken: HashSet::new(),
            undecodable: HashMap::new(),
            zero_tailed: HashSet::new(),
            ready: VecDeque::new(),
            leftover: VecDeque::new(),
            last_change: Instant::now(),
            index: 0,
            ended: false,
        }
    }

    /// Never take photos reached through a link into `out` (the output folder), as a batch run skips them:
    /// outputs read back as inputs would feed the run its own outputs, without end.
    pub fn excluding(mut self, out: &Path) -> Self {
        self.exclude.push(out.to_owned());
        self
    }

    /// One scan: note new and changed files; take those unchanged since the last scan.
    fn scan(&mut self) {
        let exclude: Vec<&Path> = self.exclude.iter().map(PathBuf::as_path).collect();
        let Ok(found) = find_photos_excluding(&self.dir, &exclude) else {
            return;
        };
        for entry in found.photos {
            if self.taken.contains(&entry.path) {
                continue;
            }
            let Ok(meta) = std::fs::metadata(&entry.path) else {
                continue;
            };
            let stamp: Stamp = (meta.len(), meta.modified().ok());
            if let Some((s, _, _)) = self.undecodable.get(&entry.path) {
                if *s == stamp {
                    continue;
                }
                self.last_change = Instant::now();
                self.undecodable.remove(&entry.path);
                self.zero_tailed.remove(&entry.path);
            }
            match self.seen.insert(entry.path.clone(), stamp) {
                Some(prev) if prev == stamp && stamp.0 > 0 => {
                    self.seen.remove(&entry.path);
                    let t = Instant::now();
                    match decode(&entry.path) {
                        Ok(_) if ends_in_zeros(&entry.path) => {
                            let e = Error::Decode {
                                path: entry.path.clone(),
                                reason: format!(
                                    "its last {ZERO_TAIL} bytes are zeros: a preallocated file still being \
                                     written? Taken when it changes or when the watch ends"
                                ),
                            };
                            self.zero_tailed.insert(entry.path.clone());
                            self.undecodable
                                .insert(entry.path.clone(), (stamp, entry, e));
                        }
                        Ok(photo) => {
                            self.taken.insert(entry.path.clone());
                            let ms = t.elapsed().as_secs_f64() * 1000.0;
                            self.ready.push_back((entry, photo, ms));
                        }
                        Err(e) => {
                            self.undecodable
                                .insert(entry.path.clone(), (stamp, entry, e));
                        }
                    }
                }
                Some(prev) if prev == stamp => {}
                _ => self.last_change = Instant::now(),
            }
        }
    }

    /// The watch ends: files that decoded but ended in zeros are taken as they are (in name order); those still
    /// undecodable are left to report.
    fn end(&mut self) {
        let mut left: Vec<_> = self
            .undecodable
            .drain()
            .map(|(_, (_, en, e))| (en, e))
            .collect();
        left.sort_by(|a, b| alphanumeric_sort::compare_path(&a.0.relative, &b.0.relative));
        for (entry, e) in left {
            if !self.zero_tailed.contains(&entry.path) {
                self.leftover.push_back((entry, e));
                continue;
            }
            let t = Instant::now();
            match decode(&entry.path) {
                Ok(photo) => {
                    let ms = t.elapsed().as_secs_f64() * 1000.0;
                    self.ready.push_back((entry, photo, ms));
                }
                Err(e) => self.leftover.push_back((entry, e)),
            }
        }
    }

    fn item(&mut self, entry: Entry) -> Item {
        let index = self.index;
        self.index += 1;
        Item {
            index,
            entry,
            role: Role::Write,
        }
    }
}

/// The photo a watch of `dir` takes first (complete as [`WatchFolder`] sees it: unchanged between two scans and
/// decodable), once it is there: for what the run resolves from the photos before it starts (`--transfer auto`,
/// as a batch run reads it from its first photo). `None` when the watch ends before any photo is complete (stop
/// raised, or `idle` without a new or changed file).
pub fn first_complete(
    dir: &Path,
    exclude: &Path,
    poll: Duration,
    idle: Option<Duration>,
    stop: Arc<AtomicBool>,
) -> Option<PathBuf> {
    let mut watch = WatchFolder::new(dir, poll, idle, stop).excluding(exclude);
    // The first scan now: photos already complete in the folder are seen without waiting a poll first.
    watch.scan();
    loop {
        match watch.next_photo()? {
            (item, Ok(_), _) => return Some(item.entry.path),
            (_, Err(_), _) => continue,
        }
    }
}

impl Source for WatchFolder {
    fn next_photo(&mut self) -> Option<(Item, Result<Photo>, f64)> {
        loop {
            if let Some((entry, photo, ms)) = self.ready.pop_front() {
                return Some((self.item(entry), Ok(photo), ms));
            }
            if self.ended {
                let (entry, e) = self.leftover.pop_front()?;
                return Some((self.item(entry), Err(e), 0.0));
            }
            let idle = self.idle.is_some_and(|d| self.last_change.elapsed() >= d);
            if self.stop.load(Ordering::SeqCst) || idle {
                self.ended = true;
                self.end();
                continue;
            }
            // Sleep one poll interval, in small steps so that a stop request is seen quickly.
            let until = Instant::now() + self.poll;
            while Instant::now() < until && !self.stop.load(Ordering::SeqCst) {
                std::thread::sleep(Duration::from_millis(20).min(self.poll));
            }
            if !self.stop.load(Ordering::SeqCst) {
                self.scan();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn jpeg(seed: u8) -> Vec<u8> {
        let px: Vec<u8> = (0..48 * 32 * 3)
            .map(|i| (i as u8).wrapping_mul(seed))
            .collect();
        let mut out = Vec::new();
        jpeg_encoder::Encoder::new(&mut out, 90)
            .encode(&px, 48, 32, jpeg_encoder::ColorType::Rgb)
            .unwrap();
        out
    }

    /// A JPEG the camera is still writing (cut short and closed, or with a zero-filled tail) is not taken: it is
    /// held back and taken once it is complete.
    #[test]
    fn an_incomplete_jpeg_is_held_back_until_complete() {
        let d = tempfile::tempdir().unwrap();
        let full = jpeg(7);
        let mut cut = full[..full.len() / 2].to_vec();
        cut.extend_from_slice(&[0xFF, 0xD9]);
        let mut zeros = full.clone();
        let n = zeros.len();
        zeros[n / 2..].fill(0);
        let stop = Arc::new(AtomicBool::new(false));
        for partial in [cut, zeros] {
            let p = d.path().join("IMG_0001.jpg");
            std::fs::write(&p, &partial).unwrap();
            let mut w = WatchFolder::new(d.path(), Duration::from_millis(1), None, stop.clone());
            w.scan();
            w.scan();
            w.scan();
            assert!(w.ready.is_empty(), "an incomplete JPEG was taken");
            assert!(w.undecodable.contains_key(&p));
            std::fs::write(&p, &full).unwrap();
            // A new stamp (size, and mtime where the file system keeps it finely enough) counts as a change.
            w.scan();
            w.scan();
            assert_eq!(w.ready.len(), 1, "the complete JPEG was not taken");
            std::fs::remove_file(&p).unwrap();
        }
    }

    /// An uncompressed RGB TIFF with its directory first and its pixels last (as several writers lay it out).
    fn tiff_ifd_first(w: u32, h: u32, px: &[u8]) -> Vec<u8> {
        let mut t = b"II*\0".to_vec();
        t.extend_from_slice(&8u32.to_le_bytes());
        let entries: [(u16, u16, u32); 10] = [
            (256, 4, w),
            (257, 4, h),
            (258, 3, 134), // BitsPerSample 8,8,8: 6 bytes after the directory
            (259, 3, 1),
            (262, 3, 2),
            (273, 4, 140),
            (277, 3, 3),
            (278, 4, h),
            (279, 4, w * h * 3),
            (284, 3, 1),
        ];
        t.extend_from_slice(&(entries.len() as u16).to_le_bytes());
        for (tag, kind, value) in entries {
            let count: u32 = if tag == 258 { 3 } else { 1 };
            t.extend_from_slice(&tag.to_le_bytes());
            t.extend_from_slice(&kind.to_le_bytes());
            t.extend_from_slice(&count.to_le_bytes());
            t.extend_from_slice(&value.to_le_bytes());
        }
        t.extend_from_slice(&0u32.to_le_bytes());
        t.extend_from_slice(&[8, 0, 8, 0, 8, 0]);
        assert_eq!(t.len(), 140);
        t.extend_from_slice(px);
        t
    }

    /// A preallocated TIFF being written (its directory and first rows in place, the rest still zeros) decodes,
    /// black below: it is held back and taken once it changes (before: taken at once, never read again, and
    /// corrected as a black photo); unchanged until the watch ends, it is taken then, as it is.
    #[test]
    fn a_preallocated_tiff_being_written_is_held_back() {
        let d = tempfile::tempdir().unwrap();
        let (w, h) = (64u32, 48u32);
        let px: Vec<u8> = (0..w * h * 3).map(|i| (i % 200) as u8 + 20).collect();
        let full = tiff_ifd_first(w, h, &px);
        let mut partial = full.clone();
        let n = partial.len();
        partial[140 + (n - 140) / 3..].fill(0);
        let p = d.path().join("IMG_0001.tif");
        std::fs::write(&p, &partial).unwrap();
        assert!(
            decode(&p).is_ok(),
            "the partial TIFF should decode (black below)"
        );
        let stop = Arc::new(AtomicBool::new(false));
        let mut w1 = WatchFolder::new(d.path(), Duration::from_millis(1), None, stop.clone());
        for _ in 0..3 {
            w1.scan();
        }
        assert!(
            w1.ready.is_empty(),
            "a preallocated TIFF was taken while being written"
        );
        std::fs::write(&p, &full).unwrap();
        w1.scan();
        w1.scan();
        let (_, photo, _) = w1
            .ready
            .pop_front()
            .expect("the complete TIFF was not taken");
        assert_eq!(photo.samples, crate::method::raster::Samples::U8(px));
        // Never completed: taken when the watch ends.
        std::fs::write(&p, &partial).unwrap();
        let mut w2 = WatchFolder::new(d.path(), Duration::from_millis(1), None, stop.clone());
        w2.scan();
        w2.scan();
        stop.store(true, Ordering::SeqCst);
        let (_, got, _) = w2.next_photo().expect("nothing taken at the end");
        assert!(got.is_ok());
    }
}
