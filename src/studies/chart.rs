//! Line and point charts of the studies, written as PNG and SVG with plotters.
//!
//! Text is drawn with plotters' `ab_glyph` renderer from DejaVu Sans embedded in the binary
//! (the `dejavu` crate), registered once as the `sans-serif` family: the charts need no
//! system font, fontconfig or font-kit, so they look the same on a fresh machine.

use anyhow::{anyhow, Context};
use plotters::coord::ranged1d::{AsRangedCoord, Ranged, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Once;

/// Size of every chart, pixels (the SVG uses the same units).
pub const SIZE: (u32, u32) = (800, 500);

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    /// Solid line through the points, with a dot on each.
    Line,
    /// Dashed line, no dots (thresholds, limits, reference levels).
    Dashed,
    /// Dots only.
    Points,
}

/// One named series.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// The points, in drawing order.
    pub points: Vec<(f64, f64)>,
    /// How it is drawn.
    pub style: Style,
    /// Palette index (series sharing a colour share an index).
    pub color: usize,
}

/// A point marked with a large symbol and a text next to it (an operating point, a seed
/// figure).
#[derive(Debug, Clone)]
pub struct Mark {
    /// Where.
    pub at: (f64, f64),
    /// Text drawn beside the symbol.
    pub text: String,
}

/// A chart: title, axes with units, series, marks.
#[derive(Debug, Clone)]
pub struct Chart {
    /// File stem (`c1_send_on_delta` gives `c1_send_on_delta.png` and `.svg`).
    pub name: String,
    /// Title.
    pub title: String,
    /// X axis description with unit.
    pub x_label: String,
    /// Y axis description with unit.
    pub y_label: String,
    /// Logarithmic x axis.
    pub x_log: bool,
    /// Logarithmic y axis.
    pub y_log: bool,
    /// X range (for a log axis, both ends > 0).
    pub x_range: (f64, f64),
    /// Y range (for a log axis, both ends > 0).
    pub y_range: (f64, f64),
    /// The series.
    pub series: Vec<Series>,
    /// Marked points.
    pub marks: Vec<Mark>,
    /// Corner of the legend.
    pub legend: Legend,
}

/// Where the legend goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Legend {
    /// Upper left corner.
    UpperLeft,
    /// Upper right corner.
    UpperRight,
    /// Lower left corner.
    LowerLeft,
    /// Lower right corner.
    LowerRight,
}

/// Colour-blind-safe palette (Okabe and Ito), then black.
const PALETTE: [RGBColor; 8] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(86, 180, 233),
    RGBColor(230, 159, 0),
    RGBColor(120, 120, 120),
    RGBColor(0, 0, 0),
];

/// Colour of palette entry `i` (wrapping).
pub fn color(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

fn register_fonts() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // DejaVu Sans is a valid TrueType font: registering it cannot fail.
        if plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .is_err()
        {
            panic!("the embedded DejaVu Sans font did not load");
        }
    });
}

