//! The check that a figure's PNG shows what it should: decoded, it is not blank, and each
//! panel's part of the image holds data, pixels in a curve's colour. The axes, the text and the
//! truth's curve are grey or black, the background white and the faults' markers red, so
//! coloured pixels other than that red can only be a curve's: an empty panel has none.
//! (Series colour 3 is a red too and does not count; no run or paper figure gives a panel only
//! that colour.)

// Each test file uses a part of these helpers.
#![allow(dead_code)]

use std::ops::Range;
use std::path::Path;

use looplab_shared::tools::plot::figure::{Cell, grid};

/// The fewest data pixels a panel with a curve shows: a curve across a panel draws hundreds.
pub const MIN_DATA_PIXELS: usize = 50;

/// A decoded PNG: width, height and each pixel's red, green and blue, row by row.
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[u8; 3]>,
}

impl Image {
    pub fn read(path: &Path) -> Image {
        let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut reader = png::Decoder::new(file).read_info().unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut buffer = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buffer).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(info.bit_depth, png::BitDepth::Eight, "{}", path.display());
        let channels = match info.color_type {
            png::ColorType::Rgb => 3,
            png::ColorType::Rgba => 4,
            other => panic!("{}: colour type {other:?}", path.display()),
        };
        let pixels = buffer[..info.buffer_size()].chunks(channels).map(|p| [p[0], p[1], p[2]]).collect();
        Image { width: info.width, height: info.height, pixels }
    }

    fn pixels_in<'a>(&'a self, x: &'a Range<u32>, y: Range<u32>) -> impl Iterator<Item = [u8; 3]> + 'a {
        y.flat_map(move |row| x.clone().map(move |column| self.pixels[(row * self.width + column) as usize]))
    }
}

/// A pixel in a curve's colour: coloured (not white, grey or black) and not the faults' red
/// (200, 0, 0) over white, whose green and blue are equal.
pub fn is_data(pixel: [u8; 3]) -> bool {
    let [r, g, b] = pixel.map(i32::from);
    let chroma = r.max(g).max(b) - r.min(g).min(b);
    let fault_red = r > g && (g - b).abs() <= 3;
    chroma >= 50 && !fault_red
}

/// The data pixels in each cell.
pub fn data_pixels(image: &Image, cells: &[Cell]) -> Vec<usize> {
    cells.iter().map(|cell| image.pixels_in(&cell.x, cell.y.clone()).filter(|p| is_data(*p)).count()).collect()
}

/// Why the image fails the check, if it does: blank (under 1 % of its pixels drawn), or a
/// panel without data.
pub fn check(image: &Image, cells: &[Cell]) -> Result<(), String> {
    let drawn = image.pixels.iter().filter(|p| **p != [255, 255, 255]).count();
    if drawn * 100 < image.pixels.len() {
        return Err(format!("blank: {drawn} of {} pixels drawn", image.pixels.len()));
    }
    let empty: Vec<String> = data_pixels(image, cells)
        .iter()
        .enumerate()
        .filter(|(_, n)| **n < MIN_DATA_PIXELS)
        .map(|(i, n)| format!("panel {} has {n} data pixels", i + 1))
        .collect();
    if empty.is_empty() { Ok(()) } else { Err(empty.join(", ")) }
}

/// Panics unless the PNG at `path`, a figure of `panels` panels (with a caption or not), has the
/// figure's size, is not blank and has data in every panel.
pub fn assert_figure(path: &Path, panels: usize, caption: bool) {
    let ((width, height), cells) = grid(panels, caption);
    let image = Image::read(path);
    assert_eq!((image.width, image.height), (width, height), "{}", path.display());
    if let Err(why) = check(&image, &cells) {
        panic!("{}: {why}", path.display());
    }
}

/// Panics unless the PNG at `path` is not blank and has data within `charts` (the charts' parts
/// of a latency figure, above their legends).
pub fn assert_charts(path: &Path, charts: &[Cell]) {
    if let Err(why) = check(&Image::read(path), charts) {
        panic!("{}: {why}", path.display());
    }
}
