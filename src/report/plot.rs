//! SVG plots of distributions (plotters' SVG backend, text left to the viewer's fonts):
//! a histogram with optional reference lines, and several distributions overlaid as
//! normalised step curves so cohorts of different sizes compare directly.

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::jobs::stats::{Histogram, histogram};

/// Pixel size of every plot.
const SIZE: (u32, u32) = (640, 400);
/// Bins of a histogram plot.
pub const PLOT_BINS: usize = 24;
/// Line colours of overlaid series, in order (colour-blind safe, Okabe–Ito).
const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(0, 0, 0),
];

/// A vertical reference line (e.g. the Chamfer sampling floor).
#[derive(Debug, Clone, PartialEq)]
pub struct Marker {
    /// Legend text.
    pub label: String,
    /// Position on the x axis.
    pub value: f64,
}

/// One named set of values.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// The values; non-finite ones are ignored.
    pub values: Vec<f64>,
}

/// What a histogram plot shows.
#[derive(Debug, Clone, PartialEq)]
pub struct HistogramPlot<'a> {
    /// Title above the plot.
    pub title: &'a str,
    /// Caption of the x axis (quantity and units).
    pub x_label: &'a str,
    /// The values.
    pub values: &'a [f64],
    /// Reference lines.
    pub markers: &'a [Marker],
}

/// Renders a histogram of `plot.values` as an SVG document. With no finite value the plot
/// says so instead of drawing empty axes.
pub fn histogram_svg(plot: &HistogramPlot<'_>) -> String {
    let values = finite_sorted(plot.values);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        draw(&root, plot, &values).expect("drawing into a String cannot fail");
        root.present().expect("drawing into a String cannot fail");
    }
    svg
}

fn draw(
    root: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    plot: &HistogramPlot<'_>,
    values: &[f64],
) -> Result<(), DrawingAreaErrorKind<std::io::Error>> {
    root.fill(&WHITE)?;
    let title = format!("{} (n = {})", plot.title, values.len());
    if values.is_empty() {
        return no_data(root, &title);
    }
    let hist = histogram(values, PLOT_BINS);
    let (x_lo, x_hi) = x_range(&hist, plot.markers);
    let y_hi = hist.counts.iter().copied().max().unwrap_or(1).max(1) as f64 * 1.1;
    let mut chart = chart(root, &title, (x_lo, x_hi), y_hi)?;
    chart
        .configure_mesh()
        .x_desc(plot.x_label)
        .y_desc("count")
        .x_label_formatter(&|x| tick(*x))
        .y_labels((y_hi.ceil() as usize + 1).clamp(3, 11))
        .y_label_formatter(&|y| integer_tick(*y))
        .light_line_style(WHITE)
        .disable_x_mesh()
        .draw()?;
    let fill = PALETTE[0].mix(0.55).filled();
    chart.draw_series(hist.counts.iter().enumerate().map(|(i, &c)| {
        Rectangle::new([(hist.edges[i], 0.0), (hist.edges[i + 1], c as f64)], fill)
    }))?;
    for (k, marker) in plot.markers.iter().enumerate() {
        let colour = PALETTE[(k + 1) % PALETTE.len()];
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(marker.value, 0.0), (marker.value, y_hi)],
                colour.stroke_width(2),
            )))?
            .label(format!("{} = {}", marker.label, tick(marker.value)))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2))
            });
    }
    if !plot.markers.is_empty() {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
    }
    Ok(())
}

/// Renders several distributions over one common x range as step curves of the fraction
/// of each series per bin, with a legend giving each series' size and median.
pub fn overlay_svg(title: &str, x_label: &str, series: &[Series]) -> String {
    let prepared: Vec<(&str, Vec<f64>)> = series
        .iter()
        .map(|s| (s.name.as_str(), finite_sorted(&s.values)))
        .filter(|(_, v)| !v.is_empty())
        .collect();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        draw_overlay(&root, title, x_label, &prepared).expect("drawing into a String cannot fail");
        root.present().expect("drawing into a String cannot fail");
    }
    svg
}

