//! Minimal drawing for the pictures abysslight writes for people (mission overview, contact sheets): text from
//! the public-domain `font8x8` glyphs, lines, rectangles and scaled tiles.

use font8x8::UnicodeFonts;
use image::{imageops, Rgb, RgbImage};

pub const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
pub const BLACK: Rgb<u8> = Rgb([0, 0, 0]);
pub const GREY: Rgb<u8> = Rgb([150, 150, 150]);
pub const RED: Rgb<u8> = Rgb([220, 30, 30]);
pub const BLUE: Rgb<u8> = Rgb([30, 80, 200]);

/// Draw `text` with its top-left corner at `(x, y)`, each font pixel `scale`×`scale` pixels.
pub fn text(img: &mut RgbImage, x: i64, y: i64, s: &str, scale: u32, colour: Rgb<u8>) {
    let mut cx = x;
    for ch in s.chars() {
        let glyph = font8x8::BASIC_FONTS
            .get(ch)
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

/// `img` resized to `width` (aspect kept), for a contact sheet tile.
pub fn tile(img: &RgbImage, width: u32, smooth: bool) -> RgbImage {
    let h = ((img.height() as u64 * width as u64) / img.width().max(1) as u64).max(1) as u32;
    let filter = if smooth {
        imageops::FilterType::Triangle
    } else {
        imageops::FilterType::Nearest
    };
    imageops::resize(img, width, h, filter)
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
    fn line_hits_both_ends_and_clips() {
        let mut img = RgbImage::from_pixel(10, 10, WHITE);
        line(&mut img, (1, 1), (8, 5), RED);
        assert_eq!(img.get_pixel(1, 1), &RED);
        assert_eq!(img.get_pixel(8, 5), &RED);
        line(&mut img, (-5, -5), (20, 20), BLUE); // must not panic
        assert_eq!(img.get_pixel(9, 9), &BLUE);
    }
}
