//! Before/after contact sheet of a corrected folder, for looking at results (e.g. on the real photos in
//! `../shared/data/real/`, which may not be committed: sheets made from them stay local).
//!
//! ```sh
//! cargo run --release --example before_after -- INPUT_DIR OUTPUT_DIR sheet.png [ROWS] [WIDTH]
//! ```
//! Picks ROWS (default 4) photos evenly spread over the mission and puts each input beside its output, WIDTH
//! (default 480) pixels wide each. With `--save-factors` output, `F·C` is added as a third column.
//! `examples/real_sheets.rs` runs abysslight over every real set and makes these sheets for all of them.

use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        eprintln!("usage: before_after INPUT_DIR OUTPUT_DIR sheet.png [ROWS] [WIDTH]");
        std::process::exit(2);
    }
    let rows: usize = args.get(3).map_or(Ok(4), |s| s.parse())?;
    let width: u32 = args.get(4).map_or(Ok(480), |s| s.parse())?;
    let (sheet, with_factors) = abysslight::eval::before_after_sheet(
        &PathBuf::from(&args[0]),
        &PathBuf::from(&args[1]),
        rows,
        width,
    )?;
    let path = PathBuf::from(&args[2]);
    abysslight::eval::save_png(&sheet, &path)?;
    let columns = if with_factors {
        "input | corrected | F·C"
    } else {
        "input | corrected"
    };
    eprintln!("wrote {} ({columns})", path.display());
    Ok(())
}
