//! A navigation log: each photo's altitude above the seafloor, read from a CSV file (`--navigation`), matched to
//! the photos by file name or by time.
//!
//! The log is a table ([`csv`]): the first row names the columns; commas, semicolons or tabs separate them (the
//! header's first of these); cells may be quoted; lines starting with `#` are comments; a units row right under
//! the header (`s,deg,m`: no cell a number) is passed over. The altitude's column (metres) is the one the user
//! names ([`Columns`], `--navigation-columns altitude=NAME`), or else the first whose name starts with `altitude`
//! (`Altitude [m]`), or else contains it (`dvl_altitude_m`), or is `alt` (`alt_m`, `alt [m]`). Other columns are
//! ignored. Names are compared in any case, with spaces, `-` and `/` read as `_`.
//!
//! - **By file name**, one row per photo: the photo's column is the one named, or the first named `file`,
//!   `filename`, `file_name`, `image`, `image_name`, `imagename`, `photo`, `relative_path` or `path`. oplab's
//!   navigation CSVs (`relative_path`, `altitude [m]`) read as they are. A photo is matched by its file name, or
//!   else by its name without the extension (a log written for the raw frames of converted photos).
//! - **By time**, a log without a file column, as a vehicle writes it (rows at any rate, in any order): the time's
//!   column is the one named, or the first whose name starts with `time`, `datetime`, `date_time` (`Date Time`),
//!   `epoch` or `unix`, or is `utc`. Times are seconds since 1970-01-01 00:00 UTC, or dates as
//!   `2023-06-03T16:27:01.5Z` (a space for the `T`, an offset such as `+02:00`, or none: UTC). A photo's time is
//!   its EXIF `DateTimeOriginal` ([`crate::Metadata::time_taken`]); the log's times plus the clock offset
//!   (`--navigation-clock-offset`, the camera's clock minus the log's) are on the camera's clock. A photo's
//!   altitude is interpolated between the rows around it, where they lie at most `MAX_GAP_S` apart.
//!
//! Rows without a usable altitude (empty, `NaN`, `0`, negative: a DVL without bottom lock) are passed over and
//! counted ([`Navigation::notes`]); between the rows around them the gap rule decides. A log with too few usable
//! rows, or an altitude no camera is flown at (`MAX_ALTITUDE_M`: a no-data marker or another column), is refused.
//!
//! The log is joined to the photos once, when they are listed (`Navigation::join`, in parallel: for a log by
//! time it reads each photo's EXIF time); the lookups after it ([`Navigation::altitude_by_name`],
//! [`Navigation::altitude_at`]) read no file.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// The largest navigation file read (1 GiB: a million photos at a kilobyte a row).
pub const MAX_BYTES: u64 = 1 << 30;

/// Rows of a log by time further apart than this (seconds) give no altitude between them (a gap in the log).
pub(crate) const MAX_GAP_S: f64 = 10.0;

/// An altitude above this (metres) is refused: no camera lights the seafloor from there (a no-data marker such
/// as 9999, a depth column, or millimetres).
pub(crate) const MAX_ALTITUDE_M: f32 = 1000.0;

/// The fewest usable rows of a log by time (two rows bracket a photo).
pub(crate) const MIN_TIME_ROWS: usize = 2;

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

/// The log's columns as the user names them (`--navigation-columns time=Date Time,altitude=dvl_alt`, or a
/// `[navigation-columns]` table in a config file); a column not named is found by its name (the module's doc).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields, try_from = "ColumnsIn")]
pub struct Columns {
    /// The photo's file (a log by file name).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// The time (a log by time).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time: Option<String>,
    /// The altitude above the seafloor, metres.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub altitude: Option<String>,
}

/// A config file's or Python's `navigation-columns`: the command line's text, or a table.
#[derive(Deserialize)]
#[serde(untagged)]
enum ColumnsIn {
    Text(String),
    Table {
        #[serde(default)]
        file: Option<String>,
        #[serde(default)]
        time: Option<String>,
        #[serde(default)]
        altitude: Option<String>,
    },
}

impl TryFrom<ColumnsIn> for Columns {
    type Error = String;
    fn try_from(c: ColumnsIn) -> std::result::Result<Self, String> {
        match c {
            ColumnsIn::Text(t) => t.parse(),
            ColumnsIn::Table {
                file,
                time,
                altitude,
            } => Columns {
                file,
                time,
                altitude,
            }
            .checked(),
        }
    }
}

impl Columns {
    /// No column named.
    pub fn is_empty(&self) -> bool {
        *self == Columns::default()
    }

