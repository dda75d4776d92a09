//! The look of every chart in the crate, in one place: the frame (title font,
//! margin, room for the axis labels), the mesh (axis titles, tick labels,
//! grid), the legend box and its keys, the series' colours and line widths.
//!
//! The calibration report's plots and the sampling-search plot should look
//! like one family. When every chart spells out its own fonts, margins,
//! grid and legend, a change to one is easily missed in the others; here a
//! chart asks a [`ChartStyle`] for its frame, mesh and legend and takes its
//! colours and line widths from this file, so changing the look of the
//! charts is an edit in one place.

use crate::png::{PlotResult, FONT_FAMILY};
use plotters::chart::{MeshStyle, SeriesAnno};
use plotters::coord::ranged1d::{Ranged, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::TextStyle;

/// The drawing area a chart is drawn on (what `render_png` hands its
/// closure).
pub(crate) type Area<'b> = DrawingArea<BitMapBackend<'b>, Shift>;

/// The sizes, in pixels, of one kind of chart. Sizes scale with the
/// picture: the report's plots are larger than the search plot, and text
/// should stay the same fraction of a plot however large it is drawn.
pub(crate) struct ChartStyle {
    /// Font size of the title over the plot.
    caption: i32,
    /// Height of the band under the plot for tick labels and the x-axis
    /// title.
    x_label_area: u32,
    /// Width of the band left of the plot for tick labels and the y-axis
    /// title.
    y_label_area: u32,
    /// Font size of the axis titles.
    axis_desc: i32,
    /// Font size of the tick labels.
    tick_label: i32,
    /// Font size of the legend's entries.
    legend_font: i32,
    /// Radius of a measured point's dot.
    point: i32,
    /// Opacity of the legend box's white background: a curve behind the
    /// legend still shows through faintly, so the box never hides that
    /// there is data under it.
    legend_opacity: f64,
}

/// The calibration report's plots (1100x700).
pub(crate) const REPORT: ChartStyle = ChartStyle {
    caption: 28,
    x_label_area: 60,
    y_label_area: 90,
    axis_desc: 20,
    tick_label: 16,
    legend_font: 18,
    point: 5,
    legend_opacity: 0.9,
};

/// The sampling-search plot (900x600): the same look at sizes for the
/// smaller picture.
pub(crate) const SEARCH: ChartStyle = ChartStyle {
    caption: 24,
    x_label_area: 50,
    y_label_area: 70,
    axis_desc: 18,
    tick_label: 15,
    legend_font: 15,
    point: 4,
    legend_opacity: 0.85,
};

/// White space round every chart, in pixels.
const MARGIN: u32 = 20;

/// The grid: light enough that the data reads first.
const GRID: RGBColor = RGBColor(235, 235, 235);

/// Measured values: points and the curves through them.
pub(crate) const MEASURED: RGBColor = BLUE;
/// What the eye should find first: fits and models, the median, the chosen
/// value, and the warning that a fit is missing.
pub(crate) const FIT: RGBColor = RED;
/// A reference curve that is not measured (the shot-noise limit).
pub(crate) const REFERENCE: RGBColor = RGBColor(120, 120, 120);
/// A second reference level (the search's one-step result).
pub(crate) const ALTERNATIVE: RGBColor = GREEN;
/// The baseline every method must beat (the search's noisy input).
pub(crate) const BASELINE: RGBColor = BLACK;
/// The bars of a histogram of one quantity.
pub(crate) const BARS: RGBColor = RGBColor(40, 90, 170);
/// Two quantities compared on one histogram (the dark-current laws): a blue
/// and an orange, a pair that stays distinct for red-green colour
/// blindness.
pub(crate) const FIRST_OF_TWO: RGBColor = RGBColor(30, 110, 200);
/// The second of two compared quantities; see [`FIRST_OF_TWO`].
pub(crate) const SECOND_OF_TWO: RGBColor = RGBColor(230, 120, 20);
/// Notes under a chart: quieter than the data and the axis titles.
const NOTE: RGBColor = RGBColor(90, 90, 90);

/// Width of a data curve, in pixels.
const CURVE_WIDTH: u32 = 2;
/// Width of a reference curve: thinner than the data it is compared with.
const REFERENCE_WIDTH: u32 = 1;
/// Width of a marker line (a median) that must stand out over bars.
const MARKER_WIDTH: u32 = 3;
/// Dash and gap of a dashed line, in pixels: a dashed line is a level read
/// off the chart (a median, a reference), not data.
const DASH: (i32, i32) = (10, 6);

/// Length of a line key in the legend, in pixels.
const KEY_LINE: i32 = 24;
/// Width of a histogram's colour swatch in the legend; its median keys are
/// as long, so the legend's entries line up.
const KEY_SWATCH: i32 = 20;

impl ChartStyle {
    /// A measured point at `at`: a filled dot in [`MEASURED`].
    pub(crate) fn point<C>(&self, at: C) -> Circle<C, i32> {
        Circle::new(at, self.point, MEASURED.filled())
    }

    /// Give the measured points `anno` the legend entry `label`, keyed by
    /// one of their dots.
    pub(crate) fn point_key<DB: DrawingBackend>(
        &self,
        anno: &mut SeriesAnno<'_, DB>,
        label: impl Into<String>,
    ) {
        dot_key(anno, label, self.point, MEASURED.filled());
    }

    /// The frame of a chart on `root`: `caption` over it, the margin and
    /// the label bands. The caller chooses the axes (`build_cartesian_2d`)
    /// and may change a margin first.
    pub(crate) fn frame<'a, 'b>(
        &self,
        root: &'a Area<'b>,
        caption: &str,
    ) -> ChartBuilder<'a, 'b, BitMapBackend<'b>> {
        let mut builder = ChartBuilder::on(root);
        builder
            .caption(caption, (FONT_FAMILY, self.caption))
            .margin(MARGIN)
            .x_label_area_size(self.x_label_area)
            .y_label_area_size(self.y_label_area);
        builder
    }

    /// The mesh of `chart` with the axis titles `x_desc` and `y_desc`, ready
    /// to draw; the caller adds tick formatters where the defaults do not
    /// read well.
    pub(crate) fn mesh<'a, 'c, DB, X, Y, XT, YT>(
        &self,
        chart: &'c mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
        x_desc: &str,
        y_desc: &str,
    ) -> MeshStyle<'a, 'c, X, Y, DB>
    where
        DB: DrawingBackend,
        X: Ranged<ValueType = XT> + ValueFormatter<XT>,
        Y: Ranged<ValueType = YT> + ValueFormatter<YT>,
    {
        let mut mesh = chart.configure_mesh();
        mesh.x_desc(x_desc)
            .y_desc(y_desc)
            .axis_desc_style((FONT_FAMILY, self.axis_desc))
            .label_style((FONT_FAMILY, self.tick_label))
            .light_line_style(GRID);
        mesh
    }

    /// Draw the legend of `chart`'s labelled series at `position`, in a
    /// white box with a black border.
    pub(crate) fn legend<'a, 'b, CT: CoordTranslate>(
        &self,
        chart: &mut ChartContext<'a, BitMapBackend<'b>, CT>,
        position: SeriesLabelPosition,
    ) -> PlotResult
    where
        'b: 'a,
    {
        chart
            .configure_series_labels()
            .position(position)
            .label_font((FONT_FAMILY, self.legend_font))
            .background_style(WHITE.mix(self.legend_opacity))
            .border_style(BLACK)
            .draw()?;
        Ok(())
    }
}

