//! Figures as PNG (plotters' bitmap backend), with an embedded font so a figure renders the same
//! on a machine with no fonts installed. `figure`: the engine that draws a figure of panels over
//! time (`model/figure.rs` describes one); `latency`: latency distributions (bench, plot,
//! compare); `run`: a run folder's figures (`looplab plot`); `misses`: the deadline misses by
//! their cause's kind, one colour map for every figure; `paper`: the papers' figures reproduced,
//! as each scenario declares them.

pub mod fault_zoom;
pub mod figure;
pub mod latency;
pub mod misses;
pub mod paper;
pub mod run;
pub mod text;

use std::path::Path;
use std::sync::Once;

use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;

pub use text::PngBackend;

/// A figure's font family; registered once per process from the embedded DejaVu Sans.
pub const FONT: &str = "sans-serif";

/// Series colours (matplotlib's first seven, which readers of papers know).
pub const COLOURS: [RGBColor; 7] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(127, 127, 127),
];

/// The colour of series `i`.
pub fn colour(i: usize) -> RGBColor {
    COLOURS[i % COLOURS.len()]
}

/// Registers the font with plotters, which measures text with it ([`PngBackend`] draws it).
pub(crate) fn register_fonts() {
    static FONTS: Once = Once::new();
    FONTS.call_once(|| {
        for (style, bytes) in [(FontStyle::Normal, dejavu::sans::regular()), (FontStyle::Bold, dejavu::sans::bold())] {
            plotters::style::register_font(FONT, style, bytes).unwrap_or_else(|_| panic!("the embedded font loads"));
        }
    });
}

/// Draws a PNG of `size` pixels with `draw` on a white canvas and writes it to `path` (staged:
/// see [`Staged`]).
pub fn draw_png(path: &Path, size: (u32, u32), draw: impl FnOnce(&Canvas<'_>) -> Result<()>) -> Result<()> {
    let staged = Staged::new(path)?;
    {
        let root = png(staged.path(), size)?;
        draw(&root)?;
        root.present().map_err(plot_error)?;
    }
    staged.commit()
}

/// What a figure is drawn on.
pub type Canvas<'a> = DrawingArea<PngBackend<'a>, Shift>;

/// A white PNG canvas of `size` pixels at `path`; `present()` it to write the file.
fn png(path: &Path, size: (u32, u32)) -> Result<Canvas<'_>> {
    register_fonts();
    let root = PngBackend(BitMapBackend::new(path, size)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_error)?;
    Ok(root)
}

/// A figure drawn where no one else can reach it, then written where it goes. plotters writes
/// its file by name: in a run folder another user owns, the name could be swapped for a link
/// between a check and that write (and root would write through it). So it draws into a folder
/// of this process's own (0700, under the temporary folder), and [`Staged::commit`] writes the
/// bytes to the figure's path through one checked descriptor (`run_file`: no link followed, a
/// regular file only). The folder goes when the value does.
struct Staged {
    dir: tempfile::TempDir,
    file: std::path::PathBuf,
    dest: std::path::PathBuf,
}

impl Staged {
    /// Stages the figure that goes to `dest`.
    pub fn new(dest: &Path) -> Result<Self> {
        let dir = tempfile::Builder::new().prefix("looplab-figure-").tempdir()?;
        let file = dir.path().join("figure.png");
        Ok(Staged { dir, file, dest: dest.to_path_buf() })
    }

    /// Where plotters draws it.
    pub fn path(&self) -> &Path {
        &self.file
    }

    /// Writes the drawn figure to its path.
    pub fn commit(self) -> Result<()> {
        let bytes = std::fs::read(&self.file)?;
        crate::runtime::storage::run_file::write(&self.dest, &bytes)?;
        drop(self.dir);
        Ok(())
    }
}

/// plotters' errors carry the backend's error type; the figures report them as text.
pub fn plot_error(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("drawing a figure: {e}")
}

/// A legend's short line in a series' colour.
pub fn legend_mark(x: i32, y: i32, colour: RGBColor) -> PathElement<(i32, i32)> {
    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_png_with_text_is_written() {
        let path = std::env::temp_dir().join(format!("looplab-png-test-{}.png", std::process::id()));
        draw_png(&path, (200, 100), |root| {
            root.draw_text("latency, µs", &(FONT, 16).into_font().color(&BLACK), (10, 40)).map_err(plot_error)
        })
        .unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    }
}