    fn checked(self) -> std::result::Result<Self, String> {
        if self.file.is_some() && self.time.is_some() {
            return Err(
                "navigation columns: name the file's column (a log by file name) or the time's (a log by \
                        time), not both"
                    .into(),
            );
        }
        for name in [&self.file, &self.time, &self.altitude]
            .into_iter()
            .flatten()
        {
            if name.trim().is_empty() {
                return Err("navigation columns: an empty column name".into());
            }
        }
        Ok(self)
    }
}

impl FromStr for Columns {
    type Err = String;
    /// `KEY=NAME` pairs separated by commas, keys `file`, `time` and `altitude`: `time=Date Time,altitude=alt_m`.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let mut c = Columns::default();
        for pair in s.split(',').filter(|p| !p.trim().is_empty()) {
            let (key, name) = pair.split_once('=').ok_or_else(|| {
                format!(
                    "navigation columns {s:?}: expected KEY=NAME pairs separated by commas, keys file, time and \
                     altitude (e.g. time=Date Time,altitude=dvl_altitude_m)"
                )
            })?;
            let slot = match key.trim().to_lowercase().as_str() {
                "file" => &mut c.file,
                "time" => &mut c.time,
                "altitude" => &mut c.altitude,
                k => {
                    return Err(format!(
                        "navigation columns: unknown key {k:?} (file, time or altitude)"
                    ))
                }
            };
            *slot = Some(name.trim().to_string());
        }
        c.checked()
    }
}

/// How a log is read: the columns the user named and the clock offset.
#[derive(Debug, Clone, Default)]
pub struct ReadAs {
    /// Columns named by the user.
    pub columns: Columns,
    /// Seconds added to the log's times to put them on the camera's clock (the camera's clock minus the log's).
    pub clock_offset: f64,
}

/// A photo joined to the log (`Navigation::join`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Joined {
    /// Its altitude, where the log gives one.
    pub altitude: Option<f32>,
    /// A log by time: the photo's EXIF time (seconds since 1970 UTC), where it has one.
    pub time: Option<f64>,
}

/// Each photo's altitude from a navigation log ([`Navigation::read`]).
#[derive(Debug)]
pub struct Navigation {
    /// The file it was read from.
    pub path: PathBuf,
    /// The SHA-256 of the file's content, in hex (empty for a log not read from a file).
    pub sha256: String,
    rows: Rows,
    /// What reading found that the user should know (dropout rows passed over, conflicting duplicate times).
    notes: Vec<String>,
}

/// The rows of a log.
#[derive(Debug)]
enum Rows {
    /// By file name, sorted by name.
    ByName(Names),
    /// By time: (seconds on the camera's clock, altitude, line), in time order (rows of one time in file order).
    ByTime(Vec<(f64, f32, u32)>),
}

/// A log by file name: every name in one string, and the rows sorted by name and by stem (a million rows take
/// tens of megabytes, with no allocation per row).
#[derive(Debug, Default)]
struct Names {
    text: String,
    rows: Vec<NameRow>,
    /// Indices into `rows`, sorted by stem.
    by_stem: Vec<u32>,
}

#[derive(Debug, Clone, Copy)]
struct NameRow {
    start: u32,
    len: u32,
    stem_len: u32,
    altitude: f32,
    line: u32,
}

impl Names {
    fn name(&self, r: &NameRow) -> &str {
        &self.text[r.start as usize..(r.start + r.len) as usize]
    }

    fn stem(&self, r: &NameRow) -> &str {
        &self.text[r.start as usize..(r.start + r.stem_len) as usize]
    }

    fn push(&mut self, name: &str, altitude: f32, line: u32) {
        let start = self.text.len() as u32;
        self.text.push_str(name);
        self.rows.push(NameRow {
            start,
            len: name.len() as u32,
            stem_len: stem(name).len() as u32,
            altitude,
            line,
        });
    }

    /// Sort the rows; a name listed twice is an error naming both lines.
    fn sort(&mut self) -> std::result::Result<(), String> {
        let mut rows = std::mem::take(&mut self.rows);
        rows.par_sort_unstable_by(|a, b| self.name(a).cmp(self.name(b)).then(a.line.cmp(&b.line)));
        let twice = rows
            .windows(2)
            .filter(|w| self.name(&w[0]) == self.name(&w[1]))
            .min_by_key(|w| w[1].line);
        if let Some(w) = twice {
            return Err(format!(
                "line {}: {} is listed twice (also on line {})",
                w[1].line,
                self.name(&w[1]),
                w[0].line
            ));
        }
        let mut by_stem: Vec<u32> = (0..rows.len() as u32).collect();
        by_stem.par_sort_unstable_by(|&a, &b| {
            self.stem(&rows[a as usize])
                .cmp(self.stem(&rows[b as usize]))
        });
        self.rows = rows;
        self.by_stem = by_stem;
        Ok(())
    }

