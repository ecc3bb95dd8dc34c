//! Outputs are byte-identical whatever the thread count (issue 5): rayon splits rows differently, the writers run
//! in parallel, but every photo must come out the same.

use std::path::Path;

use abysslight::eval::synthetic_photo;
use abysslight::io::{write_atomic, EncodeSettings};
use abysslight::Transfer;
use abysslight::{correct_mission, Options, Silent};

fn mission(dir: &Path) {
    for j in 0..3 {
        let p = synthetic_photo(203, 137, j, true);
        write_atomic(
            &p,
            &dir.join(format!("wc/w{j}.png")),
            EncodeSettings::default(),
        )
        .unwrap();
    }
    for j in 0..9 {
        let p = synthetic_photo(203, 137, j, false);
        let ext = if j % 3 == 0 { "png" } else { "jpg" };
        write_atomic(
            &p,
            &dir.join(format!("survey/img{j}.{ext}")),
            EncodeSettings::default(),
        )
        .unwrap();
    }
}

fn outputs(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

#[test]
fn outputs_are_byte_identical_for_1_2_and_3_threads() {
    let d = tempfile::tempdir().unwrap();
    mission(d.path());
    for transfer in [Transfer::Linear, Transfer::Srgb] {
        let mut runs = Vec::new();
        for threads in [1usize, 2, 3] {
            let out = d.path().join(format!("out-{transfer}-{threads}"));
            let opts = Options {
                water_column: Some(d.path().join("wc")),
                survey: Some(d.path().join("survey")),
                out: Some(out.clone()),
                threads: Some(threads),
                window: Some(5),
                downsample: Some(8),
                transfer: Some(transfer),
                ..Options::default()
            };
            let r = correct_mission(&opts, &Silent).unwrap();
            assert_eq!(r.corrected, 9);
            runs.push(outputs(&out));
        }
        assert_eq!(runs[0].len(), 9);
        assert!(runs[0] == runs[1], "{transfer}: 1 vs 2 threads differ");
        assert!(runs[0] == runs[2], "{transfer}: 1 vs 3 threads differ");
    }
}
