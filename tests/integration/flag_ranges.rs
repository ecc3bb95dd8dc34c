//! Every numeric flag of every subcommand is range-checked before anything is read or written (before: `sheet
//! --width` huge aborted, `bench --size 0x0` panicked, `evaluate --cell 1e-300` grew without bound, `simulate
//! --noise nan` wrote black photos, `--limit` near 2^64 with `--shard` wrote nothing and exited 0).

use crate::common;

use std::process::Command;

use common::{s, BIN};

#[test]
fn out_of_range_numbers_are_usage_errors_naming_the_flag() {
    let d = tempfile::tempdir().unwrap();
    let (a, b) = (d.path().join("a"), d.path().join("b"));
    for p in [&a, &b] {
        std::fs::create_dir_all(p).unwrap();
    }
    let out = d.path().join("out");
    let (sheet, json) = (d.path().join("s.png"), d.path().join("e.json"));
    #[rustfmt::skip]
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["sheet", s(&a), s(&b), s(&sheet), "--width", "4000000000"], "--width"),
        (vec!["sheet", s(&a), s(&b), s(&sheet), "--width", "0"], "--width"),
        (vec!["sheet", s(&a), s(&b), s(&sheet), "--rows", "0"], "--rows"),
        (vec!["bench", "--size", "0x0"], "--size"),
        (vec!["evaluate", s(&a), "--cell", "1e-300", "--json", s(&json)], "--cell"),
        (vec!["evaluate", s(&a), "--cell", "nan", "--json", s(&json)], "--cell"),
        (vec!["simulate", "--noise", "nan", "--out", s(&out)], "--noise"),
        (vec!["simulate", "--altitude=-1", "--out", s(&out)], "--altitude"),
        (vec!["simulate", "--size", "0x0", "--out", s(&out)], "--size"),
        (vec!["simulate", "--contamination", "2", "--out", s(&out)], "--contamination"),
        (vec!["simulate", "--white-balance", "nan,1,1", "--out", s(&out)], "--white-balance"),
    ];
    for (args, flag) in cases {
        let o = Command::new(BIN).args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(flag), "{args:?}: {err}");
    }
    assert!(
        !out.exists(),
        "simulate wrote before its flags were checked"
    );
}

/// `--limit` near 2^64 with a shard: the shard's photos, not none.
#[test]
fn a_huge_limit_with_a_shard_corrects_the_shard() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = (d.path().join("survey"), d.path().join("water"));
    for p in [&survey, &water] {
        std::fs::create_dir_all(p).unwrap();
    }
    for i in 0..9u32 {
        image::RgbImage::from_fn(32, 24, |x, y| {
            image::Rgb([((x * 5 + y * 3 + i * 17) % 200 + 30) as u8, 90, 60])
        })
        .save(survey.join(format!("IMG_{i:04}.png")))
        .unwrap();
    }
    image::RgbImage::from_pixel(32, 24, image::Rgb([10, 12, 14]))
        .save(water.join("wc.png"))
        .unwrap();
    let out = d.path().join("out");
    #[rustfmt::skip]
    let o = Command::new(BIN)
        .args(["correct", "-q", "--survey", s(&survey), "--water-column", s(&water), "--out", s(&out), "--window", "3",
               "--shard", "2/3", "--limit", "18446744073709551615"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let written: Vec<_> = (0..9)
        .filter(|i| out.join(format!("IMG_{i:04}.png")).exists())
        .collect();
    assert_eq!(written, vec![3, 4, 5]);
}