    /// The altitude of the photo named `name`, else of the one row of its stem.
    fn get(&self, name: &str) -> Option<f32> {
        if let Ok(k) = self.rows.binary_search_by(|r| self.name(r).cmp(name)) {
            return Some(self.rows[k].altitude);
        }
        let s = stem(name);
        let at = |k: usize| self.by_stem.get(k).map(|&i| &self.rows[i as usize]);
        let k = self
            .by_stem
            .partition_point(|&i| self.stem(&self.rows[i as usize]) < s);
        match (at(k), at(k + 1)) {
            (Some(r), next) if self.stem(r) == s => {
                // Two files of one stem (a.jpg, a.png) leave the stem unmatched.
                (next.is_none_or(|n| self.stem(n) != s)).then_some(r.altitude)
            }
            _ => None,
        }
    }
}

impl Navigation {
    /// Read a navigation CSV (a regular file of at most [`MAX_BYTES`]). Errors name the file and, for a bad row,
    /// its line: no header, no photo or altitude column, a time that does not read, an implausible altitude, a
    /// photo listed twice, too few usable rows.
    pub fn read(path: &Path, how: &ReadAs) -> Result<Navigation> {
        let bytes = crate::io::whole::read_whole(path, MAX_BYTES, "navigation log")?;
        let mut nav = Navigation::parse(path, &bytes, how).map_err(|reason| Error::Config {
            path: path.to_path_buf(),
            reason,
        })?;
        nav.sha256 = crate::io::whole::sha256(&bytes);
        Ok(nav)
    }

    /// [`Navigation::read`] of a text already in memory; the error is the reason alone.
    fn parse(path: &Path, bytes: &[u8], how: &ReadAs) -> std::result::Result<Navigation, String> {
        let bytes = bytes.strip_prefix(b"\xef\xbb\xbf").unwrap_or(bytes);
        let header_text = bytes
            .split(|&b| b == b'\n')
            .map(|l| String::from_utf8_lossy(l).trim().to_string())
            .find(|l| !l.is_empty() && !l.starts_with('#'))
            .ok_or(
                "empty: a header row naming a file and an altitude column, then a row per photo",
            )?;
        let sep = [b',', b';', b'\t']
            .into_iter()
            .find(|&c| header_text.as_bytes().contains(&c))
            .unwrap_or(b',');
        let mut reader = csv::ReaderBuilder::new()
            .delimiter(sep)
            .has_headers(false)
            .flexible(true)
            .comment(Some(b'#'))
            .trim(csv::Trim::All)
            .from_reader(bytes);
        let mut record = csv::ByteRecord::new();
        let mut header = None;
        while reader.read_byte_record(&mut record).map_err(csv_error)? {
            if !blank(&record) {
                header = Some(record.clone());
                break;
            }
        }
        let header = header.ok_or("empty: a header row naming a file and an altitude column")?;
        let header_line = line_of(&header);
        let names: Vec<String> = header.iter().map(|c| normal(&cell_text(c))).collect();
        let key = Key::choose(&names, &how.columns, header_line, &header_text)?;
        let alt_col = altitude_column(&names, &how.columns, header_line, &header_text)?;
        let mut table = Table::default();
        let mut first_row = true;
        while reader.read_byte_record(&mut record).map_err(csv_error)? {
            if blank(&record) {
                continue;
            }
            let line = line_of(&record);
            let cell = |c: usize| cell_text(record.get(c).unwrap_or(b""));
            if std::mem::take(&mut first_row) && units_row(&record, &key, alt_col) {
                continue;
            }
            table.rows += 1;
            let Some(altitude) = table.altitude(&cell(alt_col), line)? else {
                continue;
            };
            match key {
                Key::Time(t) => {
                    let text = cell(t);
                    if text.is_empty() {
                        table.dropout(line);
                        continue;
                    }
                    let time = parse_time(&text).ok_or_else(|| {
                        format!(
                            "line {line}: time {text:?} does not read as a time (seconds since 1970, or a date \
                             and time such as 2023-06-03T16:27:01Z)"
                        )
                    })?;
                    table
                        .times
                        .push((time + how.clock_offset, altitude, line as u32));
                }
                Key::File(f) => {
                    let cell = cell(f);
                    let file = file_name(&cell);
                    if file.is_empty() {
                        return Err(format!("line {line}: no photo file in column {}", f + 1));
                    }
                    table.names.push(file, altitude, line as u32);
                }
            }
        }
        table.finish(path, matches!(key, Key::Time(_)))
    }

