//! The one gate every file abysslight writes passes through.
//!
//! Each subcommand opens a [`Gate`] before it reads its first photo: its inputs (folders and files it reads) and
//! its outputs (folders it writes into, files it writes) are checked up front ([`Gate::open`]), and for as long as
//! the gate is open every write ([`crate::io::write_with`] calls [`check_target`] before creating its temp file
//! and again just before renaming it into place) is refused when
//!
//! - its path is, or lies inside, an input (resolved: symbolic links followed, `..` taken);
//! - it lies below an output folder and an existing component below that folder is a symbolic link (the write
//!   could land anywhere; the output folder itself may be a link the user chose);
//! - the name exists and is not a regular file: a symbolic link, a folder, a FIFO, a device node or a socket
//!   (the rename would replace `/dev/null` itself, or a FIFO's reader would wait forever).
//!
//! The last rule holds even with no gate open. Temp files are created with `O_CREAT | O_EXCL` (which does not
//! follow a link at the final component), in the target's own folder, and renamed over the final name.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::error::{Error, Result};
use crate::io::paths::{check_no_links_below, check_outputs, resolve};

/// What an open gate protects.
#[derive(Debug)]
struct Open {
    id: u64,
    /// Inputs, resolved, with what they are.
    inputs: Vec<(String, PathBuf)>,
    /// Output folders (absolute, not resolved: a link the user named is the folder).
    roots: Vec<PathBuf>,
}

static OPEN: Mutex<Vec<Open>> = Mutex::new(Vec::new());
static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// An output of a subcommand: a folder it writes into, or one file it writes.
#[derive(Debug, Clone, Copy)]
pub enum Output<'a> {
    /// A folder (`--out DIR`): it may exist (and may be a link the user chose); it must be a folder.
    Folder(&'a str, &'a Path),
    /// A file (`--report FILE`, `--sheet FILE`, `--json FILE`): it must not be a folder, a link or a special
    /// file, and its folder must be writable.
    File(&'a str, &'a Path),
}

impl Output<'_> {
    fn flag_path(&self) -> (&str, &Path) {
        match *self {
            Output::Folder(f, p) | Output::File(f, p) => (f, p),
        }
    }
}

/// The inputs and outputs a subcommand declared; writes are checked against them until it is dropped.
#[derive(Debug)]
pub struct Gate {
    id: u64,
}

impl Gate {
    /// Check `outputs` against `inputs` and against what is on disk (see the module documentation), before
    /// anything is read or written; then protect them until the gate is dropped. Errors are usage errors naming
    /// the option, the path and the reason.
    pub fn open(outputs: &[Output], inputs: &[(&str, &Path)]) -> Result<Gate> {
        let pairs: Vec<(&str, &Path)> = outputs.iter().map(Output::flag_path).collect();
        check_outputs(&pairs, inputs)?;
        let mut roots = Vec::new();
        for o in outputs {
            match *o {
                Output::Folder(flag, p) => {
                    check_folder(flag, p)?;
                    roots.push(absolute(p));
                }
                Output::File(flag, p) => {
                    check_file(flag, p)?;
                    roots.push(absolute(p).parent().map(Path::to_owned).unwrap_or_default());
                }
            }
        }
        let id = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let inputs = inputs
            .iter()
            .filter(|(_, p)| *p != Path::new("-"))
            .map(|(w, p)| (w.to_string(), resolve(p)))
            .collect();
        lock().push(Open { id, inputs, roots });
        Ok(Gate { id })
    }
}

impl Drop for Gate {
    fn drop(&mut self) {
        lock().retain(|o| o.id != self.id);
    }
}

fn lock() -> std::sync::MutexGuard<'static, Vec<Open>> {
    OPEN.lock().unwrap_or_else(|p| p.into_inner())
}

fn absolute(p: &Path) -> PathBuf {
    std::path::absolute(p).unwrap_or_else(|_| p.to_owned())
}

fn refuse(flag: &str, p: &Path, why: &str) -> Error {
    Error::Usage(format!("{flag} {}: {why}", p.display()))
}

/// What kind of thing that is not a regular file `m` describes, if it is one.
fn not_regular(m: &std::fs::Metadata) -> Option<&'static str> {
    let t = m.file_type();
    if t.is_symlink() {
        return Some("a symbolic link");
    }
    if t.is_dir() {
        return Some("a folder");
    }
    if t.is_file() {
        return None;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return Some("a FIFO (named pipe)");
        }
        if t.is_char_device() || t.is_block_device() {
            return Some("a device node");
        }
        if t.is_socket() {
            return Some("a socket");
        }
    }
    Some("not a regular file")
}

/// An output folder: if it exists it is a folder (through a link the user chose, if so); else its nearest
/// existing ancestor is a folder.
fn check_folder(flag: &str, p: &Path) -> Result<()> {
    match std::fs::metadata(p) {
        Ok(m) if m.is_dir() => Ok(()),
        Ok(m) => Err(refuse(
            flag,
            p,
            &format!(
                "exists and is {}, not a folder",
                not_regular(&m).unwrap_or("a file")
            ),
        )),
        Err(_) if std::fs::symlink_metadata(p).is_ok() => Err(refuse(
            flag,
            p,
            "a symbolic link whose target does not exist",
        )),
        Err(_) => nearest_folder(flag, p).map(|_| ()),
    }
}

