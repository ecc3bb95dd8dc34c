//! A cruise: several dives in one folder, corrected one after the other with the same options
//! (`abysslight correct --cruise CRUISE --out OUT`).
//!
//! Layout: every folder `CRUISE/<dive>/` that holds a `survey/` folder is a dive; its water-column frames are in
//! `CRUISE/<dive>/water-column/` (without it, and without `--scatter`, the dive gets `S = 0` and a warning, as a
//! single `correct` run without `--water-column` does). Dive `<dive>` is written to `OUT/<dive>/`, with its own
//! `_abysslight/` report. Dives run in natural name order (dive2 before dive10). Other folders and files in
//! `CRUISE` are passed over.
//!
//! ```text
//! CRUISE/dive042/water-column/*.jpg   ->  OUT/dive042/...
//! CRUISE/dive042/survey/*.jpg
//! CRUISE/dive043/water-column/*.jpg   ->  OUT/dive043/...
//! CRUISE/dive043/survey/*.jpg
//! ```

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::run::merge::{merge_shards, Merged};
use crate::run::options::Options;
use crate::run::report::{Progress, Report};

/// Folder of a dive's survey photos, below the dive's folder.
pub const SURVEY: &str = "survey";
/// Folder of a dive's water-column frames, below the dive's folder.
pub const WATER_COLUMN: &str = "water-column";

/// One dive of a cruise.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Dive {
    /// The dive folder's name (also the name of its output folder).
    pub name: String,
    /// `CRUISE/<dive>/survey`.
    pub survey: PathBuf,
    /// `CRUISE/<dive>/water-column`, where it exists.
    pub water_column: Option<PathBuf>,
}

impl Dive {
    /// The options of this dive's run: `base` with the dive's survey, water column (unless `base` gives a
    /// `scatter` image for every dive) and `out_root/<dive>` as output.
    pub fn options(&self, base: &Options, out_root: &Path) -> Options {
        Options {
            survey: Some(self.survey.clone()),
            water_column: if base.scatter.is_some() {
                None
            } else {
                self.water_column.clone()
            },
            out: Some(out_root.join(&self.name)),
            report: None,
            ..base.clone()
        }
    }
}

/// The dives of the cruise folder `cruise`, in natural name order; an error when it has none.
pub fn find_dives(cruise: &Path) -> Result<Vec<Dive>> {
    let rd = std::fs::read_dir(cruise).map_err(|e| Error::io(cruise, e))?;
    let mut names: Vec<String> = rd
        .flatten()
        .filter(|e| e.path().join(SURVEY).is_dir())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    alphanumeric_sort::sort_str_slice(&mut names);
    if names.is_empty() {
        return Err(Error::Usage(format!(
            "{}: no dives: a cruise folder holds one folder per dive, each with a {SURVEY}/ folder (and its \
             {WATER_COLUMN}/ frames), e.g. {}/dive042/{SURVEY}",
            cruise.display(),
            cruise.display()
        )));
    }
    Ok(names
        .into_iter()
        .map(|name| {
            let dir = cruise.join(&name);
            let wc = dir.join(WATER_COLUMN);
            Dive {
                name,
                survey: dir.join(SURVEY),
                water_column: wc.is_dir().then_some(wc),
            }
        })
        .collect())
}

/// Correct every dive of `cruise` with the options `base` (its `out` the root of the dives' outputs), one after
/// the other. A dive that cannot run does not stop the others: each dive's result is returned.
pub fn correct_cruise(
    base: &Options,
    cruise: &Path,
    progress: &dyn Progress,
) -> Result<Vec<(Dive, Result<Report>)>> {
    let out = base.out.clone().ok_or_else(|| {
        Error::Usage("--cruise needs --out DIR (one folder per dive is made in it)".into())
    })?;
    let dives = find_dives(cruise)?;
    Ok(dives
        .into_iter()
        .map(|d| {
            let opts = d.options(base, &out);
            progress.stage(&format!(
                "dive {}: {} -> {}",
                d.name,
                d.survey.display(),
                out.join(&d.name).display()
            ));
            let r = opts
                .validate()
                .and_then(|()| crate::run::correct_mission(&opts, progress));
            (d, r)
        })
        .collect())
}

/// `merge-shards` over the output of a sharded cruise: every `out/<dive>/` that has an `_abysslight/` folder, in
/// natural name order, each merged on its own.
pub fn merge_cruise(out: &Path) -> Result<Vec<(String, Result<Merged>)>> {
    let rd = std::fs::read_dir(out).map_err(|e| Error::io(out, e))?;
    let mut names: Vec<String> = rd
        .flatten()
        .filter(|e| e.path().join(crate::io::WORK_DIR).is_dir())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    alphanumeric_sort::sort_str_slice(&mut names);
    if names.is_empty() {
        return Err(Error::Usage(format!(
            "{}: neither the --out of a sharded dive (no {} folder) nor of a sharded cruise (no <dive>/{} \
             folders)",
            out.display(),
            crate::io::WORK_DIR,
            crate::io::WORK_DIR
        )));
    }
    Ok(names
        .into_iter()
        .map(|n| {
            let r = merge_shards(&out.join(&n));
            (n, r)
        })
        .collect())
}