    /// The altitude of the photo named `file_name` in a log by file name (matched by its name, else by its name
    /// without the extension); `None` for a log by time.
    pub fn altitude_by_name(&self, file_name: &str) -> Option<f32> {
        match &self.rows {
            Rows::ByName(names) => names.get(file_name),
            Rows::ByTime(_) => None,
        }
    }

    /// A log by time: the altitude at `t` (seconds since 1970 UTC on the camera's clock), interpolated between the
    /// rows around it where they lie at most `MAX_GAP_S` apart; `None` outside the log and in its gaps.
    pub fn altitude_at(&self, t: f64) -> Option<f32> {
        let Rows::ByTime(rows) = &self.rows else {
            return None;
        };
        let k = rows.partition_point(|r| r.0 < t);
        match (k.checked_sub(1).map(|j| rows[j]), rows.get(k)) {
            (_, Some(&(t1, a1, _))) if t1 == t => Some(a1),
            (Some((t0, a0, _)), Some(&(t1, a1, _))) if t1 - t0 <= MAX_GAP_S => {
                let w = ((t - t0) / (t1 - t0)) as f32;
                Some(a0 + w * (a1 - a0))
            }
            _ => None,
        }
    }

    /// The photo at `path` joined to the log: by its file name, or for a log by time at its EXIF time (read from
    /// the file: the one read of this module besides the log's).
    pub(crate) fn photo(&self, path: &Path) -> Joined {
        match &self.rows {
            Rows::ByName(names) => Joined {
                altitude: names.get(&path.file_name().unwrap_or_default().to_string_lossy()),
                time: None,
            },
            Rows::ByTime(_) => {
                let time = crate::Metadata::read(path)
                    .ok()
                    .and_then(|m| m.time_taken());
                Joined {
                    altitude: time.and_then(|t| self.altitude_at(t)),
                    time,
                }
            }
        }
    }

    /// The photos at `paths` joined to the log ([`Navigation::photo`]), in parallel, in their order.
    pub(crate) fn join(&self, paths: &[&Path]) -> Vec<Joined> {
        paths.par_iter().map(|p| self.photo(p)).collect()
    }

    /// Rows read: photos listed, or times of a log by time.
    pub fn len(&self) -> usize {
        match &self.rows {
            Rows::ByName(n) => n.rows.len(),
            Rows::ByTime(t) => t.len(),
        }
    }

    /// No row (never, for a navigation that was read).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether photos are matched by their time (a log without a file column).
    pub fn by_time(&self) -> bool {
        matches!(self.rows, Rows::ByTime(_))
    }

    /// A log by time: its first and last time (seconds since 1970 UTC, on the camera's clock).
    pub fn time_span(&self) -> Option<(f64, f64)> {
        match &self.rows {
            Rows::ByTime(t) => Some((t.first()?.0, t.last()?.0)),
            Rows::ByName(_) => None,
        }
    }

    /// What reading the log found that the user should know, each a sentence (no file name): dropout rows passed
    /// over, times listed twice with different altitudes.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }
}

/// The column photos are matched by.
#[derive(Debug, Clone, Copy)]
enum Key {
    File(usize),
    Time(usize),
}

impl Key {
    /// The file's column (a log by name) or else the time's, as named by the user or found by name.
    fn choose(
        names: &[String],
        given: &Columns,
        line: usize,
        header: &str,
    ) -> std::result::Result<Key, String> {
        if let Some(f) = &given.file {
            return named(names, f, "file", line, header).map(Key::File);
        }
        if let Some(t) = &given.time {
            return named(names, t, "time", line, header).map(Key::Time);
        }
        if let Some(f) = names
            .iter()
            .position(|c| FILE_COLUMNS.contains(&c.as_str()))
        {
            return Ok(Key::File(f));
        }
        let time = names.iter().position(|c| {
            ["time", "datetime", "date_time", "epoch", "unix"]
                .iter()
                .any(|p| c.starts_with(p))
                || c == "utc"
        });
        time.map(Key::Time).ok_or_else(|| {
            format!(
                "line {line}: no column names the photo's file (one of {}) or the time (time, timestamp, \
                 datetime, date time, epoch, utc); the header is {header:?}: name them with \
                 --navigation-columns (e.g. time=NAME,altitude=NAME)",
                FILE_COLUMNS.join(", ")
            )
        })
    }
}

