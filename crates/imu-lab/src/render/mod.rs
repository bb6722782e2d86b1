//! Everything the lab renders for people, in one place: numbers with significant digits, HTML
//! escaping, SVG figures (Allan curves of noise-model fits in [`allan`], scatter panels in
//! [`scatter`]) and their PNG rasterisation, the noise lab's tables and HTML report
//! ([`noise`]), the calibration lab's text, HTML report and figures ([`calibration`]), and the
//! step table of either lab's walk ([`steps`]).
pub mod allan;
pub mod calibration;
pub mod noise;
pub mod scatter;
pub mod session_report;
pub mod steps;

use std::path::Path;

use anyhow::{bail, Context, Result};

/// Escape text for HTML and SVG (`&`, `<`, `>`).
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

pub use noise_model::session::sig;

/// Rasterise an SVG document to PNG at its own size on a white background (resvg; the labels
/// use the system's fonts, and are left out where the system has none).
pub fn svg_to_png(svg: &str) -> anyhow::Result<Vec<u8>> {
    use anyhow::Context;
    use resvg::{tiny_skia, usvg};
    let mut opt = usvg::Options::default();
    let db = opt.fontdb_mut();
    db.load_system_fonts();
    // The figures ask for the generic "sans-serif", which fontdb maps to Arial; point it at a
    // sans face this system has (DejaVu Sans on Debian), else at any face at all.
    let family = ["DejaVu Sans", "Liberation Sans", "Arial", "Helvetica"]
        .into_iter()
        .find(|f| {
            db.faces()
                .any(|face| face.families.iter().any(|(n, _)| n == f))
        })
        .map(str::to_string)
        .or_else(|| {
            db.faces()
                .next()
                .and_then(|f| f.families.first().map(|(n, _)| n.clone()))
        });
    if let Some(family) = family {
        db.set_sans_serif_family(family);
    }
    let tree = usvg::Tree::from_str(svg, &opt).context("parsing the figure's SVG")?;
    let size = tree.size().to_int_size();
    let mut pixmap =
        tiny_skia::Pixmap::new(size.width(), size.height()).context("the figure has no area")?;
    pixmap.fill(tiny_skia::Color::WHITE);
    resvg::render(&tree, tiny_skia::Transform::default(), &mut pixmap.as_mut());
    pixmap.encode_png().context("encoding the PNG")
}

/// Write an SVG document to `path` as SVG or PNG, by the name's extension (refusing others).
pub fn write_figure(path: &Path, svg: &str) -> Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let bytes = match ext.as_deref() {
        Some("svg") => svg.as_bytes().to_vec(),
        Some("png") => svg_to_png(svg).with_context(|| format!("rendering {}", path.display()))?,
        _ => bail!("{}: give a .svg or .png name", path.display()),
    };
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn significant_digits() {
        assert_eq!(sig(0.009344468, 4), "0.009344");
        assert_eq!(sig(123.456, 4), "123.5");
        assert_eq!(sig(4.5e-5, 2), "4.5e-5");
        assert_eq!(sig(0.0, 3), "0");
        assert_eq!(sig(f64::NAN, 3), "—");
    }
}
