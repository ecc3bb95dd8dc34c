//! A navigation log: each photo's altitude above the seafloor, read from a CSV file of one row per photo, matched
//! to the photos by file name (`--navigation`).
//!
//! The first row names the columns; commas, semicolons or tabs separate them (the header's first of these). The
//! photo's column is the first named `file`, `filename`, `file_name`, `image`, `image_name`, `imagename`, `photo`,
//! `relative_path` or `path` (any case); the altitude's the first whose name starts with `altitude` (`altitude`,
//! `Altitude [m]`, `altitude_m`: metres). Other columns are ignored. oplab's navigation CSVs (`relative_path`,
//! `altitude [m]`) read as they are. A photo is matched by its file name, or else by its name without the
//! extension (a log written for the raw frames of converted photos). Values may be quoted; `#` starts a comment
//! line.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// The largest navigation file read (1 GiB: a million photos at a kilobyte a row).
pub const MAX_BYTES: u64 = 1 << 30;

/// Column names of the photo's file, in any case.
const FILE_COLUMNS: [&str; 9] = [
    "file",
    "filename",
    "file_name",
    "image",
    "image_name",
    "imagename",
    "photo",
    "relative_path",
    "path",
];

/// Each photo's altitude from a navigation log ([`Navigation::read`]).
#[derive(Debug, Clone, Default)]
pub struct Navigation {
    /// The file it was read from.
    pub path: PathBuf,
    by_name: HashMap<String, f32>,
    by_stem: HashMap<String, Option<f32>>,
}

impl Navigation {
    /// Read a navigation CSV. Errors name the file and, for a bad row, its line: no header, no photo or altitude
    /// column, an altitude that is not a positive number of metres, a photo listed twice, no row at all.
    pub fn read(path: &Path) -> Result<Navigation> {
        let bad = |reason: String| Error::Config {
            path: path.to_path_buf(),
            reason,
        };
        let size = std::fs::metadata(path)
            .map_err(|e| Error::io(path, e))?
            .len();
        if size > MAX_BYTES {
            return Err(bad(format!(
                "navigation file of {size} bytes; at most {MAX_BYTES} are read (one row per photo)"
            )));
        }
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let text = String::from_utf8_lossy(&bytes);
        Navigation::parse(path, &text).map_err(bad)
    }

    /// [`Navigation::read`] of a text already in memory; the error is the reason alone.
    fn parse(path: &Path, text: &str) -> std::result::Result<Navigation, String> {
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(k, l)| (k + 1, l.trim_start_matches('\u{feff}').trim()))
            .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
        let (header_line, header) = lines.next().ok_or(
            "empty: a header row naming a file and an altitude column, then a row per photo",
        )?;
        let sep = [',', ';', '\t']
            .into_iter()
            .find(|&c| header.contains(c))
            .unwrap_or(',');
        let names: Vec<String> = split(header, sep)
            .into_iter()
            .map(|c| c.to_lowercase())
            .collect();
        let file_col = names
            .iter()
            .position(|c| FILE_COLUMNS.contains(&c.as_str()))
            .ok_or_else(|| {
                format!(
                    "line {header_line}: no column names the photo's file (one of {}); the header is {header:?}",
                    FILE_COLUMNS.join(", ")
                )
            })?;
        let alt_col = names
            .iter()
            .position(|c| c.starts_with("altitude"))
            .ok_or_else(|| {
                format!(
                    "line {header_line}: no altitude column (a name starting with \"altitude\", in metres); the \
                     header is {header:?}"
                )
            })?;
        let mut nav = Navigation {
            path: path.to_path_buf(),
            ..Navigation::default()
        };
        let mut first_line: HashMap<String, usize> = HashMap::new();
        for (line, row) in lines {
            let cells = split(row, sep);
            let cell = |c: usize| cells.get(c).map(String::as_str).unwrap_or("");
            let file = file_name(cell(file_col));
            if file.is_empty() {
                return Err(format!(
                    "line {line}: no photo file in column {}",
                    file_col + 1
                ));
            }
            let text = cell(alt_col);
            let altitude: f32 = text
                .parse()
                .ok()
                .filter(|a: &f32| a.is_finite() && *a > 0.0)
                .ok_or_else(|| {
                    format!("line {line}: altitude {text:?} of {file} is not a positive number of metres")
                })?;
            if let Some(was) = first_line.insert(file.clone(), line) {
                return Err(format!(
                    "line {line}: {file} is listed twice (also on line {was})"
                ));
            }
            // Two files of one stem (a.jpg, a.png) leave the stem unmatched.
            let stem = stem(&file);
            nav.by_stem
                .entry(stem)
                .and_modify(|a| *a = None)
                .or_insert(Some(altitude));
            nav.by_name.insert(file, altitude);
        }
        if nav.by_name.is_empty() {
            return Err("no rows: a row per photo after the header".into());
        }
        Ok(nav)
    }

    /// The altitude of the photo at `path`, matched by its file name, else by its name without the extension.
    pub fn altitude_of(&self, path: &Path) -> Option<f32> {
        let name = path.file_name()?.to_string_lossy();
        self.by_name
            .get(name.as_ref())
            .copied()
            .or_else(|| self.by_stem.get(&stem(&name)).copied().flatten())
    }

    /// Photos listed.
    pub fn len(&self) -> usize {
        self.by_name.len()
    }

    /// No photo listed (never, for a navigation that was read).
    pub fn is_empty(&self) -> bool {
        self.by_name.is_empty()
    }
}