/// The column the user named `name` (compared as [`normal`]).
fn named(
    names: &[String],
    name: &str,
    what: &str,
    line: usize,
    header: &str,
) -> std::result::Result<usize, String> {
    let want = normal(name);
    names.iter().position(|c| *c == want).ok_or_else(|| {
        format!(
            "line {line}: no column named {name:?} (--navigation-columns {what}={name}); the header is {header:?}"
        )
    })
}

/// The altitude's column: named by the user, or the first whose name starts with `altitude`, or contains it, or
/// is `alt` (alone or before `_`, ` ` or `[`).
fn altitude_column(
    names: &[String],
    given: &Columns,
    line: usize,
    header: &str,
) -> std::result::Result<usize, String> {
    if let Some(a) = &given.altitude {
        return named(names, a, "altitude", line, header);
    }
    let short = |c: &str| c == "alt" || c.starts_with("alt_") || c.starts_with("alt[");
    let found = (names.iter().position(|c| c.starts_with("altitude")))
        .or_else(|| names.iter().position(|c| c.contains("altitude")))
        .or_else(|| names.iter().position(|c| short(c)));
    found.ok_or_else(|| {
        format!(
            "line {line}: no altitude column (a name containing \"altitude\", in metres); the header is \
             {header:?}: name it with --navigation-columns altitude=NAME"
        )
    })
}

/// A column's name as it is compared: trimmed, lower case, spaces, `-` and `/` as `_`.
fn normal(name: &str) -> String {
    name.trim()
        .to_lowercase()
        .chars()
        .map(|c| if matches!(c, ' ' | '-' | '/') { '_' } else { c })
        .collect()
}

/// The rows of a log as they are read, and what was passed over.
#[derive(Default)]
struct Table {
    names: Names,
    times: Vec<(f64, f32, u32)>,
    /// Rows after the header (and the units row).
    rows: usize,
    dropouts: usize,
    dropout_lines: Vec<usize>,
}

impl Table {
    /// The altitude of a cell: `Ok(None)` for a dropout (empty, not a number, `NaN`, zero or negative: counted),
    /// an error for an implausible one.
    fn altitude(&mut self, text: &str, line: usize) -> std::result::Result<Option<f32>, String> {
        match text.parse::<f32>() {
            Ok(a) if a > MAX_ALTITUDE_M => Err(format!(
                "line {line}: altitude {text:?} is not a camera's height over the seafloor (at most \
                 {MAX_ALTITUDE_M} m): a no-data marker or another column? Remove such rows, or name the \
                 altitude's column with --navigation-columns altitude=NAME"
            )),
            Ok(a) if a > 0.0 => Ok(Some(a)),
            _ => {
                self.dropout(line);
                Ok(None)
            }
        }
    }

    fn dropout(&mut self, line: usize) {
        self.dropouts += 1;
        if self.dropout_lines.len() < 3 {
            self.dropout_lines.push(line);
        }
    }

