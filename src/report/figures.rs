//! The validation report's own plots (plotters' SVG backend, as [`super::plot`]): SIMCor's
//! bootstrap density band with the real and virtual densities, and a χ² QQ plot of
//! Mahalanobis forms with the identity line.

use plotters::prelude::*;

/// Pixel size of every figure.
const SIZE: (u32, u32) = (640, 400);
/// Band, real density, virtual density, second QQ series (Okabe–Ito).
const BAND: RGBColor = RGBColor(86, 180, 233);
const REAL: RGBColor = RGBColor(213, 94, 0);
const VIRTUAL: RGBColor = RGBColor(0, 114, 178);

/// A density band plot's data.
#[derive(Debug, Clone, Copy)]
pub struct BandPlot<'a> {
    /// Title above the plot.
    pub title: &'a str,
    /// Caption of the x axis.
    pub x_label: &'a str,
    /// Grid of the densities.
    pub grid: &'a [f64],
    /// Lower band (2.5 % of the resampled virtual densities).
    pub lower: &'a [f64],
    /// Upper band (97.5 %).
    pub upper: &'a [f64],
    /// Real density.
    pub real: &'a [f64],
    /// Density of the whole virtual sample.
    pub virtual_density: &'a [f64],
}

/// The band as a filled area, the real density over it, the virtual density thinner.
pub fn band_svg(plot: &BandPlot<'_>) -> String {
    render(|root| draw_band(root, plot))
}

fn draw_band(
    root: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    p: &BandPlot<'_>,
) -> Result<(), DrawingAreaErrorKind<std::io::Error>> {
    root.fill(&WHITE)?;
    let (Some(&lo), Some(&hi)) = (p.grid.first(), p.grid.last()) else {
        return root.draw(&Text::new("no data", (20, 30), ("sans-serif", 20)));
    };
    let y_hi = [p.upper, p.real, p.virtual_density]
        .iter()
        .flat_map(|s| s.iter())
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
        .max(1e-12)
        * 1.1;
    let mut chart = ChartBuilder::on(root)
        .caption(p.title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(60)
        .build_cartesian_2d(lo..hi, 0.0..y_hi)?;
    chart
        .configure_mesh()
        .x_desc(p.x_label)
        .y_desc("density")
        .x_label_formatter(&|x| super::plot::tick(*x))
        .y_label_formatter(&|y| super::plot::tick(*y))
        .light_line_style(WHITE)
        .draw()?;
    let mut outline: Vec<(f64, f64)> = p
        .grid
        .iter()
        .copied()
        .zip(p.upper.iter().copied())
        .collect();
    outline.extend(p.grid.iter().copied().zip(p.lower.iter().copied()).rev());
    chart
        .draw_series(std::iter::once(Polygon::new(
            outline,
            BAND.mix(0.35).filled(),
        )))?
        .label("virtual 95 % bootstrap band")
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 16, y + 5)], BAND.mix(0.35).filled()));
    let line = |values: &[f64]| -> Vec<(f64, f64)> {
        p.grid.iter().copied().zip(values.iter().copied()).collect()
    };
    chart
        .draw_series(std::iter::once(PathElement::new(
            line(p.real),
            REAL.stroke_width(2),
        )))?
        .label("real density")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], REAL.stroke_width(2)));
    chart
        .draw_series(std::iter::once(PathElement::new(
            line(p.virtual_density),
            VIRTUAL.stroke_width(1),
        )))?
        .label("virtual density")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], VIRTUAL.stroke_width(1)));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
}

/// One set of QQ points.
#[derive(Debug, Clone)]
pub struct QqSeries {
    /// Legend text.
    pub name: String,
    /// (theoretical quantile, observed value) pairs.
    pub points: Vec<(f64, f64)>,
}

/// QQ points of each series against the identity line.
pub fn qq_svg(title: &str, x_label: &str, series: &[QqSeries]) -> String {
    render(|root| draw_qq(root, title, x_label, series))
}

fn draw_qq(
    root: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    title: &str,
    x_label: &str,
    series: &[QqSeries],
) -> Result<(), DrawingAreaErrorKind<std::io::Error>> {
    root.fill(&WHITE)?;
    let all = series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|(x, y)| x.is_finite() && y.is_finite());
    let hi = all.flat_map(|&(x, y)| [x, y]).fold(0.0, f64::max).max(1e-9) * 1.05;
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(52)
        .build_cartesian_2d(0.0..hi, 0.0..hi)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc("observed")
        .x_label_formatter(&|x| super::plot::tick(*x))
        .y_label_formatter(&|y| super::plot::tick(*y))
        .light_line_style(WHITE)
        .draw()?;
    chart
        .draw_series(std::iter::once(PathElement::new(
            vec![(0.0, 0.0), (hi, hi)],
            BLACK.mix(0.4).stroke_width(1),
        )))?
        .label("identity")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK.mix(0.4)));
    for (k, s) in series.iter().enumerate() {
        let colour = if k == 0 { VIRTUAL } else { REAL };
        chart
            .draw_series(
                s.points
                    .iter()
                    .map(|&(x, y)| Circle::new((x, y), 3, colour.filled())),
            )?
            .label(format!("{} (n = {})", s.name, s.points.len()))
            .legend(move |(x, y)| Circle::new((x + 8, y), 3, colour.filled()));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
}

fn render(
    draw: impl FnOnce(
        &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    ) -> Result<(), DrawingAreaErrorKind<std::io::Error>>,
) -> String {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        draw(&root).expect("drawing into a String cannot fail");
        root.present().expect("drawing into a String cannot fail");
    }
    svg
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_band_plot_draws_the_band_and_both_densities() {
        let grid: Vec<f64> = (0..50).map(|i| i as f64).collect();
        let bump: Vec<f64> = grid
            .iter()
            .map(|x| (-(x - 25.0).powi(2) / 50.0).exp())
            .collect();
        let lower: Vec<f64> = bump.iter().map(|v| 0.8 * v).collect();
        let upper: Vec<f64> = bump.iter().map(|v| 1.2 * v).collect();
        let svg = band_svg(&BandPlot {
            title: "annulus",
            x_label: "mm",
            grid: &grid,
            lower: &lower,
            upper: &upper,
            real: &bump,
            virtual_density: &bump,
        });
        assert!(
            svg.starts_with("<svg") && svg.contains("<polygon"),
            "{}",
            &svg[..80]
        );
        assert!(svg.contains("real density") && svg.contains("virtual 95 % bootstrap band"));
        assert!(
            svg.matches("<polyline").count() >= 2,
            "both densities are drawn"
        );
    }

    #[test]
    fn the_qq_plot_has_one_marker_per_point_and_the_identity_line() {
        let points = vec![(1.0, 1.2), (2.0, 1.9), (3.0, 3.3)];
        let svg = qq_svg(
            "QQ",
            "χ² quantile",
            &[QqSeries {
                name: "cohort".into(),
                points,
            }],
        );
        assert_eq!(
            svg.matches("<circle").count(),
            3 + 1,
            "three points and the legend's"
        );
        assert!(svg.contains("identity") && svg.contains("cohort (n = 3)"));
    }
}