/// A number as an axis label: no trailing zeros, thousands without separators.
pub fn tick_label(v: f64) -> String {
    if v == 0.0 {
        return "0".to_string();
    }
    let a = v.abs();
    let s = if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 1.0 {
        format!("{v:.2}")
    } else if a >= 0.001 {
        format!("{v:.4}")
    } else {
        return format!("{v:.0e}");
    };
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

impl Chart {
    /// Writes `<dir>/<name>.png` and `<dir>/<name>.svg`; returns both paths.
    pub fn write(&self, dir: &Path) -> anyhow::Result<[PathBuf; 2]> {
        register_fonts();
        let png = dir.join(format!("{}.png", self.name));
        let svg = dir.join(format!("{}.svg", self.name));
        {
            let root = BitMapBackend::new(&png, SIZE).into_drawing_area();
            self.draw(&root)
                .with_context(|| format!("drawing {}", png.display()))?;
            root.present()
                .map_err(|e| anyhow!("writing {}: {e}", png.display()))?;
        }
        {
            let root = SVGBackend::new(&svg, SIZE).into_drawing_area();
            self.draw(&root)
                .with_context(|| format!("drawing {}", svg.display()))?;
            root.present()
                .map_err(|e| anyhow!("writing {}: {e}", svg.display()))?;
        }
        Ok([png, svg])
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> anyhow::Result<()> {
        let (x0, x1) = self.x_range;
        let (y0, y1) = self.y_range;
        match (self.x_log, self.y_log) {
            (false, false) => self.draw_in(root, x0..x1, y0..y1),
            (true, false) => self.draw_in(root, (x0..x1).log_scale(), y0..y1),
            (false, true) => self.draw_in(root, x0..x1, (y0..y1).log_scale()),
            (true, true) => self.draw_in(root, (x0..x1).log_scale(), (y0..y1).log_scale()),
        }
    }

    fn draw_in<DB, X, Y>(&self, root: &DrawingArea<DB, Shift>, x: X, y: Y) -> anyhow::Result<()>
    where
        DB: DrawingBackend,
        X: AsRangedCoord<Value = f64>,
        Y: AsRangedCoord<Value = f64>,
        X::CoordDescType: Ranged<ValueType = f64> + ValueFormatter<f64>,
        Y::CoordDescType: Ranged<ValueType = f64> + ValueFormatter<f64>,
    {
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("{e:?}");
        root.fill(&WHITE).map_err(e)?;
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 22))
            .margin(12)
            .margin_right(30)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(x, y)
            .map_err(e)?;
        let fmt = |v: &f64| tick_label(*v);
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .x_label_formatter(&fmt)
            .y_label_formatter(&fmt)
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .x_labels(10)
            .y_labels(8)
            .light_line_style(TRANSPARENT)
            .bold_line_style(RGBColor(220, 220, 220))
            .draw()
            .map_err(e)?;
        // Points outside the ranges are left out (plotters does not clip lines to the plot
        // area, and a log axis has no place for 0); the summary's tables hold them all.
        let (xr, yr) = (self.x_range, self.y_range);
        let inside = |p: &(f64, f64)| {
            p.0 >= xr.0.min(xr.1)
                && p.0 <= xr.0.max(xr.1)
                && p.1 >= yr.0.min(yr.1)
                && p.1 <= yr.0.max(yr.1)
        };
        for s in &self.series {
            let points: Vec<(f64, f64)> = s.points.iter().copied().filter(inside).collect();
            let s = Series {
                points,
                ..s.clone()
            };
            let c = color(s.color);
            let legend_style = c.stroke_width(2);
            let anno = match s.style {
                Style::Line => {
                    chart
                        .draw_series(s.points.iter().map(|&p| Circle::new(p, 3, c.filled())))
                        .map_err(e)?;
                    chart
                        .draw_series(LineSeries::new(s.points.iter().copied(), c.stroke_width(2)))
                        .map_err(e)?
                }
                Style::Dashed => chart
                    .draw_series(DashedLineSeries::new(
                        s.points.iter().copied(),
                        6,
                        4,
                        c.stroke_width(2),
                    ))
                    .map_err(e)?,
                Style::Points => chart
                    .draw_series(s.points.iter().map(|&p| Circle::new(p, 4, c.filled())))
                    .map_err(e)?,
            };
            if !s.label.is_empty() {
                // A dashed series shows two dashes in the legend.
                let gap = if s.style == Style::Dashed {
                    (8, 12)
                } else {
                    (10, 10)
                };
                anno.label(&s.label).legend(move |(x, y)| {
                    EmptyElement::at((x, y))
                        + PathElement::new(vec![(0, 0), (gap.0, 0)], legend_style)
                        + PathElement::new(vec![(gap.1, 0), (20, 0)], legend_style)
                });
            }
        }
        for m in self.marks.iter().filter(|m| inside(&m.at)) {
            chart
                .draw_series(std::iter::once(
                    EmptyElement::at(m.at)
                        + TriangleMarker::new((0, 0), 9, BLACK.filled())
                        + Text::new(m.text.clone(), (10, -18), ("sans-serif", 14)),
                ))
                .map_err(e)?;
        }
        chart
            .configure_series_labels()
            .position(match self.legend {
                Legend::UpperLeft => SeriesLabelPosition::UpperLeft,
                Legend::UpperRight => SeriesLabelPosition::UpperRight,
                Legend::LowerLeft => SeriesLabelPosition::LowerLeft,
                Legend::LowerRight => SeriesLabelPosition::LowerRight,
            })
            .label_font(("sans-serif", 14))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .draw()
            .map_err(e)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(tick_label(0.0), "0");
        assert_eq!(tick_label(1500.0), "1500");
        assert_eq!(tick_label(2.5), "2.5");
        assert_eq!(tick_label(0.125), "0.125");
        assert_eq!(tick_label(10.0), "10");
        assert_eq!(tick_label(0.0001), "1e-4");
    }
}

#[cfg(test)]
mod write_tests {
    use super::*;

    #[test]
    fn writes_a_png_and_an_svg_with_text() {
        let dir = std::env::temp_dir().join(format!("skinbox-chart-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let chart = Chart {
            name: "t".into(),
            title: "Title of the chart".into(),
            x_label: "x (us)".into(),
            y_label: "y (%)".into(),
            x_log: true,
            y_log: false,
            x_range: (1.0, 1000.0),
            y_range: (0.0, 100.0),
            series: vec![
                Series {
                    label: "rising".into(),
                    points: vec![(1.0, 10.0), (10.0, 40.0), (1000.0, 90.0)],
                    style: Style::Line,
                    color: 0,
                },
                Series {
                    label: "limit".into(),
                    points: vec![(1.0, 50.0), (1000.0, 50.0)],
                    style: Style::Dashed,
                    color: 1,
                },
            ],
            marks: vec![Mark {
                at: (10.0, 40.0),
                text: "seed".into(),
            }],
            legend: Legend::UpperLeft,
        };
        let [png, svg] = chart.write(&dir).unwrap();
        let bytes = std::fs::read(&png).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        let text = std::fs::read_to_string(&svg).unwrap();
        assert!(text.contains("Title of the chart"));
        assert!(text.contains("<text"));
        eprintln!("{}", png.display());
    }
}
