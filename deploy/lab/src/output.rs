//! What the commands write to a run or sweep directory: files replaced whole, and a PNG
//! rasterised from an SVG with resvg, which needs a font for the text.
//!
//! Fonts for the PNG: the file named by `ALFD_FONT` if set, else the system's fonts (the usual
//! font directories, `/usr/share/fonts` on Linux; `fonts-dejavu-core` is enough). With no font at
//! all (or `ALFD_FONT` set but empty) the PNG is not written and a warning says why; the SVG
//! always is, and the command succeeds either way.

use std::path::Path;
#[cfg(feature = "png")]
use std::sync::Arc;

#[cfg(feature = "png")]
use crate::error::Context as _;

/// Writes `bytes` to `dir/name`, replacing the file whole (a reader never sees half of it); a
/// full disk is waited out (`alfd_harness::DISK_FULL_PATIENCE`).
pub fn write(dir: &Path, name: &str, bytes: &[u8]) -> crate::Result<()> {
    let patience = alfd_harness::DISK_FULL_PATIENCE;
    Ok(alfd_harness::write_atomically_patiently(
        &dir.join(name),
        bytes,
        patience,
    )?)
}

#[cfg(feature = "png")]
const PREFERRED_FAMILIES: [&str; 6] = [
    "DejaVu Sans",
    "Liberation Sans",
    "Noto Sans",
    "FreeSans",
    "Arial",
    "Helvetica",
];

/// Without the `png` feature (a build with `--no-default-features`, which leaves out resvg and
/// its font stack, about 14% of a clean build): no PNG, a warning, the SVG as always.
#[cfg(not(feature = "png"))]
pub fn png_from_svg(_svg: &str) -> crate::Result<Option<Vec<u8>>> {
    eprintln!(
        "warning: this alfd was built without the `png` feature: the plot is written as SVG only"
    );
    Ok(None)
}

/// Rasterises an SVG to PNG bytes. `Ok(None)` when no font is available (the text could not be
/// drawn), with a warning on stderr saying why.
///
/// Fonts: `ALFD_FONT` unset: the system's; set to a file: that font; set but empty: none (SVG only).
#[cfg(feature = "png")]
pub fn png_from_svg(svg: &str) -> crate::Result<Option<Vec<u8>>> {
    let mut db = resvg::usvg::fontdb::Database::new();
    match std::env::var_os("ALFD_FONT") {
        None => db.load_system_fonts(),
        Some(path) if path.is_empty() => {}
        Some(path) => {
            if let Err(e) = db.load_font_file(&path) {
                eprintln!(
                    "warning: cannot load the font ALFD_FONT={}: {e}",
                    path.to_string_lossy()
                );
            }
        }
    }
    let families: Vec<String> = db
        .faces()
        .flat_map(|f| f.families.iter().map(|(name, _)| name.clone()))
        .collect();
    let Some(family) = PREFERRED_FAMILIES
        .iter()
        .find(|p| families.iter().any(|f| f == *p))
        .map(|p| p.to_string())
        .or_else(|| families.first().cloned())
    else {
        eprintln!(
            "warning: no font found (install one, e.g. fonts-dejavu-core, or set ALFD_FONT to a \
             .ttf file): the plot is written as SVG only, no PNG"
        );
        return Ok(None);
    };
    tracing::debug!(%family, "PNG font");
    db.set_sans_serif_family(family.clone());
    let mut opt = resvg::usvg::Options {
        font_family: family,
        ..Default::default()
    };
    opt.fontdb = Arc::new(db);
    let tree = resvg::usvg::Tree::from_str(svg, &opt).context("parsing the SVG")?;
    let size = tree.size().to_int_size();
    let mut pixmap = resvg::tiny_skia::Pixmap::new(size.width(), size.height())
        .context("the plot has no size")?;
    pixmap.fill(resvg::tiny_skia::Color::WHITE);
    resvg::render(
        &tree,
        resvg::tiny_skia::Transform::default(),
        &mut pixmap.as_mut(),
    );
    Ok(Some(pixmap.encode_png().context("encoding the PNG")?))
}