    /// The log, or why it cannot be used (too few usable rows).
    fn finish(mut self, path: &Path, by_time: bool) -> std::result::Result<Navigation, String> {
        let usable = self.names.rows.len() + self.times.len();
        let least = if by_time { MIN_TIME_ROWS } else { 1 };
        let lines = |l: &[usize]| {
            l.iter()
                .map(|k| k.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        };
        if self.rows == 0 {
            return Err("no rows: a row per photo (or per time) after the header".into());
        }
        if usable < least {
            return Err(format!(
                "{usable} of {} rows give a usable altitude (a positive number of metres; e.g. line {} has \
                 none): a log {} needs at least {least}; is the altitude's column the right one \
                 (--navigation-columns altitude=NAME)?",
                self.rows,
                lines(&self.dropout_lines),
                if by_time { "by time" } else { "by file name" }
            ));
        }
        let mut notes = Vec::new();
        if self.dropouts > 0 {
            notes.push(format!(
                "{} of {} rows give no altitude (empty, NaN, zero or negative: a dropout, e.g. line {}) and were \
                 passed over{}",
                self.dropouts,
                self.rows,
                lines(&self.dropout_lines),
                if by_time {
                    format!(
                        "; photos between the rows around them have an altitude where those lie at most {MAX_GAP_S} s \
                         apart"
                    )
                } else {
                    String::new()
                }
            ));
        }
        let rows = if by_time {
            // Stable: rows of one time stay in file order, and the first is the one read at that time.
            self.times.sort_by(|a, b| a.0.total_cmp(&b.0));
            let conflicts: Vec<_> = self
                .times
                .windows(2)
                .filter(|w| w[0].0 == w[1].0 && w[0].1 != w[1].1)
                .collect();
            if let Some(w) = conflicts.first() {
                notes.push(format!(
                    "{} time(s) are listed twice with different altitudes (e.g. lines {} and {}: {} m and {} m); \
                     the first row of each is taken",
                    conflicts.len(),
                    w[0].2,
                    w[1].2,
                    w[0].1,
                    w[1].1
                ));
            }
            Rows::ByTime(self.times)
        } else {
            self.names.sort()?;
            Rows::ByName(self.names)
        };
        Ok(Navigation {
            path: path.to_path_buf(),
            sha256: String::new(),
            rows,
            notes,
        })
    }
}

/// The first row under the header is a units row (`s,deg,m`): no cell reads as a number, the altitude's cell is
/// not empty, and (a log by time) the time's cell does not read as a time.
fn units_row(record: &csv::ByteRecord, key: &Key, alt_col: usize) -> bool {
    let cell = |c: usize| cell_text(record.get(c).unwrap_or(b""));
    let no_number = record.iter().all(|c| cell_text(c).parse::<f64>().is_err());
    let key_reads = match *key {
        Key::Time(t) => parse_time(&cell(t)).is_some(),
        Key::File(_) => false,
    };
    no_number && !cell(alt_col).is_empty() && !key_reads
}

fn blank(record: &csv::ByteRecord) -> bool {
    record.iter().all(|c| c.is_empty())
}

fn line_of(record: &csv::ByteRecord) -> usize {
    record.position().map_or(0, |p| p.line() as usize)
}

fn cell_text(cell: &[u8]) -> std::borrow::Cow<'_, str> {
    String::from_utf8_lossy(cell)
}

fn csv_error(e: csv::Error) -> String {
    match e.position() {
        Some(p) => format!("line {}: {e}", p.line()),
        None => e.to_string(),
    }
}

/// A time as seconds since 1970-01-01 00:00 UTC: a number (those seconds), or a date and time, `YYYY-MM-DD` (or
/// `YYYY:MM:DD`, as EXIF writes it, or with `/`), `T` or a space, `HH:MM:SS` with an optional fraction, and an
/// optional `Z` or offset (`+02:00`, `-0330`); without one, UTC.
pub(crate) fn parse_time(text: &str) -> Option<f64> {
    let text = text.trim();
    if let Ok(v) = text.parse::<f64>() {
        return v.is_finite().then_some(v);
    }
    // A date alone is no time.
    let b = text.as_bytes();
    if b.len() <= 11 {
        return None;
    }
    let mut iso = text.to_string();
    if matches!(b[4], b':' | b'/') && b[7] == b[4] {
        iso.replace_range(4..5, "-");
        iso.replace_range(7..8, "-");
    }
    let stamp = match iso.parse::<jiff::Timestamp>() {
        Ok(t) => t,
        Err(_) => {
            let civil: jiff::civil::DateTime = iso.parse().ok()?;
            jiff::tz::Offset::UTC.to_timestamp(civil).ok()?
        }
    };
    Some(stamp.as_second() as f64 + f64::from(stamp.subsec_nanosecond()) * 1e-9)
}

/// Seconds since 1970-01-01 00:00 UTC of a date and time of the proleptic Gregorian calendar (second 60, a leap
/// second, counts as the next minute's 0); `None` for a date or time that does not exist.
pub(crate) fn utc_seconds(y: i32, month: u32, day: u32, h: u32, m: u32, s: u32) -> Option<f64> {
    let date = jiff::civil::Date::new(
        i16::try_from(y).ok()?,
        i8::try_from(month).ok()?,
        i8::try_from(day).ok()?,
    )
    .ok()?;
    if h > 23 || m > 59 || s > 60 {
        return None;
    }
    let midnight = jiff::tz::Offset::UTC
        .to_timestamp(date.to_datetime(jiff::civil::Time::midnight()))
        .ok()?;
    Some((midnight.as_second() + i64::from(h * 3600 + m * 60 + s)) as f64)
}

