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
            }
            match self.seen.insert(entry.path.clone(), stamp) {
                Some(prev) if prev == stamp && stamp.0 > 0 => {
                    self.seen.remove(&entry.path);
                    let t = Instant::now();
                    match decode(&entry.path) {
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
                let mut left: Vec<_> = self
                    .undecodable
                    .drain()
                    .map(|(_, (_, en, e))| (en, e))
                    .collect();
                left.sort_by(|a, b| alphanumeric_sort::compare_path(&a.0.relative, &b.0.relative));
                self.leftover.extend(left);
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
}
