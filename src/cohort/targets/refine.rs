//! Weight refinement: moving a missing draw's weights on the simplex, as little as they can,
//! until the predicted measurements lie inside the targets.

use super::Targets;
use crate::anatomy::shape::ShapeAnatomy;

/// Convex weights for a mixture whose first `indices.len()` weights belong to those training
/// shapes (any further weights, e.g. anchors', stay fixed) that should bring its
/// measurements into `targets`, given that the mixture measured `measured`.
///
/// Each measurement is predicted as the weighted mean of the parts' training measurements
/// plus the residual the current weights left (which carries the fixed parts, the latent
/// noise and the decoder's departure from linearity). The weights then descend on the
/// squared distance of the prediction outside the targets, inset by a quarter of each
/// two-sided range (a tenth of the parts' spread for a one-sided bound) so that the
/// remaining non-linearity still lands inside, projected onto the simplex of the same total
/// weight. Starting from the current weights, they stop as soon as the prediction is inside,
/// so a refined mixture stays as close as it can to its draw. `None` when a part or a target
/// is unmeasured, fewer than two weights can move, they would not move, or even the
/// prediction of the best weights misses the targets.
pub fn refine_weights(
    targets: &Targets,
    training: &[Option<ShapeAnatomy>],
    indices: &[usize],
    weights: &[f64],
    measured: &ShapeAnatomy,
) -> Option<Vec<f64>> {
    let k = indices.len();
    if k < 2 || weights.len() < k {
        return None;
    }
    let start = &weights[..k];
    let mass: f64 = start.iter().sum();
    if !mass.is_finite() || mass <= 1e-9 {
        return None;
    }
    /// One target's linear prediction `p(w) = slope · w + offset` and its aim `[lo, hi]`.
    struct Row {
        slope: Vec<f64>,
        offset: f64,
        lo: f64,
        hi: f64,
    }
    let mut rows = Vec::new();
    for (m, range) in targets.iter() {
        let values = indices
            .iter()
            .map(|&i| training.get(i)?.as_ref().and_then(|a| m.value(a)))
            .collect::<Option<Vec<f64>>>()?;
        let actual = m.value(measured)?;
        let predicted: f64 = values.iter().zip(start).map(|(v, w)| v * w).sum();
        let mean = values.iter().sum::<f64>() / k as f64;
        let (lo, hi) = values
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        let inset = match (range.min, range.max) {
            (Some(a), Some(b)) => 0.25 * (b - a),
            _ => 0.1 * (hi - lo),
        };
        rows.push(Row {
            // Centred: the weights' sum is fixed, so the mean only shifts the offset and the
            // descent is better conditioned.
            slope: values.iter().map(|v| v - mean).collect(),
            offset: mass * mean + (actual - predicted),
            lo: range.min.map_or(f64::NEG_INFINITY, |a| a + inset),
            hi: range.max.map_or(f64::INFINITY, |b| b - inset),
        });
    }
    let lipschitz: f64 = rows
        .iter()
        .map(|r| r.slope.iter().map(|s| s * s).sum::<f64>())
        .sum();
    if lipschitz <= 1e-12 {
        return None;
    }
    let mut w = start.to_vec();
    for _ in 0..2000 {
        let mut gradient = vec![0.0; k];
        for r in &rows {
            let p: f64 = r.slope.iter().zip(&w).map(|(s, w)| s * w).sum::<f64>() + r.offset;
            let excess = if p > r.hi {
                p - r.hi
            } else if p < r.lo {
                p - r.lo
            } else {
                0.0
            };
            for (g, s) in gradient.iter_mut().zip(&r.slope) {
                *g += excess * s;
            }
        }
        if gradient.iter().all(|g| g.abs() < 1e-12) {
            break;
        }
        let stepped: Vec<f64> = w
            .iter()
            .zip(&gradient)
            .map(|(w, g)| w - g / lipschitz)
            .collect();
        w = project_to_simplex(&stepped, mass);
    }
    let moved = w.iter().zip(start).any(|(a, b)| (a - b).abs() > 1e-4);
    // A mixture whose parts cannot reach the targets even by the prediction is better
    // replaced by a fresh draw than refined.
    let reaches = targets.iter().zip(&rows).all(|((_, range), r)| {
        let p: f64 = r.slope.iter().zip(&w).map(|(s, w)| s * w).sum::<f64>() + r.offset;
        range.miss(p) < 1e-9
    });
    (moved && reaches).then(|| [w.as_slice(), &weights[k..]].concat())
}

