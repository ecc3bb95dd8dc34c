//! Minimal drawing for the pictures abysslight writes for people (mission overview, contact sheets): text from
//! the public-domain `font8x8` glyphs, lines, rectangles and scaled tiles.

use font8x8::UnicodeFonts;
use image::{imageops, Rgb, RgbImage};

/// Background and text colours of the pictures.
pub const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
/// Text and axes.
pub const BLACK: Rgb<u8> = Rgb([0, 0, 0]);
/// Thresholds and grid lines.
pub const GREY: Rgb<u8> = Rgb([150, 150, 150]);
/// Flagged photos.
pub const RED: Rgb<u8> = Rgb([220, 30, 30]);
/// Health series.
pub const BLUE: Rgb<u8> = Rgb([30, 80, 200]);

/// Draw `text` with its top-left corner at `(x, y)`, each font pixel `scale`×`scale` pixels.
pub fn text(img: &mut RgbImage, x: i64, y: i64, s: &str, scale: u32, colour: Rgb<u8>) {
    let mut cx = x;
    for ch in s.chars() {
        let glyph = font8x8::BASIC_FONTS
            .get(ch)
            .or_else(|| font8x8::LATIN_FONTS.get(ch))
            .or_else(|| font8x8::BASIC_FONTS.get('?'));
        if let Some(rows) = glyph {
            for (gy, bits) in rows.iter().enumerate() {
                for gx in 0..8 {
                    if bits & (1 << gx) != 0 {
                        fill_rect(
                            img,
                            cx + gx as i64 * scale as i64,
                            y + gy as i64 * scale as i64,
                            scale,
                            scale,
                            colour,
                        );
                    }
                }
            }
        }
        cx += 8 * scale as i64;
    }
}

/// Width in pixels of `s` drawn at `scale`.
pub fn text_width(s: &str, scale: u32) -> u32 {
    s.chars().count() as u32 * 8 * scale
}

/// Fill a rectangle, clipped to the image.
pub fn fill_rect(img: &mut RgbImage, x: i64, y: i64, w: u32, h: u32, colour: Rgb<u8>) {
    let (iw, ih) = (img.width() as i64, img.height() as i64);
    for yy in y.max(0)..(y + h as i64).min(ih) {
        for xx in x.max(0)..(x + w as i64).min(iw) {
            img.put_pixel(xx as u32, yy as u32, colour);
        }
    }
}

/// A straight line (Bresenham), clipped to the image.
pub fn line(img: &mut RgbImage, (x0, y0): (i64, i64), (x1, y1): (i64, i64), colour: Rgb<u8>) {
    let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
    let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
    let (mut x, mut y, mut err) = (x0, y0, dx + dy);
    loop {
        if x >= 0 && y >= 0 && x < img.width() as i64 && y < img.height() as i64 {
            img.put_pixel(x as u32, y as u32, colour);
        }
        if x == x1 && y == y1 {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x += sx;
        }
        if e2 <= dx {
            err += dx;
            y += sy;
        }
    }
}

/// Tallest tile, as a multiple of the tile's width: a photo taller than that (a 7×4000 line-scan strip) is fitted
/// into `width × TALLEST · width` instead of being drawn hundreds of thousands of pixels tall.
pub const TALLEST: u32 = 2;

/// `img` resized to `width` (aspect kept; a photo more than [`TALLEST`] times as tall as wide to that height and
/// narrower), for a contact sheet tile.
pub fn tile(img: &RgbImage, width: u32, smooth: bool) -> RgbImage {
    let (iw, ih) = (img.width().max(1) as u64, img.height() as u64);
    let h = ((ih * width as u64) / iw).max(1);
    let most = width as u64 * TALLEST as u64;
    let (width, h) = if h > most {
        (((iw * most) / ih.max(1)).max(1) as u32, most)
    } else {
        (width, h)
    };
    let h = h as u32;
    let filter = if smooth {
        imageops::FilterType::Triangle
    } else {
        imageops::FilterType::Nearest
    };
    imageops::resize(img, width, h, filter)
}