/// A time zone's offset from UTC in seconds: `Z`, or `+HH:MM`, `-HH:MM`, `+HHMM`, `+HH` (EXIF's `OffsetTime`).
pub(crate) fn parse_offset(text: &str) -> Option<f64> {
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

/// A time as a reader sees it: `2023-06-03 16:27:01Z` (UTC, to the second).
pub(crate) fn iso(t: f64) -> String {
    match jiff::Timestamp::from_second(t.floor() as i64) {
        Ok(s) => s.strftime("%Y-%m-%d %H:%M:%SZ").to_string(),
        Err(_) => format!("{t:.0} s since 1970"),
    }
}

/// The file name of a path in the log, with `/` or `\` between folders.
fn file_name(cell: &str) -> &str {
    cell.rsplit(['/', '\\']).next().unwrap_or("")
}

/// A file name without its extension.
fn stem(name: &str) -> &str {
    match name.rsplit_once('.') {
        Some((s, _)) if !s.is_empty() => s,
        _ => name,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_as(text: &str, how: &ReadAs) -> std::result::Result<Navigation, String> {
        Navigation::parse(Path::new("nav.csv"), text.as_bytes(), how)
    }

    fn parse(text: &str) -> std::result::Result<Navigation, String> {
        parse_as(text, &ReadAs::default())
    }

    fn altitude_of(nav: &Navigation, path: &str) -> Option<f32> {
        nav.photo(Path::new(path)).altitude
    }

    #[test]
    fn reads_plain_and_oplab_logs() {
        let nav = parse("file,altitude\n0001.jpg,3.5\n0002.jpg,4.25\n").unwrap();
        assert_eq!(nav.len(), 2);
        assert_eq!(altitude_of(&nav, "/dive/0002.jpg"), Some(4.25));
        assert_eq!(altitude_of(&nav, "0003.jpg"), None);
        // oplab's columns, a path with folders, a byte-order mark and quoted cells.
        let oplab = "\u{feff}Imagenumber,Northing [m],Easting [m],Depth [m],Roll [deg],Pitch [deg],Heading [deg],\
                     Altitude [m],Timestamp,Latitude [deg],Longitude [deg],relative_path\n\
                     1,0.1,0.2,4000.0,0.5,-1.0,90.0,2.93,1.6e9,-10.0,-120.0,\"image/PR_001_LC16.tif\"\n";
        let nav = parse(oplab).unwrap();
        assert_eq!(altitude_of(&nav, "x/PR_001_LC16.tif"), Some(2.93));
        // By the name without the extension (a log of the raw frames, photos converted to PNG).
        assert_eq!(altitude_of(&nav, "out/PR_001_LC16.png"), Some(2.93));
        // Semicolons, tabs, comments and blank lines.
        let nav = parse("# sledge\n\nimage;Altitude_m\nA.JPG;2.0\n").unwrap();
        assert_eq!(altitude_of(&nav, "A.JPG"), Some(2.0));
        let nav = parse("photo\taltitude\nb.png\t1.5\n").unwrap();
        assert_eq!(altitude_of(&nav, "b.png"), Some(1.5));
        // A quoted cell holding the separator.
        let nav = parse("file,altitude\n\"a,b.png\",1.25\n").unwrap();
        assert_eq!(altitude_of(&nav, "a,b.png"), Some(1.25));
    }

    #[test]
    fn a_stem_of_two_files_matches_neither_by_stem() {
        let nav = parse("file,altitude\na.jpg,3\na.png,4\nc.jpg,5\n").unwrap();
        assert_eq!(altitude_of(&nav, "a.png"), Some(4.0));
        assert_eq!(altitude_of(&nav, "a.tif"), None);
        assert_eq!(altitude_of(&nav, "c.tif"), Some(5.0));
    }

    #[test]
    fn bad_logs_say_where_and_why() {
        let err = |t: &str| parse(t).unwrap_err();
        assert!(err("").contains("empty"));
        assert!(err("name,altitude\na.jpg,3\n").contains("no column names the photo's file"));
        assert!(err("time,altitude\n100,3\nnoon,3\n").contains("line 3"));
        assert!(err("file,depth\na.jpg,3\n").contains("no altitude column"));
        let e = err("file,altitude\na.jpg,3\nd/a.jpg,4\n");
        assert!(
            e.contains("line 3") && e.contains("twice") && e.contains("line 2"),
            "{e}"
        );
        assert!(err("file,altitude\n").contains("no rows"));
        assert!(err("file,altitude\n,3\n").contains("line 2"));
        let e = err("file,altitude\na.jpg,3\nb.jpg,9999\n");
        assert!(e.contains("line 3") && e.contains("9999"), "{e}");
        assert!(err("file,altitude\na.jpg,1e30\n").contains("line 2"));
        let e = err("file,altitude\na.jpg,0\nb.jpg,NaN\n");
        assert!(e.contains("0 of 2 rows") && e.contains("line 2, 3"), "{e}");
        let e = err("time,altitude\n1,3\n2,-1\n");
        assert!(e.contains("1 of 2 rows") && e.contains("at least 2"), "{e}");
    }

    #[test]
    fn dropouts_are_passed_over_and_counted() {
        let nav = parse("time,altitude\n0,2\n1,0\n2,NaN\n3,\n4,-1\n5,3\n").unwrap();
        assert_eq!(nav.len(), 2);
        // Bridged by the gap rule: 5 s apart.
        assert_eq!(nav.altitude_at(2.5), Some(2.5));
        let note = &nav.notes()[0];
        assert!(
            note.starts_with("4 of 6 rows") && note.contains("line 3, 4, 5"),
            "{note}"
        );
        // A photo's row without an altitude leaves that photo unlisted.
        let nav = parse("file,altitude\na.jpg,2\nb.jpg,0\n").unwrap();
        assert_eq!(altitude_of(&nav, "b.jpg"), None);
        assert_eq!(nav.notes().len(), 1);
    }

    #[test]
    fn a_units_row_and_names_as_vehicles_write_them() {
        let nav = parse("Date Time;lat;dvl_altitude_m\ns;deg;m\n2023-06-03T18:27:00+02:00;1;3\n2023-06-03T16:27:02Z;1;5\n")
            .unwrap();
        assert!(nav.by_time() && nav.notes().is_empty());
        assert_eq!(nav.altitude_at(1_685_809_621.0), Some(4.0));
        let nav = parse("file,alt_m\n-,m\na.jpg,2\n").unwrap();
        assert_eq!(altitude_of(&nav, "a.jpg"), Some(2.0));
        // A units row anywhere else is a bad time.
        assert!(parse("time,altitude\n1,2\ns,m\n")
            .unwrap_err()
            .contains("line 3"));
    }

    #[test]
    fn columns_named_by_the_user() {
        let how = |c: &str| ReadAs {
            columns: c.parse().unwrap(),
            clock_offset: 0.0,
        };
        let text = "t_log,height,range\n10,9,2\n11,9,4\n";
        assert!(parse(text).unwrap_err().contains("--navigation-columns"));
        let nav = parse_as(text, &how("time=T_LOG, altitude=range")).unwrap();
        assert_eq!(nav.altitude_at(10.5), Some(3.0));
        let e = parse_as(text, &how("time=when")).unwrap_err();
        assert!(e.contains("no column named \"when\""), "{e}");
        assert!("file=a,time=b".parse::<Columns>().is_err());
        assert!("depth=a".parse::<Columns>().is_err());
        assert_eq!(
            "altitude=Alt [m]"
                .parse::<Columns>()
                .unwrap()
                .altitude
                .as_deref(),
            Some("Alt [m]")
        );
    }

    #[test]
    fn a_clock_offset_moves_the_log_and_conflicting_times_are_said() {
        let how = ReadAs {
            clock_offset: -7200.0,
            ..ReadAs::default()
        };
        let nav = parse_as("time,altitude\n7200,2\n7201,4\n", &how).unwrap();
        assert_eq!(nav.altitude_at(0.5), Some(3.0));
        assert_eq!(nav.time_span(), Some((0.0, 1.0)));
        let nav = parse("time,altitude\n1,2\n2,4\n1,3\n2,4\n").unwrap();
        assert_eq!(nav.altitude_at(1.0), Some(2.0), "the first row of a time");
        let note = &nav.notes()[0];
        assert!(
            note.starts_with("1 time(s)") && note.contains("lines 2 and 4"),
            "{note}"
        );
    }

    #[test]
    fn times_read_as_an_independent_calendar_gives_them() {
        // Seconds since 1970 UTC from Python's datetime.
        for (text, want) in [
            ("2023-06-03T16:27:01Z", 1_685_809_621.0),
            ("2023-06-03 16:27:01", 1_685_809_621.0),
            ("2023:06:03 16:27:01", 1_685_809_621.0),
            ("2023/06/03 16:27:01", 1_685_809_621.0),
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
        assert_eq!(utc_seconds(2023, 6, 3, 16, 27, 1), Some(1_685_809_621.0));
        assert_eq!(utc_seconds(2023, 2, 29, 0, 0, 0), None);
        assert_eq!(iso(1_685_809_621.7), "2023-06-03 16:27:01Z");
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
        let e = Navigation::read(&p, &ReadAs::default())
            .unwrap_err()
            .to_string();
        assert!(e.starts_with(&p.display().to_string()), "{e}");
        let e = Navigation::read(&d.path().join("none.csv"), &ReadAs::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("none.csv"), "{e}");
        let e = Navigation::read(d.path(), &ReadAs::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("a folder"), "{e}");
    }
}
