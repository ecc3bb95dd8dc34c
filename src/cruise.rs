//! A cruise: several dives in one folder, corrected one after the other with the same options
//! (`abysslight correct --cruise CRUISE --out OUT`).
//!
//! Layout: every folder `CRUISE/<dive>/` that holds a `survey/` folder is a dive; its water-column frames are in
//! `CRUISE/<dive>/water-column/` (without it, and without `--scatter`, the dive gets `S = 0` and a warning, as a
//! single `correct` run without `--water-column` does). Dive `<dive>` is written to `OUT/<dive>/`, with its own
//! `_abysslight/` report. A dive's navigation log, where it has one, is `CRUISE/<dive>/navigation.csv` (each
//! photo's altitude: `--navigation`). Dives run in natural name order (dive2 before dive10). Other folders and files
//! in `CRUISE` are passed over.
//!
//! ```text
//! CRUISE/dive042/water-column/*.jpg   ->  OUT/dive042/...
//! CRUISE/dive042/survey/*.jpg
//! CRUISE/dive042/navigation.csv       (optional)
//! CRUISE/dive043/water-column/*.jpg   ->  OUT/dive043/...
//! CRUISE/dive043/survey/*.jpg
//! ```

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::io::gate::{Gate, Output};
use crate::report::{Progress, Report};
use crate::run::merge::{merge_shards, Merged};
use crate::run::options::{Options, Shard};

/// Folder of a dive's survey photos, below the dive's folder.
pub(crate) const SURVEY: &str = "survey";
/// Folder of a dive's water-column frames, below the dive's folder.
pub(crate) const WATER_COLUMN: &str = "water-column";
/// A dive's navigation log (each photo's altitude), in the dive's folder.
pub(crate) const NAVIGATION: &str = "navigation.csv";

/// One dive of a cruise.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Dive {
    /// The dive folder's name (also the name of its output folder).
    pub name: String,
    /// `CRUISE/<dive>/survey`.
    pub survey: PathBuf,
    /// `CRUISE/<dive>/water-column`, where it exists.
    pub water_column: Option<PathBuf>,
    /// `CRUISE/<dive>/navigation.csv`, where it exists.
    pub navigation: Option<PathBuf>,
}

impl Dive {
    /// The options of this dive's run: `base` with the dive's survey, water column (unless `base` gives a
    /// `scatter` image for every dive), navigation log (its own or none) and `out_root/<dive>` as output.
    pub fn options(&self, base: &Options, out_root: &Path) -> Options {
        Options {
            survey: Some(self.survey.clone()),
            water_column: if base.scatter.is_some() {
                None
            } else {
                self.water_column.clone()
            },
            navigation: self.navigation.clone(),
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
            let (wc, nav) = (dir.join(WATER_COLUMN), dir.join(NAVIGATION));
            Dive {
                name,
                survey: dir.join(SURVEY),
                water_column: wc.is_dir().then_some(wc),
                // Whatever is there by that name: a folder or a FIFO is that dive's error (named), not passed over.
                navigation: std::fs::symlink_metadata(&nav).is_ok().then_some(nav),
            }
        })
        .collect())
}

/// The folders every dive of a cruise reads: its survey and its water-column folder, the latter whether or not it
/// exists (photos written there would be read as the dive's water column by the next run), each named for a
/// message.
fn dive_inputs(dives: &[Dive]) -> Vec<(String, PathBuf)> {
    let mut inputs = Vec::new();
    for d in dives {
        inputs.push((format!("survey of dive {}", d.name), d.survey.clone()));
        let wc = d.water_column.clone().unwrap_or_else(|| {
            d.survey
                .parent()
                .map_or_else(|| PathBuf::from(WATER_COLUMN), |p| p.join(WATER_COLUMN))
        });
        inputs.push((format!("water column of dive {}", d.name), wc));
        if let Some(nav) = &d.navigation {
            inputs.push((format!("navigation log of dive {}", d.name), nav.clone()));
        }
    }
    inputs
}

/// A cruise about to be corrected: its dives, and the write gate that protects every dive's inputs from every
/// dive's writes for as long as it is held.
#[derive(Debug)]
pub(crate) struct CruiseRun {
    /// The dives, in natural name order.
    pub dives: Vec<Dive>,
    _gate: Gate,
}

