//! The figures' text, drawn glyph by glyph at the font's own positions.
//!
//! plotters' ab_glyph text drawing (0.3.7) rasterises each glyph at the origin and then pastes
//! it at the pen position cut to whole pixels, dropping the glyph's left side bearing, and it
//! rounds the vertical offset of tall and short glyphs in opposite directions: "p99 37 0 µs",
//! "en d to end", a decimal point a pixel above the baseline. [`PngBackend`] is the bitmap
//! backend with that one step replaced: every glyph is placed at its exact pen position (the
//! advances and kerning that plotters also measures the text's width with) on one baseline,
//! and rasterised there. Everything else is the bitmap backend's own.

use std::sync::OnceLock;

use ab_glyph::{Font, FontRef, ScaleFont, point};
use plotters::prelude::*;
use plotters_backend::text_anchor::{HPos, VPos};
use plotters_backend::{BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingErrorKind, FontStyle};

/// The bitmap backend, drawing text with [`draw_glyphs`].
pub struct PngBackend<'a>(pub BitMapBackend<'a>);

/// The embedded DejaVu Sans in `style` (bold, or regular for any other).
fn font(style: FontStyle) -> &'static FontRef<'static> {
    static REGULAR: OnceLock<FontRef<'static>> = OnceLock::new();
    static BOLD: OnceLock<FontRef<'static>> = OnceLock::new();
    let (cell, bytes) = match style {
        FontStyle::Bold => (&BOLD, dejavu::sans::bold()),
        _ => (&REGULAR, dejavu::sans::regular()),
    };
    cell.get_or_init(|| FontRef::try_from_slice(bytes).expect("the embedded font loads"))
}

/// Rasterises `text` at `size` pixels, calling `put(x, y, coverage)` for each pixel it covers.
/// The text starts at x = 0; its baseline lies at the font's ascent below y = 0, so the text
/// sits in the box plotters lays it out in (its width: the sum of advances and kerning; its
/// height: about the ascent), with only descenders below.
pub fn draw_glyphs(font: &FontRef<'_>, size: f32, text: &str, mut put: impl FnMut(i32, i32, f32)) {
    let scaled = font.as_scaled(size);
    let baseline = scaled.ascent();
    let mut pen = 0.0;
    let mut previous = None;
    for c in text.chars() {
        let id = scaled.glyph_id(c);
        if let Some(previous) = previous {
            pen += scaled.kern(previous, id);
        }
        previous = Some(id);
        if let Some(outline) = font.outline_glyph(id.with_scale_and_position(size, point(pen, baseline))) {
            let bounds = outline.px_bounds();
            let (x0, y0) = (bounds.min.x as i32, bounds.min.y as i32);
            outline.draw(|x, y, coverage| put(x0 + x as i32, y0 + y as i32, coverage));
        }
        pen += scaled.h_advance(id);
    }
}

