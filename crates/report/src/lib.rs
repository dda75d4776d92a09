//! What people would rather look at than numbers: the calibration report
//! (photon-transfer curve, histograms, maps, Markdown summary), montages of
//! previews side by side, and the sampling-search plot. Everything renders
//! headless with an embedded font and is written atomically as PNG.
//!
//! Kept out of the physics and network crates so that plotting and fonts are
//! linked only where a picture is drawn.

#![warn(missing_docs)]

mod calibration;
mod chart;
mod error;
mod montage;
mod png;
mod search_plot;

pub use calibration::{write_report, PtcPoint, ReportData, REPORT_FILES};
pub use error::ReportError;
pub use montage::{write_montage, Panel};
pub use search_plot::{write_search_plot, SearchCurve};
