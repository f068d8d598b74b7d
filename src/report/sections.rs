//! Report sections built from the project's results: the reconstruction fidelity of a model
//! (the seed paper's Fig. 2) and the pairwise distances within a cohort (its Fig. 3), and any
//! other distribution of per-shape values.

use super::html::Section;
use super::plot::{HistogramPlot, Marker, histogram_svg, tick};
use crate::sdf::inference::evaluation::{CHAMFER_UNITS, quantile};

/// Chamfer distances as every report labels them.
pub const CD_LABEL: &str = "Chamfer distance (unit ball, squared)";

/// A histogram of `values` with their order statistics beside it.
pub fn distribution(
    heading: &str,
    caption: &str,
    x_label: &str,
    values: &[f64],
    markers: &[Marker],
) -> Section {
    let svg = histogram_svg(&HistogramPlot {
        title: heading,
        x_label,
        values,
        markers,
    });
    let mut rows = order_statistics(values);
    rows.extend(markers.iter().map(|m| (m.label.clone(), tick(m.value))));
    Section {
        heading: heading.to_owned(),
        caption: caption.to_owned(),
        svg,
        rows,
    }
}

/// Reconstruction Chamfer distances of a model's training shapes, with the sampling floor
/// (the CD of two samplings of one surface: nothing below it is measurable).
pub fn reconstruction_cd(cds: &[f64], sampling_floor: Option<f64>) -> Section {
    let markers: Vec<Marker> = sampling_floor
        .map(|value| Marker {
            label: "sampling floor (median)".into(),
            value,
        })
        .into_iter()
        .collect();
    distribution(
        "Reconstruction Chamfer distance",
        &format!(
            "Each training shape reconstructed from its latent code and compared with its \
             original mesh; {CHAMFER_UNITS}."
        ),
        CD_LABEL,
        cds,
        &markers,
    )
}

/// Pairwise Chamfer distances among a cohort's shapes (each unordered pair once): every
/// pair, or a random sample of the `sampled_from` pairs of a large cohort.
pub fn pairwise_cd(values: &[f64], sampled_from: Option<u64>) -> Section {
    let which = match sampled_from {
        None => "Every unordered pair of generated shapes".to_owned(),
        Some(population) => format!(
            "A uniform random sample of {} of the {population} unordered pairs of generated \
             shapes",
            values.len()
        ),
    };
    distribution(
        "Pairwise Chamfer distance within the cohort",
        &format!("{which}; a wider distribution means a more diverse cohort. {CHAMFER_UNITS}."),
        CD_LABEL,
        values,
        &[],
    )
}

/// Distances of generated shapes to their nearest training shape (privacy of the training
/// patients: a shape at the sampling floor would be a copy).
pub fn novelty_cd(values: &[f64], markers: &[Marker]) -> Section {
    distribution(
        "Novelty: Chamfer distance to the nearest training shape",
        &format!(
            "For each generated shape, the distance to the closest reconstruction of a training \
             shape; small values mean near-copies of a training patient. {CHAMFER_UNITS}."
        ),
        CD_LABEL,
        values,
        markers,
    )
}

/// The requested minimum novelty as a reference line, when the cohort asked for one.
pub fn novelty_floor(min_novelty: Option<f64>) -> Option<Marker> {
    min_novelty.filter(|v| *v > 0.0).map(|value| Marker {
        label: "requested minimum".into(),
        value,
    })
}

/// The entries above the diagonal of a square matrix, row by row.
pub fn upper_triangle(matrix: &[Vec<f64>]) -> Vec<f64> {
    matrix
        .iter()
        .enumerate()
        .flat_map(|(i, row)| row.iter().skip(i + 1).copied())
        .collect()
}

/// Count, mean, standard deviation and quantiles as label/value rows.
pub fn order_statistics(values: &[f64]) -> Vec<(String, String)> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    let mut rows = vec![("n".to_owned(), v.len().to_string())];
    if v.is_empty() {
        return rows;
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let std = if v.len() > 1 {
        (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    } else {
        0.0
    };
    rows.push(("mean".into(), tick(mean)));
    rows.push(("std".into(), tick(std)));
    for (label, q) in [
        ("min", 0.0),
        ("q05", 0.05),
        ("q25", 0.25),
        ("median", 0.5),
        ("q75", 0.75),
        ("q95", 0.95),
        ("max", 1.0),
    ] {
        rows.push((label.into(), tick(quantile(&v, q))));
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upper_triangle_takes_each_pair_once() {
        let m = vec![
            vec![0.0, 1.0, 2.0],
            vec![1.0, 0.0, 3.0],
            vec![2.0, 3.0, 0.0],
        ];
        assert_eq!(upper_triangle(&m), vec![1.0, 2.0, 3.0]);
        assert!(upper_triangle(&[vec![0.0]]).is_empty());
    }

    #[test]
    fn order_statistics_match_hand_computed_values() {
        let rows = order_statistics(&[4.0, 1.0, f64::NAN, 3.0, 2.0]);
        let get = |k: &str| rows.iter().find(|(l, _)| l == k).unwrap().1.clone();
        assert_eq!(get("n"), "4");
        assert_eq!(get("mean"), "2.5");
        assert_eq!(get("median"), "2.5");
        assert_eq!(get("min"), "1");
        assert_eq!(get("max"), "4");
        // Sample standard deviation of 1..4 is sqrt(5/3) = 1.291.
        assert_eq!(get("std"), "1.291");
        assert_eq!(
            order_statistics(&[]),
            vec![("n".to_owned(), "0".to_owned())]
        );
    }

    #[test]
    fn reconstruction_section_shows_the_floor() {
        let s = reconstruction_cd(&[1e-4, 2e-4, 3e-4], Some(5e-5));
        assert!(
            s.rows
                .contains(&("sampling floor (median)".into(), "5.00e-5".into()))
        );
        assert!(s.svg.contains("sampling floor"));
        assert!(s.svg.contains("n = 3"));
    }
}
