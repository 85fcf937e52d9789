//! Reports: self-contained HTML pages with inline SVG plots.
//!
//! - [`audit`]: fit quality across the network (`pipewave audit`).
//! - [`svg`]: the small SVG pieces plotters does not draw well for us (the network map, whose
//!   segments are grouped by colour class into one path each, and inline bars), and escaping.
//! - [`charts`]: the XY charts, drawn with `plotters`' SVG backend.

pub mod audit;
pub mod charts;
pub mod field;
pub mod svg;
pub mod zones;
