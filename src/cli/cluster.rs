//! The CLI's part of running on a cluster: `merge-shards` after a job array of `correct --shard K/N` runs, and
//! `correct --cruise` over the dives of a cruise (src/run/merge.rs, src/run/cruise.rs).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use abysslight::cruise::{merge_cruise, open_cruise, recorded_dives};
use abysslight::run::merge::{merge_shards, Merged};
use abysslight::Error;
use clap::Args;

use super::{CorrectArgs, EXIT_OK, EXIT_SOME_FAILED, EXIT_USAGE};

/// `merge-shards --help`: what it reads, examples, exit status.
pub const MERGE_LONG_HELP: &str = "\
Reads OUT/_abysslight/report-shard-K-of-N.json of every shard and writes OUT/_abysslight/report.json,
overview.png and flagged.png as one run over the whole survey would have. Refuses (naming the shard) when a
shard is missing or unfinished, ran with other options, or left photos of its chunk out of its report (a run
with --limit, an edited report): every photo of the survey is corrected or failed in a merged report. Where OUT
holds one folder per dive (correct --cruise), each dive is merged, and a dive the tasks were given that has no
shard reports is named.

Examples:
  sbatch --array=1-16 deploy/slurm/correct-array.sbatch --water-column W --survey S --out OUT
  abysslight merge-shards OUT

  Shards that took their --out from a config file:
    abysslight merge-shards --config dive042.toml

  All shards at once on one machine, then the merge:
    parallel abysslight correct --water-column W --survey S --out OUT --shard {}/8 ::: $(seq 8) && abysslight merge-shards OUT

Exit status:
  0  merged; every photo was corrected
  1  merged, but some files failed in the shards (listed in report.json)
  2  not merged: a shard is missing, unfinished, ran differently or left photos out, or a dive of the cruise
     has no reports (named on stderr)";

#[derive(Args, Debug)]
pub struct MergeShardsArgs {
    /// The --out of the shards (or of a sharded --cruise: every dive in it is merged).
    #[arg(value_name = "OUT", required_unless_present = "config")]
    out: Option<PathBuf>,
    /// The shards' --config file, for its `out` (when OUT is not given: the shards took --out from it).
    #[arg(long, value_name = "FILE", conflicts_with = "out")]
    config: Option<PathBuf>,
    /// No summary line (errors are still printed).
    #[arg(long, short = 'q')]
    quiet: bool,
}

fn summary(m: &Merged) -> String {
    format!(
        "merged {} shards: {} of {} photos in the report ({} corrected, {} failed, {} flagged); report: {}",
        m.shards,
        m.frames,
        m.survey_photos,
        m.corrected,
        m.failed + m.water_column_failed,
        m.flagged,
        m.report_path.display()
    )
}

/// `abysslight merge-shards OUT`.
pub fn merge(a: MergeShardsArgs) -> Result<ExitCode, Error> {
    let out = match (&a.out, &a.config) {
        (Some(out), _) => out.clone(),
        (None, Some(cfg)) => abysslight::Options::from_toml_file(cfg)?
            .out
            .ok_or_else(|| {
                Error::Usage(format!(
                    "merge-shards: {} gives no out = \"DIR\": give OUT, the --out of the shards",
                    cfg.display()
                ))
            })?,
        (None, None) => return Err(Error::Usage("merge-shards: give OUT".into())),
    };
    if out.join(abysslight::io::WORK_DIR).is_dir() && recorded_dives(&out).is_none() {
        let m = merge_shards(&out)?;
        if !a.quiet {
            eprintln!("abysslight: {}", summary(&m));
        }
        return Ok(ExitCode::from(if m.all_ok() {
            EXIT_OK
        } else {
            EXIT_SOME_FAILED
        }));
    }
    let mut code = EXIT_OK;
    for (dive, r) in merge_cruise(&out)? {
        match r {
            Ok(m) => {
                if !a.quiet {
                    eprintln!("abysslight: dive {dive}: {}", summary(&m));
                }
                if !m.all_ok() {
                    code = code.max(EXIT_SOME_FAILED);
                }
            }
            Err(e) => {
                eprintln!("abysslight: dive {dive}: error: {e}");
                code = EXIT_USAGE;
            }
        }
    }
    Ok(ExitCode::from(code))
}

/// The `--report FILE` of dive `dive` in a cruise: `FILE-<dive>.<ext>` beside FILE (`-`, stdout, stays `-`).
fn dive_report(file: &Path, dive: &str) -> PathBuf {
    if file == Path::new("-") {
        return file.to_owned();
    }
    let stem = file.file_stem().unwrap_or_default().to_string_lossy();
    let name = match file.extension() {
        Some(ext) => format!("{stem}-{dive}.{}", ext.to_string_lossy()),
        None => format!("{stem}-{dive}"),
    };
    file.with_file_name(name)
}

/// `abysslight correct --cruise DIR --out OUT`: each dive as its own `correct` run (the same flags, the dive's
/// survey, water column and `OUT/<dive>`), one after the other; a dive that fails does not stop the others. The
/// exit status is the worst of the dives'.
pub fn correct_cruise(mut args: CorrectArgs, cruise: &Path) -> Result<ExitCode, Error> {
    let out = args.out.clone().ok_or_else(|| {
        Error::Usage("--cruise needs --out DIR (one folder per dive is made in it)".into())
    })?;
    if out == Path::new("-") {
        return Err(Error::Usage(
            "--cruise writes one folder per dive: --out - cannot be used".into(),
        ));
    }
    if args.navigation.is_some() {
        return Err(Error::Usage(format!(
            "--navigation names one dive's log; with --cruise each dive reads its own, \
             CRUISE/<dive>/{}",
            abysslight::cruise::NAVIGATION
        )));
    }
    // Every output path against every dive's inputs before the first write; held until every dive has run.
    // A dry run writes nothing, not even the record of the dives a sharded cruise's task was given.
    let run = open_cruise(cruise, &out, args.shard.filter(|_| !args.dry_run))?;
    let dives = &run.dives;
    args.cruise = None;
    let report = args.report.clone();
    let mut worst = EXIT_OK;
    let mut failed = Vec::new();
    for (i, d) in dives.iter().enumerate() {
        if !args.quiet {
            eprintln!("abysslight: dive {} ({} of {})", d.name, i + 1, dives.len());
        }
        args.survey = Some(d.survey.clone());
        args.water_column = d.water_column.clone();
        args.navigation = d.navigation.clone();
        args.dive_of_cruise = true;
        args.out = Some(out.join(&d.name));
        // One report file per dive (FILE-<dive>.json beside FILE): one file for all would keep the last dive's.
        args.report = report.as_deref().map(|r| dive_report(r, &d.name));
        let code = match super::correct(&args) {
            Ok(code) => code,
            Err(e) => {
                eprintln!("abysslight: dive {}: error: {e}", d.name);
                ExitCode::from(EXIT_USAGE)
            }
        };
        let c = if code == ExitCode::from(EXIT_OK) {
            EXIT_OK
        } else if code == ExitCode::from(EXIT_SOME_FAILED) {
            EXIT_SOME_FAILED
        } else {
            EXIT_USAGE
        };
        if c != EXIT_OK {
            failed.push(d.name.clone());
        }
        worst = worst.max(c);
    }
    if !failed.is_empty() {
        eprintln!("abysslight: dives with failures: {}", failed.join(", "));
    }
    Ok(ExitCode::from(worst))
}
