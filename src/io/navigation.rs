//! A navigation log: each photo's altitude above the seafloor, read from a CSV file (`--navigation`), matched to
//! the photos by file name or by time.
//!
//! The first row names the columns; commas, semicolons or tabs separate them (the header's first of these). The
//! altitude's column is the first whose name starts with `altitude` (`altitude`, `Altitude [m]`, `altitude_m`:
//! metres). Other columns are ignored. Values may be quoted; `#` starts a comment line.
//!
//! - **By file name**, one row per photo: the photo's column is the first named `file`, `filename`, `file_name`,
//!   `image`, `image_name`, `imagename`, `photo`, `relative_path` or `path` (any case). oplab's navigation CSVs
//!   (`relative_path`, `altitude [m]`) read as they are. A photo is matched by its file name, or else by its name
//!   without the extension (a log written for the raw frames of converted photos).
//! - **By time**, a log without a file column, as a vehicle writes it (rows at any rate, in any order): the time's
//!   column is the first whose name starts with `time`, `datetime`, `date_time`, `epoch` or `unix`, or is `utc`.
//!   Times are seconds since 1970-01-01 00:00 UTC, or dates as `2023-06-03T16:27:01.5Z` (a space for the `T`, an
//!   offset such as `+02:00`, or none: UTC). A photo's time is its EXIF `DateTimeOriginal`
//!   ([`crate::Metadata::time_taken`]); its altitude is interpolated between the rows around it, where they lie at
//!   most [`MAX_GAP_S`] apart.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// The largest navigation file read (1 GiB: a million photos at a kilobyte a row).
pub const MAX_BYTES: u64 = 1 << 30;