/// The nearest existing ancestor of `p`, which must be a folder.
fn nearest_folder(flag: &str, p: &Path) -> Result<PathBuf> {
    let abs = absolute(p);
    let mut at = abs.parent();
    while let Some(a) = at {
        match std::fs::metadata(a) {
            Ok(m) if m.is_dir() => return Ok(a.to_owned()),
            Ok(_) => {
                return Err(refuse(
                    flag,
                    p,
                    &format!("{} exists and is not a folder", a.display()),
                ))
            }
            Err(_) => at = a.parent(),
        }
    }
    Err(refuse(flag, p, "no existing folder above it"))
}

/// An output file: not a folder, link or special file; its folder (or the nearest existing one above) writable,
/// found by creating and removing a temp file there.
fn check_file(flag: &str, p: &Path) -> Result<()> {
    if let Ok(m) = std::fs::symlink_metadata(p) {
        if let Some(what) = not_regular(&m) {
            return Err(refuse(
                flag,
                p,
                &format!(
                    "is {what}: abysslight writes this file atomically (a temp file renamed over it), which would \
                     replace it; name a regular file"
                ),
            ));
        }
    }
    let dir = nearest_folder(flag, p)?;
    tempfile::Builder::new()
        .prefix(".abysslight-probe.")
        .tempfile_in(&dir)
        .map(drop)
        .map_err(|e| refuse(flag, p, &format!("cannot write in {}: {e}", dir.display())))
}

/// Refuse a run folder (`<out>/_abysslight`) holding a symbolic link (`factors` pointing at the survey): every
/// file abysslight puts there is its own, and a link there could send a write anywhere.
pub fn check_work_dir(work_dir: &Path) -> Result<()> {
    let Ok(rd) = std::fs::read_dir(work_dir) else {
        return Ok(());
    };
    for e in rd.flatten() {
        if e.file_type().is_ok_and(|t| t.is_symlink()) {
            return Err(Error::Usage(format!(
                "--out: {} is a symbolic link inside the run folder {}: abysslight does not write through \
                 links (--save-factors, the report and the pictures would land where it points); remove it",
                e.path().display(),
                work_dir.display()
            )));
        }
    }
    Ok(())
}

/// The check of one write (called by [`crate::io::write_with`]): `path` is not a link or special file, is not
/// an input of an open gate, and crosses no link below an output folder of one.
pub fn check_target(path: &Path) -> Result<()> {
    if let Ok(m) = std::fs::symlink_metadata(path) {
        if let Some(what) = not_regular(&m) {
            return Err(Error::io(
                path,
                std::io::Error::other(format!(
                    "is {what}; abysslight only replaces regular files it wrote (never a link, folder, FIFO or \
                     device)"
                )),
            ));
        }
    }
    let open = lock();
    if open.is_empty() {
        return Ok(());
    }
    let abs = absolute(path);
    let resolved = resolve(path);
    for o in open.iter() {
        if let Some((what, input)) = o.inputs.iter().find(|(_, i)| resolved.starts_with(i)) {
            return Err(Error::io(
                path,
                std::io::Error::other(format!(
                    "resolves to {}, which is (inside) the {what} {}: abysslight never writes over or into its \
                     inputs",
                    resolved.display(),
                    input.display()
                )),
            ));
        }
        for root in o.roots.iter().filter(|r| abs.starts_with(r)) {
            check_no_links_below(root, &abs)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn writes_through_links_into_inputs_and_onto_special_files_are_refused() {
        let d = tempfile::tempdir().unwrap();
        let survey = d.path().join("survey");
        let out = d.path().join("out");
        std::fs::create_dir_all(&survey).unwrap();
        std::fs::create_dir_all(out.join("_abysslight")).unwrap();
        std::os::unix::fs::symlink(&survey, out.join("_abysslight/factors")).unwrap();
        let gate = Gate::open(
            &[Output::Folder("--out", &out)],
            &[("survey folder", &survey)],
        )
        .unwrap();
        let e = check_target(&out.join("_abysslight/factors/a.png"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("survey"), "{e}");
        assert!(check_target(&survey.join("b.png")).is_err());
        assert!(check_target(&out.join("a.png")).is_ok());
        drop(gate);
        // Closed: only the file-type rule is left.
        assert!(check_target(&survey.join("b.png")).is_ok());
        assert!(check_target(Path::new("/dev/null")).is_err());
        assert!(Gate::open(&[Output::File("--report", Path::new("/dev/null"))], &[]).is_err());
        assert!(Gate::open(&[Output::File("--report", d.path())], &[]).is_err());
        assert!(Gate::open(&[Output::Folder("--out", Path::new("/dev/null"))], &[]).is_err());
    }
}