/// The nearest point to `v` with non-negative entries summing to `mass` (Euclidean).
fn project_to_simplex(v: &[f64], mass: f64) -> Vec<f64> {
    let mut sorted = v.to_vec();
    sorted.sort_by(|a, b| b.total_cmp(a));
    let (mut sum, mut shift) = (0.0, 0.0);
    for (j, u) in sorted.iter().enumerate() {
        sum += u;
        let candidate = (sum - mass) / (j + 1) as f64;
        if u - candidate > 0.0 {
            shift = candidate;
        }
    }
    v.iter().map(|x| (x - shift).max(0.0)).collect()
}

#[cfg(test)]
mod tests {
    use super::super::search::{CandidateSource, MAX_REFINEMENTS, Measured, search};
    use super::super::test_support::{anatomy, targets};
    use super::*;

    /// Training shapes 0 and 1 with annuli 20 and 30 mm (length 60 and 80 mm).
    fn two_roots() -> Vec<Option<ShapeAnatomy>> {
        vec![
            Some(anatomy(Some(20.0), 60.0)),
            Some(anatomy(Some(30.0), 80.0)),
        ]
    }

    fn annulus_of(weights: &[f64]) -> f64 {
        20.0 * weights[0] + 30.0 * weights[1]
    }

    #[test]
    fn refined_weights_bring_a_linear_measurement_just_inside_the_inset_range() {
        let t = targets(&[("annulus_mm", Some(28.0), Some(30.0))]).unwrap();
        let training = two_roots();
        // Measured exactly as the linear prediction: the aim is [28.5, 29.5], reached at
        // its near end, so w₁ = 0.85.
        let w = refine_weights(
            &t,
            &training,
            &[0, 1],
            &[0.5, 0.5],
            &anatomy(Some(25.0), 70.0),
        )
        .unwrap();
        assert!((w[0] + w[1] - 1.0).abs() < 1e-12 && w.iter().all(|&x| x >= 0.0));
        assert!((annulus_of(&w) - 28.5).abs() < 1e-3, "{w:?}");
        // The shape measured 1 mm above the prediction: the residual is carried over.
        let w = refine_weights(
            &t,
            &training,
            &[0, 1],
            &[0.5, 0.5],
            &anatomy(Some(26.0), 70.0),
        )
        .unwrap();
        assert!((annulus_of(&w) + 1.0 - 28.5).abs() < 1e-3, "{w:?}");
    }

    #[test]
    fn refinement_keeps_fixed_weights_and_meets_several_targets() {
        let t = targets(&[
            ("annulus_mm", Some(22.0), Some(24.0)),
            ("length_mm", None, Some(70.0)),
        ])
        .unwrap();
        let training = vec![
            Some(anatomy(Some(20.0), 60.0)),
            Some(anatomy(Some(30.0), 80.0)),
            Some(anatomy(Some(24.0), 90.0)),
        ];
        // The last weight (an anchor's) stays; the three training parts share 0.7.
        let start = [0.1, 0.3, 0.3, 0.3];
        let measured = anatomy(Some(26.0), 80.0);
        let w = refine_weights(&t, &training, &[0, 1, 2], &start, &measured).unwrap();
        assert_eq!(w.len(), 4);
        assert_eq!(w[3], 0.3);
        assert!((w[..3].iter().sum::<f64>() - 0.7).abs() < 1e-12);
        let linear = |w: &[f64], f: fn(&ShapeAnatomy) -> f64| -> f64 {
            let parts: f64 = (0..3)
                .map(|i| w[i] * f(training[i].as_ref().unwrap()))
                .sum();
            let start_parts: f64 = (0..3)
                .map(|i| start[i] * f(training[i].as_ref().unwrap()))
                .sum();
            parts + f(&measured) - start_parts
        };
        let annulus = linear(&w, |a| a.annulus_mm.unwrap());
        let length = linear(&w, |a| a.length_mm);
        assert!(
            (22.0..=24.0).contains(&annulus),
            "annulus {annulus} from {w:?}"
        );
        assert!(length <= 70.0 + 1e-6, "length {length} from {w:?}");
    }