/// Rows of a log by time further apart than this (seconds) give no altitude between them (a gap in the log).
pub const MAX_GAP_S: f64 = 10.0;

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
#[derive(Debug, Default)]
pub struct Navigation {
    /// The file it was read from.
    pub path: PathBuf,
    by_name: HashMap<String, f32>,
    by_stem: HashMap<String, Option<f32>>,
    /// A log by time: (seconds, altitude), in time order.
    by_time: Vec<(f64, f32)>,
    /// A log by time: the altitude found for each photo read so far.
    found: std::sync::Mutex<HashMap<PathBuf, Option<f32>>>,
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
            .position(|c| FILE_COLUMNS.contains(&c.as_str()));
        let time_col = names.iter().position(|c| {
            ["time", "datetime", "date_time", "epoch", "unix"]
                .iter()
                .any(|p| c.starts_with(p))
                || c == "utc"
        });
        let (file_col, time_col) = match (file_col, time_col) {
            (Some(f), _) => (f, None),
            (None, Some(t)) => (0, Some(t)),
            (None, None) => {
                return Err(format!(
                    "line {header_line}: no column names the photo's file (one of {}) or the time (time, \
                     timestamp, datetime, epoch, utc); the header is {header:?}",
                    FILE_COLUMNS.join(", ")
                ))
            }
        };
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
            if let Some(t) = time_col {
                let time = parse_time(cell(t)).ok_or_else(|| {
                    format!("line {line}: time {:?} does not read as a time", cell(t))
                })?;
                let text = cell(alt_col);
                let altitude = positive(text).ok_or_else(|| {
                    format!("line {line}: altitude {text:?} is not a positive number of metres")
                })?;
                nav.by_time.push((time, altitude));
                continue;
            }
            let file = file_name(cell(file_col));
            if file.is_empty() {
                return Err(format!(
                    "line {line}: no photo file in column {}",
                    file_col + 1
                ));
            }
            let text = cell(alt_col);
            let altitude = positive(text).ok_or_else(|| {
                format!(
                    "line {line}: altitude {text:?} of {file} is not a positive number of metres"
                )
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
        if nav.by_name.is_empty() && nav.by_time.is_empty() {
            return Err("no rows: a row per photo (or per time) after the header".into());
        }
        nav.by_time.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(nav)
    }

    /// The altitude of the photo at `path`: matched by its file name, else by its name without the extension; or,
    /// for a log by time, at the time the photo's EXIF gives (read once per photo).
    pub fn altitude_of(&self, path: &Path) -> Option<f32> {
        if !self.by_time.is_empty() {
            let mut found = self.found.lock().unwrap_or_else(|e| e.into_inner());
            return *found.entry(path.to_path_buf()).or_insert_with(|| {
                let t = crate::Metadata::read(path).ok()?.time_taken()?;
                self.altitude_at(t)
            });
        }
        let name = path.file_name()?.to_string_lossy();
        self.by_name
            .get(name.as_ref())
            .copied()
            .or_else(|| self.by_stem.get(&stem(&name)).copied().flatten())
    }

    /// A log by time: the altitude at `t` (seconds since 1970 UTC), interpolated between the rows around it where
    /// they lie at most [`MAX_GAP_S`] apart; `None` outside the log and in its gaps.
    pub fn altitude_at(&self, t: f64) -> Option<f32> {
        let rows = &self.by_time;
        let k = rows.partition_point(|r| r.0 < t);
        match (k.checked_sub(1).map(|j| rows[j]), rows.get(k)) {
            (_, Some(&(t1, a1))) if t1 == t => Some(a1),
            (Some((t0, a0)), Some(&(t1, a1))) if t1 - t0 <= MAX_GAP_S => {
                let w = ((t - t0) / (t1 - t0)) as f32;
                Some(a0 + w * (a1 - a0))
            }
            _ => None,
        }
    }

    /// Rows read: photos listed, or times of a log by time.
    pub fn len(&self) -> usize {
        self.by_name.len() + self.by_time.len()
    }

    /// No row (never, for a navigation that was read).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether photos are matched by their time (a log without a file column).
    pub fn by_time(&self) -> bool {
        !self.by_time.is_empty()
    }
}

/// A positive, finite number of metres.
fn positive(text: &str) -> Option<f32> {
    text.parse()
        .ok()
        .filter(|a: &f32| a.is_finite() && *a > 0.0)
}

/// A time as seconds since 1970-01-01 00:00 UTC: a number (those seconds), or a date and time, `YYYY-MM-DD` (or
/// `YYYY:MM:DD`, as EXIF writes it, or with `/`), `T` or a space, `HH:MM:SS` with an optional fraction, and an
/// optional `Z` or offset (`+02:00`, `-0330`); without one, UTC.
pub fn parse_time(text: &str) -> Option<f64> {
    let text = text.trim();
    if let Ok(v) = text.parse::<f64>() {
        return v.is_finite().then_some(v);
    }
    let (date, rest) = text.split_at_checked(10)?;
    let rest = rest.strip_prefix(['T', 't', ' '])?;
    let d: Vec<&str> = date.split(['-', ':', '/']).collect();
    let [y, m, day] = d[..] else { return None };
    let (y, m, day): (i64, u32, u32) = (y.parse().ok()?, m.parse().ok()?, day.parse().ok()?);
    if !(1..=12).contains(&m) || day == 0 || day > days_in_month(y, m) {
        return None;
    }
    // The clock, then the zone.
    let zone_at = rest.find(['Z', 'z', '+', '-']).unwrap_or(rest.len());
    let (clock, zone) = rest.split_at(zone_at);
    let c: Vec<&str> = clock.split(':').collect();
    let [hh, mm, ss] = c[..] else { return None };
    let (hh, mm): (u32, u32) = (hh.parse().ok()?, mm.parse().ok()?);
    let ss: f64 = ss.parse().ok()?;
    if hh > 23 || mm > 59 || !(0.0..61.0).contains(&ss) {
        return None;
    }
    let offset = if zone.is_empty() {
        0.0
    } else {
        parse_offset(zone)?
    };
    let days = days_from_civil(y, m, day) as f64;
    Some(days * 86_400.0 + (hh * 3600 + mm * 60) as f64 + ss - offset)
}

/// A time zone's offset from UTC in seconds: `Z`, or `+HH:MM`, `-HH:MM`, `+HHMM`, `+HH`.
pub fn parse_offset(text: &str) -> Option<f64> {
    let text = text.trim();
    if text.eq_ignore_ascii_case("z") {
        return Some(0.0);
    }
    let (sign, hm) = match text.as_bytes().first()? {
        b'+' => (1.0, &text[1..]),
        b'-' => (-1.0, &text[1..]),
        _ => return None,
    };
    let digits: String = hm.chars().filter(|c| *c != ':').collect();
    if !digits.bytes().all(|b| b.is_ascii_digit()) || !(digits.len() == 2 || digits.len() == 4) {
        return None;
    }
    let h: f64 = digits[..2].parse().ok()?;
    let m: f64 = if digits.len() == 4 {
        digits[2..].parse().ok()?
    } else {
        0.0
    };
    (h <= 18.0 && m < 60.0).then_some(sign * (h * 3600.0 + m * 60.0))
}

/// Days from 1970-01-01 to the date (proleptic Gregorian calendar).
fn days_from_civil(y: i64, m: u32, d: u32) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = if y >= 0 { y } else { y - 399 } / 400;
    let yoe = y - era * 400;
    let mp = (m as i64 + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d as i64 - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

fn days_in_month(y: i64, m: u32) -> u32 {
    match m {
        2 if (y % 4 == 0 && y % 100 != 0) || y % 400 == 0 => 29,
        2 => 28,
        4 | 6 | 9 | 11 => 30,
        _ => 31,
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
        assert!(err("time,altitude\nnoon,3\n").contains("line 2"));
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
    fn times_read_as_an_independent_calendar_gives_them() {
        // Seconds since 1970 UTC from Python's datetime.
        for (text, want) in [
            ("2023-06-03T16:27:01Z", 1_685_809_621.0),
            ("2023-06-03 16:27:01", 1_685_809_621.0),
            ("2023:06:03 16:27:01", 1_685_809_621.0),
            ("2023-06-03T16:27:01+02:00", 1_685_802_421.0),
            ("2023-06-03T16:27:01-0130", 1_685_815_021.0),
            ("2024-05-06T07:08:09.25Z", 1_714_979_289.25),
            ("2000-02-29T23:59:59Z", 951_868_799.0),
            ("1970-01-01T00:00:00Z", 0.0),
            ("1685809621.5", 1_685_809_621.5),
        ] {
            assert_eq!(parse_time(text), Some(want), "{text}");
        }
        for bad in [
            "2023-02-29T00:00:00",
            "2023-13-01T00:00:00",
            "2023-06-03T24:00:00",
            "noon",
            "2023-06-03",
        ] {
            assert_eq!(parse_time(bad), None, "{bad}");
        }
        assert_eq!(parse_offset("+05:30"), Some(19_800.0));
        assert_eq!(parse_offset("5:30"), None);
    }

    #[test]
    fn a_log_by_time_interpolates_and_leaves_its_gaps_unknown() {
        // Rows out of order, at 1 Hz, then a gap of 30 s.
        let nav =
            parse("time,depth,altitude\n100,4000,3.0\n99,4000,2.0\n101,4000,5.0\n131,4000,4.0\n")
                .unwrap();
        assert!(nav.by_time());
        assert_eq!(nav.altitude_at(99.0), Some(2.0));
        assert_eq!(nav.altitude_at(99.25), Some(2.25));
        assert_eq!(nav.altitude_at(100.5), Some(4.0));
        assert_eq!(nav.altitude_at(131.0), Some(4.0));
        assert_eq!(nav.altitude_at(110.0), None, "a gap of 30 s");
        assert_eq!(nav.altitude_at(98.0), None, "before the log");
        assert_eq!(nav.altitude_at(132.0), None, "after the log");
        // Dates with a zone.
        let nav =
            parse("Timestamp;Altitude [m]\n2023-06-03T18:27:00+02:00;3\n2023-06-03T16:27:02Z;5\n")
                .unwrap();
        assert_eq!(nav.altitude_at(1_685_809_621.0), Some(4.0));
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
