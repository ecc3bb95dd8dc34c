//! Files read whole (a config file, a navigation log, a shard's report): only regular files, and never more than
//! a limit. The size a file reports is not trusted (a device such as `/dev/zero` reports 0 and never ends): at
//! most the limit plus one byte is read, and a file that has that byte is refused. A FIFO or a device is refused
//! before it is opened (opening a FIFO waits for a writer).

use std::io::Read;
use std::path::Path;

use crate::error::{Error, Result};

/// The file at `path` (links followed) is a regular file, or an error naming it and saying what it is instead.
/// `what` names the input in the message ("navigation log", "config file").
pub fn check_regular(path: &Path, what: &str) -> Result<()> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if meta.is_file() {
        return Ok(());
    }
    Err(Error::Config {
        path: path.to_path_buf(),
        reason: format!(
            "the {what} is {}, not a regular file: give the file itself (a FIFO or a device is not read)",
            kind(&meta)
        ),
    })
}

/// The whole content of the regular file at `path`, at most `limit` bytes: an error naming the file when it is
/// not a regular file ([`check_regular`]) or longer than `limit`.
pub fn read_whole(path: &Path, limit: u64, what: &str) -> Result<Vec<u8>> {
    check_regular(path, what)?;
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut bytes = Vec::new();
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > limit {
        return Err(Error::Config {
            path: path.to_path_buf(),
            reason: format!("the {what} is longer than {limit} bytes, the most that is read"),
        });
    }
    Ok(bytes)
}

/// [`read_whole`] as text (UTF-8, or an error naming the file).
pub fn read_text(path: &Path, limit: u64, what: &str) -> Result<String> {
    String::from_utf8(read_whole(path, limit, what)?).map_err(|e| Error::Config {
        path: path.to_path_buf(),
        reason: format!("the {what} is not UTF-8 text: {e}"),
    })
}

/// The SHA-256 of `bytes`, in hex.
pub fn sha256(bytes: &[u8]) -> String {
    use sha2::Digest;
    format!("{:x}", sha2::Sha256::digest(bytes))
}

/// The SHA-256 of the regular file at `path` (at most `limit` bytes, read in pieces), in hex.
pub fn sha256_of(path: &Path, limit: u64, what: &str) -> Result<String> {
    use sha2::Digest;
    check_regular(path, what)?;
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut hasher = sha2::Sha256::new();
    let read = std::io::copy(&mut file.take(limit.saturating_add(1)), &mut hasher)
        .map_err(|e| Error::io(path, e))?;
    if read > limit {
        return Err(Error::Config {
            path: path.to_path_buf(),
            reason: format!("the {what} is longer than {limit} bytes, the most that is read"),
        });
    }
    Ok(format!("{:x}", hasher.finalize()))
}

/// What a file that is not a regular file is, in words.
fn kind(meta: &std::fs::Metadata) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if meta.is_dir() {
        "a folder"
    } else {
        "not a regular file"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_up_to_the_limit_and_refuses_more() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.txt");
        std::fs::write(&p, b"12345").unwrap();
        assert_eq!(read_whole(&p, 5, "log").unwrap(), b"12345");
        let e = read_whole(&p, 4, "log").unwrap_err().to_string();
        assert!(
            e.contains("a.txt") && e.contains("longer than 4 bytes"),
            "{e}"
        );
        let e = read_whole(d.path(), 4, "log").unwrap_err().to_string();
        assert!(e.contains("a folder"), "{e}");
        // Python's hashlib.sha256(b"12345").hexdigest()
        let want = "5994471abb01112afcc18159f6cc74b4f511b99806da59b3caf5a9c173cacfc5";
        assert_eq!(sha256(b"12345"), want);
        assert_eq!(sha256_of(&p, 5, "log").unwrap(), want);
        assert!(sha256_of(&p, 4, "log").is_err());
    }

    #[cfg(unix)]
    #[test]
    fn a_device_is_refused_without_reading_it() {
        let e = read_whole(Path::new("/dev/zero"), 1 << 20, "log")
            .unwrap_err()
            .to_string();
        assert!(e.contains("/dev/zero") && e.contains("a device"), "{e}");
    }
}
