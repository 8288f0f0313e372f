//! What every figure shares: the font embedded for PNG text, and drawing a
//! figure into an SVG document or PNG bytes.

use plotters::coord::Shift;
use plotters::prelude::*;
use std::sync::OnceLock;

/// Font family name used in the figures. SVG viewers use their own
/// sans-serif font; PNGs use the font embedded at build time.
pub(crate) const FAMILY: &str = "sans-serif";

/// The TrueType font embedded for PNG text (DejaVu Sans from the Debian
/// package `fonts-dejavu-core` unless `REALITYGAP_FONT` named another at
/// build time; see `build.rs`).
static FONT: &[u8] = include_bytes!(env!("REALITYGAP_FONT_PATH"));

/// Registers the embedded font with plotters once.
pub(crate) fn ensure_font() -> Result<(), String> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).map_err(|_| {
                format!(
                    "the font embedded at build time ({}) is not a valid TrueType font",
                    env!("REALITYGAP_FONT_PATH")
                )
            })
        })
        .clone()
}

/// A figure that draws itself on any plotters backend.
pub(crate) trait Draw {
    /// Draws the whole figure on `root`.
    fn draw_on<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>;
}

/// Writes `figure` as `DIR/<stem>.svg` and `DIR/<stem>.png` (`width` x
/// `height`); the two paths. The message names the file that failed.
pub(crate) fn write<T: Draw>(
    figure: &T,
    dir: &std::path::Path,
    stem: &str,
    (width, height): (u32, u32),
) -> Result<Vec<std::path::PathBuf>, String> {
    let svg_path = dir.join(format!("{stem}.svg"));
    let png_path = dir.join(format!("{stem}.png"));
    let io = |p: &std::path::Path, e: std::io::Error| format!("writing {}: {e}", p.display());
    std::fs::write(&svg_path, svg(figure, width, height)?).map_err(|e| io(&svg_path, e))?;
    std::fs::write(&png_path, png(figure, width, height)?).map_err(|e| io(&png_path, e))?;
    Ok(vec![svg_path, png_path])
}

/// `figure` as an SVG document of `width` x `height` user units.
pub(crate) fn svg<T: Draw>(figure: &T, width: u32, height: u32) -> Result<String, String> {
    ensure_font()?;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        figure.draw_on(&root)?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

/// `figure` as PNG file bytes (RGB) of `width` x `height` pixels.
pub(crate) fn png<T: Draw>(figure: &T, width: u32, height: u32) -> Result<Vec<u8>, String> {
    ensure_font()?;
    let mut rgb = vec![255u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        figure.draw_on(&root)?;
        root.present().map_err(|e| e.to_string())?;
    }
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, width, height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().map_err(|e| e.to_string())?;
        w.write_image_data(&rgb).map_err(|e| e.to_string())?;
        w.finish().map_err(|e| e.to_string())?;
    }
    Ok(out)
}
