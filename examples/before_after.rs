//! Before/after contact sheet of a corrected folder, for looking at results (e.g. on the real photos in
//! `../shared/data/real/`, which may not be committed: sheets made from them stay local).
//!
//! ```sh
//! cargo run --release --example before_after -- INPUT_DIR OUTPUT_DIR sheet.png [ROWS] [WIDTH]
//! ```
//! Picks ROWS (default 4) photos evenly spread over the mission and puts each input beside its output, WIDTH
//! (default 480) pixels wide each. With `--save-factors` output, the factor image is added as a third column.

use std::path::PathBuf;

use image::{imageops, RgbImage};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        eprintln!("usage: before_after INPUT_DIR OUTPUT_DIR sheet.png [ROWS] [WIDTH]");
        std::process::exit(2);
    }
    let (input, output, sheet) = (
        PathBuf::from(&args[0]),
        PathBuf::from(&args[1]),
        PathBuf::from(&args[2]),
    );
    let rows: usize = args.get(3).map_or(Ok(4), |s| s.parse())?;
    let width: u32 = args.get(4).map_or(Ok(480), |s| s.parse())?;
    let found = abysslight::io::find_photos(&input)?;
    let n = found.photos.len();
    if n == 0 {
        return Err(format!("no photos in {}", input.display()).into());
    }
    let picks: Vec<usize> = (0..rows.min(n))
        .map(|r| (r * (n - 1)) / (rows.min(n) - 1).max(1))
        .collect();
    let load =
        |p: &std::path::Path| -> Option<RgbImage> { image::open(p).ok().map(|i| i.to_rgb8()) };
    let mut tiles: Vec<Vec<RgbImage>> = Vec::new();
    for &i in &picks {
        let e = &found.photos[i];
        let mut row = Vec::new();
        for p in [
            e.path.clone(),
            output.join(&e.relative),
            output
                .join("_abysslight/factors")
                .join(&e.relative)
                .with_extension("png"),
        ] {
            if let Some(img) = load(&p) {
                let h = (img.height() as u64 * width as u64 / img.width() as u64) as u32;
                row.push(imageops::resize(
                    &img,
                    width,
                    h.max(1),
                    imageops::FilterType::Triangle,
                ));
            }
        }
        tiles.push(row);
    }
    let cols = tiles.iter().map(Vec::len).max().unwrap_or(0) as u32;
    let row_h: Vec<u32> = tiles
        .iter()
        .map(|r| r.iter().map(|t| t.height()).max().unwrap_or(0))
        .collect();
    let gap = 4;
    let mut out = RgbImage::from_pixel(
        cols * (width + gap) + gap,
        row_h.iter().map(|h| h + gap).sum::<u32>() + gap,
        image::Rgb([255, 255, 255]),
    );
    let mut y = gap;
    for (row, h) in tiles.iter().zip(&row_h) {
        for (c, t) in row.iter().enumerate() {
            imageops::replace(
                &mut out,
                t,
                (gap + c as u32 * (width + gap)) as i64,
                y as i64,
            );
        }
        y += h + gap;
    }
    out.save(&sheet)?;
    eprintln!(
        "wrote {} ({} rows: input | corrected | F·C)",
        sheet.display(),
        tiles.len()
    );
    Ok(())
}