fn draw_overlay(
    root: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    title: &str,
    x_label: &str,
    series: &[(&str, Vec<f64>)],
) -> Result<(), DrawingAreaErrorKind<std::io::Error>> {
    root.fill(&WHITE)?;
    let all: Vec<f64> = finite_sorted(
        &series
            .iter()
            .flat_map(|(_, v)| v.clone())
            .collect::<Vec<_>>(),
    );
    if all.is_empty() {
        return no_data(root, title);
    }
    let edges = histogram(&all, PLOT_BINS).edges;
    let fractions: Vec<Vec<f64>> = series
        .iter()
        .map(|(_, v)| bin_fractions(v, &edges))
        .collect();
    let y_hi = fractions
        .iter()
        .flatten()
        .copied()
        .fold(0.0, f64::max)
        .max(1e-9)
        * 1.15;
    let (x_lo, x_hi) = (edges[0], edges[edges.len() - 1]);
    let mut chart = chart(root, title, (x_lo, x_hi), y_hi)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc("fraction per bin")
        .x_label_formatter(&|x| tick(*x))
        .y_label_formatter(&|y| format!("{y:.2}"))
        .light_line_style(WHITE)
        .disable_x_mesh()
        .draw()?;
    for (k, ((name, values), fr)) in series.iter().zip(&fractions).enumerate() {
        let colour = PALETTE[k % PALETTE.len()];
        let mut path = vec![(edges[0], 0.0)];
        for (i, &f) in fr.iter().enumerate() {
            path.push((edges[i], f));
            path.push((edges[i + 1], f));
        }
        path.push((edges[edges.len() - 1], 0.0));
        let median = crate::sdf::inference::evaluation::quantile(values, 0.5);
        chart
            .draw_series(std::iter::once(PathElement::new(
                path,
                colour.stroke_width(2),
            )))?
            .label(format!(
                "{name} (n = {}, median {})",
                values.len(),
                tick(median)
            ))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .position(SeriesLabelPosition::UpperRight)
        .draw()?;
    Ok(())
}

/// Cartesian axes over `x` × [0, y_hi] with the title above, as every plot here has them.
fn chart<'a, 'b>(
    root: &'a DrawingArea<SVGBackend<'b>, plotters::coord::Shift>,
    title: &str,
    (x_lo, x_hi): (f64, f64),
    y_hi: f64,
) -> Result<
    ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    DrawingAreaErrorKind<std::io::Error>,
> {
    ChartBuilder::on(root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(52)
        .build_cartesian_2d(x_lo..x_hi, 0.0..y_hi)
}

fn no_data(
    root: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    title: &str,
) -> Result<(), DrawingAreaErrorKind<std::io::Error>> {
    root.draw(&Text::new(title.to_owned(), (20, 30), ("sans-serif", 20)))?;
    root.draw(&Text::new("no data yet", (20, 70), ("sans-serif", 16)))
}

/// Fraction of `sorted` in each bin of `edges` (last bin closed, values outside ignored).
fn bin_fractions(sorted: &[f64], edges: &[f64]) -> Vec<f64> {
    let bins = edges.len() - 1;
    let mut counts = vec![0usize; bins];
    for &v in sorted {
        if v < edges[0] || v > edges[bins] {
            continue;
        }
        let i = edges[1..].partition_point(|&e| e <= v).min(bins - 1);
        counts[i] += 1;
    }
    counts
        .into_iter()
        .map(|c| c as f64 / sorted.len() as f64)
        .collect()
}

/// The x range covering the histogram and every marker, padded when degenerate.
fn x_range(hist: &Histogram, markers: &[Marker]) -> (f64, f64) {
    let mut lo = hist.edges[0];
    let mut hi = hist.edges[hist.edges.len() - 1];
    for m in markers.iter().filter(|m| m.value.is_finite()) {
        lo = lo.min(m.value);
        hi = hi.max(m.value);
    }
    if hi - lo <= f64::EPSILON * hi.abs().max(1.0) {
        let pad = (hi.abs() * 0.05).max(1e-12);
        (lo - pad, hi + pad)
    } else {
        let pad = (hi - lo) * 0.03;
        (lo - pad, hi + pad)
    }
}

/// Counts are whole numbers: fractional tick positions stay unlabelled.
fn integer_tick(y: f64) -> String {
    if (y - y.round()).abs() < 1e-9 {
        format!("{y:.0}")
    } else {
        String::new()
    }
}

/// Compact tick label: plain for ordinary magnitudes, scientific for tiny or huge ones.
pub fn tick(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-2..1e4).contains(&a) {
        format!("{x:.2e}")
    } else {
        let s = format!("{x:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    }
}

fn finite_sorted(values: &[f64]) -> Vec<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Heights of the histogram bars (rectangles in the bar colour) in drawing order.
    fn bar_heights(svg: &str) -> Vec<f64> {
        svg.split("<rect")
            .skip(1)
            .filter(|r| r.contains("fill=\"#0072B2\""))
            .map(|r| {
                let h = r.split("height=\"").nth(1).unwrap();
                h[..h.find('"').unwrap()].parse().unwrap()
            })
            .collect()
    }

    #[test]
    fn bars_are_proportional_to_bin_counts() {
        // 24 equal-width bins over [0, 24]: value k lands in bin k (the last bin is closed).
        let mut values = vec![];
        for (k, n) in [(0, 1), (5, 4), (11, 2), (24, 8)] {
            values.extend(std::iter::repeat_n(k as f64, n));
        }
        let svg = histogram_svg(&HistogramPlot {
            title: "t",
            x_label: "x",
            values: &values,
            markers: &[],
        });
        let heights: Vec<f64> = bar_heights(&svg).into_iter().filter(|h| *h > 0.0).collect();
        assert_eq!(heights.len(), 4, "{svg}");
        let unit = heights[0];
        for (h, n) in heights.iter().zip([1.0, 4.0, 2.0, 8.0]) {
            assert!((h / unit - n).abs() < 0.05 * n, "{heights:?}");
        }
        assert!(svg.contains("(n = 15)"));
    }

    #[test]
    fn markers_and_empty_inputs_are_labelled() {
        let svg = histogram_svg(&HistogramPlot {
            title: "CD",
            x_label: "x",
            values: &[1e-4, 2e-4, f64::NAN],
            markers: &[Marker {
                label: "floor".into(),
                value: 5e-5,
            }],
        });
        assert!(svg.contains("floor = 5.00e-5"));
        assert!(svg.contains("(n = 2)"));
        let empty = histogram_svg(&HistogramPlot {
            title: "CD",
            x_label: "x",
            values: &[],
            markers: &[],
        });
        assert!(empty.contains("no data yet") && empty.starts_with("<svg"));
    }

    #[test]
    fn overlay_names_every_series_and_fractions_sum_to_one() {
        let a = Series {
            name: "arity 2".into(),
            values: (0..10).map(f64::from).collect(),
        };
        let b = Series {
            name: "arity 8".into(),
            values: (0..40).map(|i| f64::from(i) / 8.0).collect(),
        };
        let svg = overlay_svg("pairwise", "CD", &[a, b]);
        assert!(svg.contains("arity 2 (n = 10, median 4.5)"), "{svg}");
        assert!(svg.contains("arity 8 (n = 40"));
        let sorted: Vec<f64> = (0..10).map(f64::from).collect();
        let edges: Vec<f64> = (0..=5).map(|i| f64::from(i) * 9.0 / 5.0).collect();
        let fr = bin_fractions(&sorted, &edges);
        assert!((fr.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert_eq!(fr, vec![0.2; 5]);
    }

    #[test]
    fn ticks_are_compact() {
        assert_eq!(tick(0.0), "0");
        assert_eq!(tick(25.5), "25.5");
        assert_eq!(tick(1.0), "1");
        assert_eq!(tick(1.5e-4), "1.50e-4");
    }
}
