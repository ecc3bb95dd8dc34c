//! Run abysslight over the real photo sets in `../shared/data/real/` and make a before/after sheet for each,
//! for looking at the results locally. The photos' licences do not allow committing them or images made from
//! them: everything goes to `target/real-sheets/` (or the folder given), which git ignores.
//!
//! ```sh
//! cargo run --release --example real_sheets -- [DATA_DIR] [OUT_DIR]
//! ```
//! Each set runs with the options its footage needs (masks for burned-in overlays, sRGB for camera JPEGs, a
//! window that fits the number of frames); the list below says why. Per set: `OUT_DIR/<set>/corrected/` (with
//! `_abysslight/report.json`, `overview.png`, `flagged.png`) and `OUT_DIR/<set>.png` (input | corrected | F·C).

use std::path::PathBuf;

use abysslight::Options;
use abysslight::Silent;
use abysslight::Transfer;

struct Set {
    name: &'static str,
    survey: &'static str,
    water_column: Option<&'static str>,
    window: usize,
    mask_auto: bool,
    why: &'static str,
}

const SETS: &[Set] = &[
    Set {
        name: "nephrops-1627",
        survey: "nephrops-uwtv-burrows/run_20230603_1627",
        water_column: None,
        window: 15,
        mask_auto: true,
        why: "homogeneous mud under towed lamps; burned-in text and laser dots need the auto mask",
    },
    Set {
        name: "nephrops-1632",
        survey: "nephrops-uwtv-burrows/run_20230604_1632",
        water_column: None,
        window: 15,
        mask_auto: true,
        why: "second run of the same sledge",
    },
    Set {
        name: "aurlab-structure",
        survey: "aurlab-trondheimsfjord-rov/with_structure_left",
        water_column: Some("aurlab-trondheimsfjord-rov/watercolumn_left"),
        window: 7,
        mask_auto: false,
        why: "S from real water-column frames; the 13 survey frames are mostly structure (a breakdown case: expect flags)",
    },
    Set {
        name: "aqualoc",
        survey: "mosaic-library-video-snippets/aqualoc_frames",
        water_column: None,
        window: 9,
        mask_auto: false,
        why: "greyscale deep ROV camera, cluttered scene (breakdown case)",
    },
    Set {
        name: "sparus",
        survey: "mosaic-library-video-snippets/sparus_frames",
        water_column: None,
        window: 7,
        mask_auto: false,
        why: "small AUV camera, shallow",
    },
    Set {
        name: "mbari-benthic",
        survey: "mbari-deepsea-track/benthic_frames",
        water_column: None,
        window: 7,
        mask_auto: false,
        why: "near-identical frames: F absorbs the scene (the method needs a moving camera)",
    },
    Set {
        name: "ntnu-dji",
        survey: "ntnu-rov-seafloor-mosaicprogram",
        water_column: None,
        window: 5,
        mask_auto: false,
        why: "six overlapping 11 MP photos, strong cone",
    },
    Set {
        name: "mbari-midwater",
        survey: "mbari-deepsea-track/midwater_frames",
        water_column: None,
        window: 5,
        mask_auto: false,
        why: "five midwater frames (no seafloor): the method does not apply, flags expected",
    },
    Set {
        name: "habcam-samples",
        survey: "habcam-seafloorexplorer/sample-images",
        water_column: None,
        window: 5,
        mask_auto: false,
        why: "unrelated pre-processed singles (no sequence): the method does not apply",
    },
    Set {
        name: "habcam-subjects",
        survey: "habcam-seafloorexplorer/subjects_standard",
        water_column: None,
        window: 5,
        mask_auto: false,
        why: "unrelated pre-processed singles (no sequence): the method does not apply",
    },
    Set {
        name: "funie-euvp",
        survey: "funie-gan-euvp-test",
        water_column: None,
        window: 7,
        mask_auto: false,
        why: "unrelated 256x256 singles (no sequence, too small for the texture figures)",
    },
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let data = PathBuf::from(args.first().map_or("../shared/data/real", String::as_str));
    let out = PathBuf::from(args.get(1).map_or("target/real-sheets", String::as_str));
    if !data.is_dir() {
        eprintln!(
            "{} not found: the real photos are not part of the repository (give DATA_DIR)",
            data.display()
        );
        std::process::exit(2);
    }
    for set in SETS {
        let survey = data.join(set.survey);
        if !survey.is_dir() {
            eprintln!("{}: {} missing, skipped", set.name, survey.display());
            continue;
        }
        let corrected = out.join(set.name).join("corrected");
        let opts = Options {
            survey: Some(survey.clone()),
            water_column: set.water_column.map(|w| data.join(w)),
            out: Some(corrected.clone()),
            window: Some(set.window),
            transfer: Some(Transfer::Srgb),
            mask_auto: set.mask_auto,
            save_factors: true,
            ..Options::default()
        };
        let started = std::time::Instant::now();
        let report = abysslight::correct_mission(&opts, &Silent)?;
        let flagged = report
            .frames
            .iter()
            .filter(|f| !f.health.flags.is_empty())
            .count();
        let mut kinds: std::collections::BTreeMap<&str, usize> = Default::default();
        for f in report.frames.iter().flat_map(|f| &f.health.flags) {
            *kinds.entry(f.kind()).or_default() += 1;
        }
        let (sheet, _) = abysslight::eval::before_after_sheet(&survey, &corrected, 4, 360)?;
        let sheet_path = out.join(format!("{}.png", set.name));
        abysslight::eval::save_png(&sheet, &sheet_path)?;
        println!(
            "{:<18} {:>4} photos, {:>3} failed, {:>3} flagged {:?}, {:>6.1} s -> {}  ({})",
            set.name,
            report.corrected,
            report.failed,
            flagged,
            kinds,
            started.elapsed().as_secs_f64(),
            sheet_path.display(),
            set.why
        );
    }
    Ok(())
}