/// The style of a data curve in `colour`.
pub(crate) fn curve(colour: RGBColor) -> ShapeStyle {
    colour.stroke_width(CURVE_WIDTH)
}

/// The style of a reference curve (a limit the data is compared with) in
/// `colour`.
pub(crate) fn thin_curve(colour: RGBColor) -> ShapeStyle {
    colour.stroke_width(REFERENCE_WIDTH)
}

/// The style of a marker line (a median over histogram bars) in `colour`.
pub(crate) fn marker(colour: RGBColor) -> ShapeStyle {
    colour.stroke_width(MARKER_WIDTH)
}

/// A dashed line through `points` in `style`.
pub(crate) fn dashed<C: Clone>(
    points: Vec<C>,
    style: ShapeStyle,
) -> DashedLineSeries<std::vec::IntoIter<C>, i32> {
    DashedLineSeries::new(points, DASH.0, DASH.1, style)
}

/// The fill of a histogram's bars in `colour`: translucent when `overlaid`
/// on another histogram so neither hides the other.
pub(crate) fn bars(colour: RGBColor, overlaid: bool) -> ShapeStyle {
    if overlaid {
        colour.mix(0.45).filled()
    } else {
        colour.mix(0.8).filled()
    }
}

/// Give the series `anno` the legend entry `label` with a line key in
/// `style`.
pub(crate) fn line_key<DB: DrawingBackend>(
    anno: &mut SeriesAnno<'_, DB>,
    label: impl Into<String>,
    style: ShapeStyle,
) {
    anno.label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + KEY_LINE, y)], style));
}

/// Give the series `anno` the legend entry `label` with a dot of `radius`
/// pixels in `style`, centred where a line key would be.
pub(crate) fn dot_key<DB: DrawingBackend>(
    anno: &mut SeriesAnno<'_, DB>,
    label: impl Into<String>,
    radius: i32,
    style: ShapeStyle,
) {
    anno.label(label)
        .legend(move |(x, y)| Circle::new((x + KEY_LINE / 2, y), radius, style));
}

/// Give the histogram series `anno` the legend entry `label` with a swatch
/// of its bars' `colour`.
pub(crate) fn swatch_key<DB: DrawingBackend>(
    anno: &mut SeriesAnno<'_, DB>,
    label: impl Into<String>,
    colour: RGBColor,
) {
    anno.label(label).legend(move |(x, y)| {
        Rectangle::new([(x, y - 6), (x + KEY_SWATCH, y + 6)], colour.filled())
    });
}

/// Give a marker line over a histogram (see [`marker`]) the legend entry
/// `label` with a line key as long as the histogram's swatches.
pub(crate) fn swatch_line_key<DB: DrawingBackend>(
    anno: &mut SeriesAnno<'_, DB>,
    label: impl Into<String>,
    style: ShapeStyle,
) {
    anno.label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + KEY_SWATCH, y)], style));
}

/// The style of a note written on a chart outside the plot (values left
/// out, a missing fit): `size` pixels in `colour`.
pub(crate) fn note_style(size: i32, colour: RGBColor) -> TextStyle<'static> {
    (FONT_FAMILY, size).into_font().color(&colour)
}

/// The style of a note about what a chart leaves out, `size` pixels.
pub(crate) fn quiet_note_style(size: i32) -> TextStyle<'static> {
    note_style(size, NOTE)
}
