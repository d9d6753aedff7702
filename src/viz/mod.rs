//! Pictures: mesh snapshots and plots, written as PNG.
//!
//! Two kinds of picture, both drawn with `plotters` (its bitmap backend
//! fills the polygons, draws the lines and renders the text; nothing here
//! rasterises by hand) and encoded with the `png` crate:
//!
//! - [`snapshot`]: a reconstructed mesh with its input points, and the
//!   ground-truth mesh where there is one, from three viewpoints (camera
//!   side, side, back), for `sepmem reconstruct --snapshot` and
//!   `sepmem replay --snapshots`.
//! - [`plot`]: line panels (F-score, visible recall and latency over the
//!   frames of a replay; the benchmark's sphere sweep) and grouped bars (the
//!   benchmark's F-score per input condition, beside the peers' figures).
//!
//! Text uses an embedded font (DejaVu Sans, `src/viz/fonts/`, with its
//! licence), registered with plotters' `ab_glyph` text backend, so pictures
//! render the same on a bare CI machine with no system fonts.
//!
//! What a picture shows is checked by measurement: the tests decode the PNG
//! and count the mesh-coloured pixels of each view (`tests/pictures.rs`).

pub mod plot;
pub mod snapshot;

use plotters::style::FontStyle;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// DejaVu Sans (Bitstream Vera licence, `src/viz/fonts/LICENSE`).
const FONT: &[u8] = include_bytes!("fonts/DejaVuSans.ttf");

/// The font family name the pictures ask plotters for.
pub(crate) const FAMILY: &str = "sans-serif";

/// Errors of the picture writers.
#[derive(Debug, thiserror::Error)]
pub enum VizError {
    /// Nothing to draw.
    #[error("nothing to draw: {0}")]
    Empty(String),
    /// Drawing failed inside plotters.
    #[error("drawing {what}: {message}")]
    Draw {
        /// Which picture.
        what: String,
        /// plotters' message.
        message: String,
    },
    /// The embedded font could not be registered.
    #[error("registering the embedded font: {0}")]
    Font(String),
    /// Encoding or writing the PNG failed.
    #[error("writing {}: {message}", path.display())]
    Write {
        /// The PNG file.
        path: PathBuf,
        /// The encoder's or the file system's message.
        message: String,
    },
}

/// Register the embedded font once per process.
pub(crate) fn ensure_font() -> Result<(), VizError> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            plotters::style::register_font(FAMILY, FontStyle::Normal, FONT)
                .map_err(|_| "DejaVu Sans did not parse".to_string())
        })
        .clone()
        .map_err(VizError::Font)
}

/// Map a plotters error into [`VizError::Draw`] for picture `what`.
pub(crate) fn draw_err<E: std::fmt::Display>(what: &str) -> impl Fn(E) -> VizError + '_ {
    move |e| VizError::Draw {
        what: what.to_string(),
        message: e.to_string(),
    }
}

/// An RGB8 image being drawn: `width × height × 3` bytes, row-major.
pub(crate) struct Canvas {
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) rgb: Vec<u8>,
}

impl Canvas {
    /// A canvas of `width × height` pixels (filled by the drawing code).
    pub(crate) fn new(width: u32, height: u32) -> Self {
        Canvas {
            width,
            height,
            rgb: vec![255; width as usize * height as usize * 3],
        }
    }

    /// Encode as an 8-bit RGB PNG at `path`.
    pub(crate) fn save_png(&self, path: &Path) -> Result<(), VizError> {
        let err = |message: String| VizError::Write {
            path: path.to_path_buf(),
            message,
        };
        let file = std::fs::File::create(path).map_err(|e| err(e.to_string()))?;
        let mut enc = png::Encoder::new(std::io::BufWriter::new(file), self.width, self.height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().map_err(|e| err(e.to_string()))?;
        w.write_image_data(&self.rgb)
            .map_err(|e| err(e.to_string()))?;
        w.finish().map_err(|e| err(e.to_string()))
    }
}