/// Tiles laid out in rows on white, with a caption over each column: a contact sheet. Rows may have fewer tiles
/// than there are captions; each column is as wide as its widest tile.
pub fn grid(captions: &[&str], rows: &[Vec<RgbImage>], gap: u32) -> RgbImage {
    let cols = captions
        .len()
        .max(rows.iter().map(Vec::len).max().unwrap_or(0));
    let mut col_w = vec![0u32; cols];
    for (c, w) in col_w.iter_mut().enumerate() {
        *w = rows
            .iter()
            .filter_map(|r| r.get(c))
            .map(RgbImage::width)
            .max()
            .unwrap_or(0)
            .max(captions.get(c).map_or(0, |s| text_width(s, 1)));
    }
    let caption_h = if captions.is_empty() { 0 } else { 12 };
    let row_h: Vec<u32> = rows
        .iter()
        .map(|r| r.iter().map(RgbImage::height).max().unwrap_or(0))
        .collect();
    let width = col_w.iter().map(|w| w + gap).sum::<u32>() + gap;
    let height = gap + caption_h + row_h.iter().map(|h| h + gap).sum::<u32>();
    let mut img = RgbImage::from_pixel(width.max(1), height.max(1), WHITE);
    let mut x = gap as i64;
    for (c, w) in col_w.iter().enumerate() {
        if let Some(caption) = captions.get(c) {
            text(&mut img, x, gap as i64, caption, 1, BLACK);
        }
        let mut y = (gap + caption_h) as i64;
        for (r, h) in rows.iter().zip(&row_h) {
            if let Some(t) = r.get(c) {
                imageops::replace(&mut img, t, x, y);
            }
            y += (h + gap) as i64;
        }
        x += (w + gap) as i64;
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_draws_the_glyph_bits() {
        let mut img = RgbImage::from_pixel(20, 10, WHITE);
        text(&mut img, 0, 0, "I", 1, BLACK);
        let glyph = font8x8::BASIC_FONTS.get('I').unwrap();
        for (y, bits) in glyph.iter().enumerate() {
            for x in 0..8 {
                let black = img.get_pixel(x, y as u32) == &BLACK;
                assert_eq!(black, bits & (1 << x) != 0, "({x},{y})");
            }
        }
        assert_eq!(text_width("abc", 2), 48);
    }

    #[test]
    fn tiles_keep_the_aspect_and_a_strip_fits_in_twice_the_width() {
        let photo = RgbImage::new(400, 300);
        assert_eq!(tile(&photo, 120, true).dimensions(), (120, 90));
        // A 7×4000 strip at width 120 would be 68571 pixels tall: fitted to 240, 0 pixels wide rounded up to 1.
        assert_eq!(
            tile(&RgbImage::new(7, 4000), 120, false).dimensions(),
            (1, 240)
        );
        assert_eq!(
            tile(&RgbImage::new(100, 400), 120, false).dimensions(),
            (60, 240)
        );
        assert_eq!(
            tile(&RgbImage::new(4000, 7), 120, false).dimensions(),
            (120, 1)
        );
    }

    #[test]
    fn line_hits_both_ends_and_clips() {
        let mut img = RgbImage::from_pixel(10, 10, WHITE);
        line(&mut img, (1, 1), (8, 5), RED);
        assert_eq!(img.get_pixel(1, 1), &RED);
        assert_eq!(img.get_pixel(8, 5), &RED);
        line(&mut img, (-5, -5), (20, 20), BLUE); // must not panic
        assert_eq!(img.get_pixel(9, 9), &BLUE);
    }

    #[test]
    fn grid_places_each_tile_at_its_column_and_row() {
        let a = RgbImage::from_pixel(3, 2, RED);
        let b = RgbImage::from_pixel(5, 4, BLUE);
        let g = grid(&[], &[vec![a.clone(), b.clone()], vec![b.clone()]], 1);
        // Columns are 5 wide (widest tile), rows 4 high (tallest tile in the row), gap 1 around everything.
        assert_eq!(g.dimensions(), (1 + 5 + 1 + 5 + 1, 1 + 4 + 1 + 4 + 1));
        assert_eq!(g.get_pixel(1, 1), &RED);
        assert_eq!(g.get_pixel(3, 2), &RED);
        assert_eq!(g.get_pixel(4, 1), &WHITE, "a is only 3 wide");
        assert_eq!(g.get_pixel(7, 1), &BLUE);
        assert_eq!(g.get_pixel(1, 6), &BLUE, "second row starts at 1 + 4 + 1");
        assert_eq!(g.get_pixel(7, 6), &WHITE, "second row has one tile");
    }
}