    #[test]
    fn refinement_declines_what_it_cannot_improve() {
        let t = targets(&[("annulus_mm", Some(24.0), Some(26.0))]).unwrap();
        let training = two_roots();
        let inside = anatomy(Some(25.0), 70.0);
        // Already inside the aim: the weights would not move.
        assert_eq!(
            refine_weights(&t, &training, &[0, 1], &[0.5, 0.5], &inside),
            None
        );
        let outside = anatomy(Some(21.0), 70.0);
        // A part without a measurement, a single movable weight, or an unmeasured target.
        let unmeasured = vec![training[0].clone(), None];
        assert_eq!(
            refine_weights(&t, &unmeasured, &[0, 1], &[0.5, 0.5], &outside),
            None
        );
        assert_eq!(
            refine_weights(&t, &training, &[0], &[0.5, 0.5], &outside),
            None
        );
        let vessel = anatomy(None, 70.0);
        assert_eq!(
            refine_weights(&t, &training, &[0, 1], &[0.5, 0.5], &vessel),
            None
        );
        // Both parts' annuli (20 and 30 mm) lie above 19 mm and the mixture measured as
        // predicted (25 mm): no weights can reach it.
        let below = targets(&[("annulus_mm", None, Some(19.0))]).unwrap();
        assert_eq!(
            refine_weights(&below, &training, &[0, 1], &[0.5, 0.5], &inside),
            None
        );
        // Measured 5 mm below the prediction, the same mixture can: all weight on part 0.
        let low = anatomy(Some(20.0), 70.0);
        let w = refine_weights(&below, &training, &[0, 1], &[0.5, 0.5], &low).unwrap();
        assert!(annulus_of(&w) - 5.0 <= 19.0 && w[0] > 0.5, "{w:?}");
    }

    #[test]
    fn projection_onto_the_simplex_is_the_nearest_point() {
        let p = project_to_simplex(&[0.5, 0.7, -0.2], 1.0);
        let expected = [0.4, 0.6, 0.0];
        assert!(
            p.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-12),
            "{p:?}"
        );
        // Brute force over a fine grid of the simplex.
        let v = [0.9, -0.4, 0.3];
        let p = project_to_simplex(&v, 0.6);
        let dist = |q: &[f64]| q.iter().zip(&v).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        let n = 600;
        let best = (0..=n)
            .flat_map(|i| (0..=n - i).map(move |j| (i, j)))
            .map(|(i, j)| {
                let (a, b) = (0.6 * i as f64 / n as f64, 0.6 * j as f64 / n as f64);
                dist(&[a, b, 0.6 - a - b])
            })
            .fold(f64::INFINITY, f64::min);
        assert!((p.iter().sum::<f64>() - 0.6).abs() < 1e-12 && p.iter().all(|&x| x >= 0.0));
        assert!(dist(&p) <= best + 1e-9, "{p:?}");
    }

    /// Two training roots mixed by weight; the decoder bends the annulus by up to 1.5 mm
    /// (largest at equal weights), so one linear step does not land exactly.
    struct Bent {
        training: Vec<Option<ShapeAnatomy>>,
        targets: Targets,
        draws: Vec<u32>,
    }

    impl CandidateSource for Bent {
        type Spec = Vec<f64>;
        type Kept = Vec<f64>;
        type Error = ();
        fn draw(&mut self, attempt: u32) -> Result<Vec<f64>, ()> {
            self.draws.push(attempt);
            Ok(vec![0.9, 0.1])
        }
        fn refine(&mut self, w: &Vec<f64>, measured: &ShapeAnatomy) -> Option<Vec<f64>> {
            refine_weights(&self.targets, &self.training, &[0, 1], w, measured)
        }
        fn screen(&mut self, w: &Vec<f64>) -> Result<Result<ShapeAnatomy, String>, ()> {
            Ok(Ok(anatomy(Some(bent(w)), 70.0)))
        }
        fn finalize(&mut self, _: u32, w: &Vec<f64>) -> Result<Measured<Vec<f64>>, ()> {
            Ok(Measured {
                candidate: w.clone(),
                anatomy: Ok(anatomy(Some(bent(w)), 70.0)),
                accept: true,
                rank: 0.0,
            })
        }
    }

    fn bent(w: &[f64]) -> f64 {
        annulus_of(w) + 6.0 * w[0] * w[1]
    }

    #[test]
    fn the_search_refines_the_weights_of_a_missing_draw_until_it_meets_the_target() {
        let t = targets(&[("annulus_mm", Some(26.0), Some(27.0))]).unwrap();
        let mut source = Bent {
            training: two_roots(),
            targets: t.clone(),
            draws: Vec::new(),
        };
        let o = search(&t, 10, true, &mut source).unwrap();
        assert!(o.met, "{:?}", o.kept.candidate);
        assert!((26.0..=27.0).contains(&bent(&o.kept.candidate)));
        // Every drawn mixture is [0.9, 0.1] (21.4 mm): only refinement can meet the target.
        assert!(o.refined >= 1 && o.candidates <= 1 + MAX_REFINEMENTS);
        assert_eq!(source.draws, [0]);
        assert_eq!(o.candidates, o.attempt + 1);
    }
}