/// The cells of one row, trimmed, with surrounding double quotes removed (a quoted cell may hold the separator).
fn split(row: &str, sep: char) -> Vec<String> {
    let mut cells = Vec::new();
    let (mut cell, mut quoted) = (String::new(), false);
    for c in row.chars() {
        match c {
            '"' => quoted = !quoted,
            c if c == sep && !quoted => cells.push(std::mem::take(&mut cell).trim().to_string()),
            c => cell.push(c),
        }
    }
    cells.push(cell.trim().to_string());
    cells
}

/// The file name of a path in the log, with `/` or `\` between folders.
fn file_name(cell: &str) -> String {
    cell.rsplit(['/', '\\']).next().unwrap_or("").to_string()
}

/// A file name without its extension.
fn stem(name: &str) -> String {
    match name.rsplit_once('.') {
        Some((s, _)) if !s.is_empty() => s.to_string(),
        _ => name.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> std::result::Result<Navigation, String> {
        Navigation::parse(Path::new("nav.csv"), text)
    }

    #[test]
    fn reads_plain_and_oplab_logs() {
        let nav = parse("file,altitude\n0001.jpg,3.5\n0002.jpg,4.25\n").unwrap();
        assert_eq!(nav.len(), 2);
        assert_eq!(nav.altitude_of(Path::new("/dive/0002.jpg")), Some(4.25));
        assert_eq!(nav.altitude_of(Path::new("0003.jpg")), None);
        // oplab's columns, a path with folders, a byte-order mark and quoted cells.
        let oplab = "\u{feff}Imagenumber,Northing [m],Easting [m],Depth [m],Roll [deg],Pitch [deg],Heading [deg],\
                     Altitude [m],Timestamp,Latitude [deg],Longitude [deg],relative_path\n\
                     1,0.1,0.2,4000.0,0.5,-1.0,90.0,2.93,1.6e9,-10.0,-120.0,\"image/PR_001_LC16.tif\"\n";
        let nav = parse(oplab).unwrap();
        assert_eq!(nav.altitude_of(Path::new("x/PR_001_LC16.tif")), Some(2.93));
        // By the name without the extension (a log of the raw frames, photos converted to PNG).
        assert_eq!(
            nav.altitude_of(Path::new("out/PR_001_LC16.png")),
            Some(2.93)
        );
        // Semicolons, tabs, comments and blank lines.
        let nav = parse("# sledge\n\nimage;Altitude_m\nA.JPG;2.0\n").unwrap();
        assert_eq!(nav.altitude_of(Path::new("A.JPG")), Some(2.0));
        let nav = parse("photo\taltitude\nb.png\t1.5\n").unwrap();
        assert_eq!(nav.altitude_of(Path::new("b.png")), Some(1.5));
    }

    #[test]
    fn a_stem_of_two_files_matches_neither_by_stem() {
        let nav = parse("file,altitude\na.jpg,3\na.png,4\n").unwrap();
        assert_eq!(nav.altitude_of(Path::new("a.png")), Some(4.0));
        assert_eq!(nav.altitude_of(Path::new("a.tif")), None);
    }

    #[test]
    fn bad_logs_say_where_and_why() {
        let err = |t: &str| parse(t).unwrap_err();
        assert!(err("").contains("empty"));
        assert!(err("name,altitude\na.jpg,3\n").contains("no column names the photo's file"));
        assert!(err("file,depth\na.jpg,3\n").contains("no altitude column"));
        let e = err("file,altitude\na.jpg,3\nb.jpg,-1\n");
        assert!(
            e.contains("line 3") && e.contains("b.jpg") && e.contains("\"-1\""),
            "{e}"
        );
        assert!(err("file,altitude\na.jpg,NaN\n").contains("line 2"));
        assert!(err("file,altitude\na.jpg\n").contains("line 2"));
        let e = err("file,altitude\na.jpg,3\nd/a.jpg,4\n");
        assert!(
            e.contains("line 3") && e.contains("twice") && e.contains("line 2"),
            "{e}"
        );
        assert!(err("file,altitude\n").contains("no rows"));
        assert!(err("file,altitude\n,3\n").contains("line 2"));
    }

    #[test]
    fn read_names_the_file() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("nav.csv");
        std::fs::write(&p, "file,depth\n").unwrap();
        let e = Navigation::read(&p).unwrap_err().to_string();
        assert!(e.starts_with(&p.display().to_string()), "{e}");
        let e = Navigation::read(&d.path().join("none.csv"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("none.csv"), "{e}");
    }
}