impl DrawingBackend for PngBackend<'_> {
    type ErrorType = <BitMapBackend<'static> as DrawingBackend>::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.0.get_size()
    }

    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.ensure_prepared()
    }

    fn present(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.present()
    }

    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_pixel(point, color)
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_line(from, to, style)
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_rect(upper_left, bottom_right, style, fill)
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_path(path, style)
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_circle(center, radius, style, fill)
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.fill_polygon(vert, style)
    }

    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        size: (u32, u32),
        src: &[u8],
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.blit_bitmap(pos, size, src)
    }

    /// plotters' own text drawing (anchor, rotation, clipping) with the glyphs from
    /// [`draw_glyphs`]. The layout box is plotters' own, so that what plotters measured to place
    /// the text is where it is drawn.
    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        let color = style.color();
        if color.alpha == 0.0 {
            return Ok(());
        }
        let ((min_x, min_y), (max_x, max_y)) =
            style.layout_box(text).map_err(|e| DrawingErrorKind::FontError(Box::new(e)))?;
        let (width, height) = (max_x - min_x, max_y - min_y);
        let dx = match style.anchor().h_pos {
            HPos::Left => 0,
            HPos::Right => -width,
            HPos::Center => -width / 2,
        };
        let dy = match style.anchor().v_pos {
            VPos::Top => 0,
            VPos::Center => -height / 2,
            VPos::Bottom => -height,
        };
        let transform = style.transform();
        let mut result = Ok(());
        draw_glyphs(font(style.style()), style.size() as f32, text, |x, y, coverage| {
            let (x, y) = transform.transform(x + dx - min_x, y + dy - min_y);
            let pixel = BackendColor { alpha: color.alpha * f64::from(coverage), rgb: color.rgb };
            if result.is_ok() {
                result = self.0.draw_pixel((pos.0 + x, pos.1 + y), pixel);
            }
        });
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `text` at `size` drawn at (10, 10) through the figures' backend on a white bitmap: whether
    /// each pixel is inked, rows of columns.
    fn render(text: &str, size: f64) -> Vec<Vec<bool>> {
        let (w, h) = (400u32, 60u32);
        let mut buffer = vec![255u8; (w * h * 3) as usize];
        {
            crate::tools::plot::register_fonts();
            let area = PngBackend(BitMapBackend::with_buffer(&mut buffer, (w, h))).into_drawing_area();
            area.draw_text(text, &(crate::tools::plot::FONT, size).into_font().color(&BLACK), (10, 10)).unwrap();
            area.present().unwrap();
        }
        buffer.chunks(w as usize * 3).map(|row| row.chunks(3).map(|p| p[0] < 160).collect()).collect()
    }

    /// Runs of inked columns, left to right: each glyph's ink, for glyphs that do not touch.
    fn ink_runs(image: &[Vec<bool>]) -> Vec<std::ops::Range<usize>> {
        let inked: Vec<bool> = (0..image[0].len()).map(|x| image.iter().any(|row| row[x])).collect();
        let mut runs = Vec::new();
        let mut start = None;
        for (x, inked) in inked.into_iter().chain([false]).enumerate() {
            match (inked, start) {
                (true, None) => start = Some(x),
                (false, Some(s)) => {
                    runs.push(s..x);
                    start = None;
                }
                _ => {}
            }
        }
        runs
    }

    /// Where the font puts each glyph's ink, pixels from the text's start: its pen position (the
    /// advances and kerning before it) plus its outline's extent.
    fn font_ink(text: &str, size: f32) -> Vec<(f32, f32)> {
        let font = font(FontStyle::Normal);
        let scaled = font.as_scaled(size);
        let mut pen = 0.0;
        let mut previous = None;
        let mut out = Vec::new();
        for c in text.chars() {
            let id = scaled.glyph_id(c);
            if let Some(previous) = previous {
                pen += scaled.kern(previous, id);
            }
            previous = Some(id);
            if let Some(outline) = font.outline(id) {
                let scale = scaled.h_scale_factor();
                out.push((pen + outline.bounds.min.x * scale, pen + outline.bounds.max.x * scale));
            }
            pen += scaled.h_advance(id);
        }
        out
    }

    /// The gaps between glyphs, as drawn, are the font's: each glyph's ink lies where its pen
    /// position and outline put it, within a pixel of antialiasing, so "370" reads as one number
    /// and a decimal point sits between its digits. plotters 0.3.7's own drawing fails this ("37
    /// 0": it drops each glyph's bearing and cuts its position to a whole pixel).
    #[test]
    fn glyphs_are_drawn_where_the_font_places_them() {
        for (text, size) in [("370.5", 16.0), ("p99 370 µs", 13.0), ("end to end", 16.0), ("1.04 ms", 17.0)] {
            let runs = ink_runs(&render(text, size));
            let expected = font_ink(text, size as f32);
            // Every glyph of these strings stands apart at these sizes (the count checks it).
            assert_eq!(runs.len(), expected.len(), "{text} at {size}: ink runs {runs:?}, font {expected:?}");
            for (run, (start, end)) in runs.iter().zip(&expected) {
                let (start, end) = (start + 10.0, end + 10.0);
                assert!(
                    (run.start as f32 - start).abs() <= 1.0 && (run.end as f32 - end).abs() <= 1.0,
                    "{text} at {size}: a glyph inked at {run:?}, the font puts it at {start:.1}..{end:.1}"
                );
            }
        }
    }

    /// One baseline: the decimal point's ink ends on the bottom row of the flat-footed 1s
    /// beside it (plotters 0.3.7 rounds short and tall glyphs apart: a raised point).
    #[test]
    fn a_decimal_point_sits_on_the_baseline() {
        for size in [13.0, 14.0, 16.0, 17.0] {
            let image = render("1.1", size);
            let bottom = |run: &std::ops::Range<usize>| image.iter().rposition(|row| row[run.clone()].contains(&true));
            let runs = ink_runs(&image);
            assert_eq!(runs.len(), 3, "{runs:?}");
            assert_eq!(bottom(&runs[1]), bottom(&runs[0]), "at {size}: the point against the first 1");
            assert_eq!(bottom(&runs[1]), bottom(&runs[2]), "at {size}: the point against the second 1");
        }
    }
}