/// Name of the file a sharded cruise's task `K/N` leaves in `OUT/_abysslight/`: the dives it was given, so that
/// `merge-shards OUT` names the dives no task wrote a report for.
fn dives_file(shard: Shard) -> String {
    format!("cruise-shard-{}-of-{}.json", shard.index, shard.count)
}

/// Before the first write of a cruise: find its dives, check every output path (`out` and each `out/<dive>`)
/// against every dive's inputs ([`dive_inputs`]) and hold them in a write gate; with `--shard K/N`, record the
/// dives this task was given in `out/_abysslight/cruise-shard-K-of-N.json` (for [`merge_cruise`]).
pub(crate) fn open_cruise(cruise: &Path, out: &Path, shard: Option<Shard>) -> Result<CruiseRun> {
    let dives = find_dives(cruise)?;
    let outs: Vec<PathBuf> = dives.iter().map(|d| out.join(&d.name)).collect();
    let mut outputs = vec![Output::Folder("--out", out)];
    outputs.extend(
        outs.iter()
            .map(|p| Output::Folder("--out (a dive's output)", p)),
    );
    let named = dive_inputs(&dives);
    let inputs: Vec<(&str, &Path)> = named
        .iter()
        .map(|(w, p)| (w.as_str(), p.as_path()))
        .collect();
    let gate = Gate::open(&outputs, &inputs)?;
    if let Some(s) = shard {
        let path = out.join(crate::io::WORK_DIR).join(dives_file(s));
        let names: Vec<&str> = dives.iter().map(|d| d.name.as_str()).collect();
        let record = serde_json::json!({
            "cruise": cruise,
            "shard": s,
            "dives": names,
        });
        crate::io::write_with(&path, |w| {
            serde_json::to_writer_pretty(w, &record).map_err(|e| Error::Encode {
                path: path.clone(),
                reason: e.to_string(),
            })
        })?;
    }
    Ok(CruiseRun { dives, _gate: gate })
}

/// The dives the tasks of a sharded cruise into `out` were given (from the files [`open_cruise`] leaves), in
/// natural name order; `None` when `out` is not the output of a sharded cruise.
pub(crate) fn recorded_dives(out: &Path) -> Option<Vec<String>> {
    let work = out.join(crate::io::WORK_DIR);
    let mut names: Vec<String> = Vec::new();
    let mut found = false;
    for e in std::fs::read_dir(work).ok()?.flatten() {
        let file = e.file_name().to_string_lossy().into_owned();
        if !(file.starts_with("cruise-shard-") && file.ends_with(".json")) {
            continue;
        }
        found = true;
        // A list of dive names: a regular file of at most 16 MiB, or as good as none.
        let listed = crate::io::whole::read_text(&e.path(), 16 << 20, "list of a cruise's dives")
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .and_then(|v| {
                v["dives"].as_array().map(|a| {
                    a.iter()
                        .filter_map(|n| n.as_str().map(str::to_owned))
                        .collect::<Vec<_>>()
                })
            })
            .unwrap_or_default();
        for n in listed {
            if !names.contains(&n) {
                names.push(n);
            }
        }
    }
    alphanumeric_sort::sort_str_slice(&mut names);
    found.then_some(names)
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
    let run = open_cruise(cruise, &out, base.shard)?;
    Ok(run
        .dives
        .iter()
        .cloned()
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

/// `merge-shards` over the output of a sharded cruise: every `out/<dive>/` that has an `_abysslight/` folder and
/// every dive the tasks were given (recorded in the output folder), in natural name order, each merged on its own; a dive
/// the tasks were given that has no reports is an error naming it.
pub fn merge_cruise(out: &Path) -> Result<Vec<(String, Result<Merged>)>> {
    let rd = std::fs::read_dir(out).map_err(|e| Error::io(out, e))?;
    let mut names: Vec<String> = rd
        .flatten()
        .filter(|e| e.path().join(crate::io::WORK_DIR).is_dir())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    let given = recorded_dives(out).unwrap_or_default();
    for n in &given {
        if !names.contains(n) {
            names.push(n.clone());
        }
    }
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
            let dir = out.join(&n);
            let r = if dir.join(crate::io::WORK_DIR).is_dir() {
                merge_shards(&dir)
            } else {
                Err(Error::Usage(format!(
                    "dive {n}: the tasks of the cruise were given this dive but none wrote a report into {} (its \
                     survey unreadable or empty when they ran? see the tasks' logs): correct it, then rerun the \
                     tasks",
                    dir.display()
                )))
            };
            (n, r)
        })
        .collect())
}
