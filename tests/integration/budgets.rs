//! Memory budgets from the header, on every path (docs/threat-model.md, "Bounded allocation per file"): each
//! scenario runs the command line with its address space limited (`ulimit -v`), far below what the hostile file
//! declares and far above what the mission needs, so a path that allocates what a file declares fails the test
//! (an allocation failure: an aborted run, or the file refused as "out of memory") instead of going unnoticed.
//! The large files are sparse or declared only: nothing here writes or reads gigabytes.

#![cfg(target_os = "linux")]

use crate::common;

use std::io::Write;
use std::process::{Command, Output, Stdio};

use common::{moving_mission, png_chunk, report, s, stderr, BIN};

/// Address space the runs may use, in KiB: a mission of tiny photos needs well under a tenth of it.
const LIMIT_KIB: u64 = 700_000;

/// `abysslight ARGS` under `ulimit -v LIMIT_KIB`, with `stdin` on its standard input.
fn limited(args: &[&str], stdin: &[u8]) -> Output {
    limited_to(LIMIT_KIB, args, stdin)
}

/// `abysslight ARGS` under `ulimit -v kib`, with `stdin` on its standard input.
fn limited_to(kib: u64, args: &[&str], stdin: &[u8]) -> Output {
    let script = format!("ulimit -v {kib} && exec \"$0\" \"$@\"");
    let mut child = Command::new("sh")
        .arg("-c")
        .arg(script)
        .arg(BIN)
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut input = child.stdin.take().unwrap();
    let _ = input.write_all(stdin);
    drop(input);
    child.wait_with_output().unwrap()
}

fn jpeg(seed: u32) -> Vec<u8> {
    let px: Vec<u8> = (0..32 * 24)
        .flat_map(|i| {
            let v = ((i * 7 + seed * 31) % 200 + 30) as u8;
            [v, v / 2, 255 - v]
        })
        .collect();
    let mut out = Vec::new();
    jpeg_encoder::Encoder::new(&mut out, 90)
        .encode(&px, 32, 24, jpeg_encoder::ColorType::Rgb)
        .unwrap();
    out
}

fn ihdr(w: u32, h: u32, colour: u8) -> Vec<u8> {
    let mut d = w.to_be_bytes().to_vec();
    d.extend_from_slice(&h.to_be_bytes());
    d.extend_from_slice(&[8, colour, 0, 0, 0]);
    png_chunk(b"IHDR", &d)
}

/// A valid JPEG followed by 3 GB of zeros (a sparse tail: nothing is written) is decoded from the part its header
/// allows; the rest is never read (before: the whole file was read, and with this address space the photo failed
/// "out of memory").
#[test]
fn a_valid_jpeg_with_a_huge_tail_is_read_only_as_far_as_its_header_allows() {
    let d = tempfile::tempdir().unwrap();
    let survey = d.path().join("survey");
    std::fs::create_dir_all(&survey).unwrap();
    for i in 0..6 {
        std::fs::write(survey.join(format!("IMG_{i:04}.jpg")), jpeg(i)).unwrap();
    }
    let tailed = std::fs::OpenOptions::new()
        .write(true)
        .open(survey.join("IMG_0002.jpg"))
        .unwrap();
    tailed.set_len(3 << 30).unwrap();
    let out = d.path().join("out");
    let o = limited(
        &[
            "correct",
            "--survey",
            s(&survey),
            "--out",
            s(&out),
            "--window",
            "3",
            "--threads",
            "2",
        ],
        b"",
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(out.join("IMG_0002.jpg").is_file());
    assert_eq!(report(&out)["failed"], 0);
}

/// A PNG frame on standard input whose chunk declares 2 GB (and a stream that ends long before) is one failed
/// frame, and the frame before it is written (before: the 2 GB were allocated up front; with this address space
/// the run aborted).
#[test]
fn a_png_frame_on_stdin_declaring_2_gb_is_one_failed_frame() {
    let d = tempfile::tempdir().unwrap();
    let mut stream = b"P6\n32 24\n255\n".to_vec();
    stream.extend((0..32 * 24 * 3).map(|i| (i % 251) as u8));
    stream.extend_from_slice(b"\x89PNG\r\n\x1a\n");
    stream.extend(ihdr(64, 64, 2));
    stream.extend_from_slice(&0x7fff_fff0u32.to_be_bytes());
    stream.extend_from_slice(b"IDAT");
    stream.extend_from_slice(&[0u8; 100]);
    let out = d.path().join("out");
    let o = limited(
        &[
            "correct",
            "--survey",
            "-",
            "--out",
            s(&out),
            "--window",
            "3",
        ],
        &stream,
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("stdin frame 1"), "{}", stderr(&o));
    assert!(out.join("frame-000000.ppm").is_file());
}

/// A 12000 × 12000 grey PNG of a few hundred KB among 48 × 32 photos, under `--mask-auto`: it is never decoded
/// at full size (the mission's size is known from the headers), so it costs one skipped photo, and the mask is
/// found from the others (before: `--mask-auto` decoded it, 144 MB and four times that as a raster; with this
/// address space the run aborted).
#[test]
fn mask_auto_never_decodes_a_photo_of_another_size() {
    let d = tempfile::tempdir().unwrap();
    let (survey, water) = moving_mission(d.path(), 9);
    let (w, h) = (12_000u32, 12_000u32);
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    let row = vec![0u8; w as usize + 1];
    for _ in 0..h {
        z.write_all(&row).unwrap();
    }
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend(ihdr(w, h, 0));
    png.extend(png_chunk(b"IDAT", &z.finish().unwrap()));
    png.extend(png_chunk(b"IEND", b""));
    assert!(png.len() < 1 << 20, "the big photo should be a small file");
    std::fs::write(survey.join("img4b.png"), &png).unwrap();
    let out = d.path().join("out");
    #[rustfmt::skip]
    let o = limited_to(
        300_000,
        &["correct", "--survey", s(&survey), "--water-column", s(&water), "--out", s(&out), "--window", "3",
          "--mask-auto", "--threads", "2"],
        b"",
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert_eq!(report(&out)["failed"], 1);
    assert!(
        out.join("_abysslight/mask-auto.png").is_file(),
        "{}",
        stderr(&o)
    );
}
