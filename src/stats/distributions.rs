//! The χ², Student-t and normal distributions: distribution functions and quantiles, built
//! on the special functions of [`super::special`]. Quantiles invert the distribution
//! functions with Newton steps kept inside a shrinking bracket (bisection whenever a step
//! would leave it), so they converge for every p in (0, 1). Reference values from
//! `scipy.stats` / `scipy.special` are in the tests (script: `tests/reference/special.py`).

use super::StatsError;
use super::special::{beta_inc, erfc, gamma_p, ln_gamma};

/// Distribution function of χ² with `k` > 0 degrees of freedom.
pub fn chi2_cdf(x: f64, k: f64) -> Result<f64, StatsError> {
    gamma_p(0.5 * k, 0.5 * x.max(0.0))
}

/// Quantile of χ² with `k` > 0 degrees of freedom, 0 < p < 1.
pub fn chi2_quantile(p: f64, k: f64) -> Result<f64, StatsError> {
    check_probability("χ² quantile", p)?;
    let a = 0.5 * k;
    let ln_norm = a * 2f64.ln() + ln_gamma(a)?;
    let pdf = |x: f64| {
        if x <= 0.0 {
            0.0
        } else {
            ((a - 1.0) * x.ln() - 0.5 * x - ln_norm).exp()
        }
    };
    let cdf = |x: f64| gamma_p(a, x.max(0.0) * 0.5).unwrap_or(0.0);
    // Wilson–Hilferty: (χ²/k)^(1/3) is nearly normal with mean 1 − 2/(9k).
    let z = normal_quantile(p)?;
    let v = 2.0 / (9.0 * k);
    let start = (k * (1.0 - v + z * v.sqrt()).powi(3)).max(1e-3 * k);
    let mut hi = start.max(1.0);
    while cdf(hi) < p {
        hi *= 2.0;
    }
    Ok(invert(&cdf, &pdf, p, 0.0, hi, start.min(hi)))
}

/// Distribution function of Student's t with `nu` > 0 degrees of freedom.
pub fn student_t_cdf(t: f64, nu: f64) -> Result<f64, StatsError> {
    if nu.is_nan() || nu <= 0.0 || t.is_nan() {
        return Err(StatsError::Domain {
            what: "Student t",
            detail: format!("needs ν > 0 and a number t, got ν = {nu}, t = {t}"),
        });
    }
    if t.is_infinite() {
        return Ok(if t > 0.0 { 1.0 } else { 0.0 });
    }
    let tail = 0.5 * beta_inc(0.5 * nu, 0.5, nu / (nu + t * t))?;
    Ok(if t > 0.0 { 1.0 - tail } else { tail })
}

/// Quantile of Student's t with `nu` > 0 degrees of freedom, 0 < p < 1.
pub fn student_t_quantile(p: f64, nu: f64) -> Result<f64, StatsError> {
    check_probability("Student t quantile", p)?;
    if p < 0.5 {
        return Ok(-student_t_quantile(1.0 - p, nu)?);
    }
    let ln_norm =
        ln_gamma(0.5 * nu)? + 0.5 * (nu * std::f64::consts::PI).ln() - ln_gamma(0.5 * (nu + 1.0))?;
    let pdf = |t: f64| (-0.5 * (nu + 1.0) * (1.0 + t * t / nu).ln() - ln_norm).exp();
    let cdf = |t: f64| student_t_cdf(t, nu).unwrap_or(0.5);
    let start = normal_quantile(p)?;
    let mut hi = start.max(1.0);
    while cdf(hi) < p {
        hi *= 2.0;
    }
    Ok(invert(&cdf, &pdf, p, 0.0, hi, start.min(hi)))
}

/// Standard normal distribution function Φ(x).
pub fn normal_cdf(x: f64) -> f64 {
    if x.is_nan() {
        return 0.5;
    }
    0.5 * erfc(-x / std::f64::consts::SQRT_2)
}

/// Standard normal density φ(x).
pub fn normal_pdf(x: f64) -> f64 {
    (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt()
}

/// Standard normal quantile Φ⁻¹(p), 0 < p < 1.
pub fn normal_quantile(p: f64) -> Result<f64, StatsError> {
    check_probability("normal quantile", p)?;
    if p > 0.5 {
        return Ok(-normal_quantile(1.0 - p)?);
    }
    if p == 0.5 {
        return Ok(0.0);
    }
    // Abramowitz & Stegun 26.2.23 (error < 4.5e-4) as the start, then Newton steps.
    let t = (-2.0 * p.ln()).sqrt();
    let num = 2.515_517 + t * (0.802_853 + t * 0.010_328);
    let den = 1.0 + t * (1.432_788 + t * (0.189_269 + t * 0.001_308));
    let mut x = -(t - num / den);
    for _ in 0..100 {
        let step = (normal_cdf(x) - p) / normal_pdf(x);
        x -= step;
        if step.abs() <= 1e-15 * x.abs().max(1.0) {
            break;
        }
    }
    Ok(x)
}

fn check_probability(what: &'static str, p: f64) -> Result<(), StatsError> {
    if p > 0.0 && p < 1.0 {
        Ok(())
    } else {
        Err(StatsError::Domain {
            what,
            detail: format!("needs 0 < p < 1, got {p}"),
        })
    }
}

/// Solves cdf(x) = p in [lo, hi] (cdf increasing, cdf(lo) ≤ p ≤ cdf(hi)) by Newton steps
/// from `x`, falling back to bisection whenever a step would leave the bracket.
fn invert(
    cdf: &dyn Fn(f64) -> f64,
    pdf: &dyn Fn(f64) -> f64,
    p: f64,
    mut lo: f64,
    mut hi: f64,
    mut x: f64,
) -> f64 {
    for _ in 0..500 {
        let f = cdf(x) - p;
        if f == 0.0 {
            return x;
        }
        if f < 0.0 {
            lo = x;
        } else {
            hi = x;
        }
        let density = pdf(x);
        let newton = x - f / density;
        let next = if density > 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if (next - x).abs() <= 1e-15 * x.abs().max(1e-300) {
            return next;
        }
        x = next;
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    // Printed by `python tests/reference/special.py` (scipy 1.17.1).
    const CHI2_QUANTILE: [(f64, f64, f64); 9] = [
        (0.05, 1.0, 0.003932140000019522),
        (0.5, 1.0, 0.454936423119572),
        (0.95, 1.0, 3.841458820694124),
        (0.001, 3.0, 0.024297585815692732),
        (0.5, 3.0, 2.3659738843753377),
        (0.975, 5.0, 12.832501994030027),
        (0.999, 8.0, 26.12448155837614),
        (0.01, 64.0, 40.648562828972494),
        (0.5, 128.0, 127.33395414332766),
    ];
    const STUDENT_T_CDF: [(f64, f64, f64); 6] = [
        (-3.0, 1.0, 0.10241638234956672),
        (0.7, 2.0, 0.7218034876835673),
        (2.1, 5.5, 0.9576540374351266),
        (-1.3, 17.3, 0.10532782802629392),
        (4.0, 40.0, 0.9998670438021666),
        (12.0, 3.0, 0.9993774920996054),
    ];
    const STUDENT_T_QUANTILE: [(f64, f64, f64); 5] = [
        (0.95, 1.0, 6.313751514675037),
        (0.95, 4.7, 2.043811093013787),
        (0.975, 30.0, 2.0422724563012378),
        (0.05, 12.0, -1.7822875556493194),
        (0.999, 2.0, 22.327124770119866),
    ];
    const NORMAL_CDF: [(f64, f64); 7] = [
        (-30.0, 4.906713927147908e-198),
        (-8.5, 9.47953482220325e-18),
        (-3.0, 0.0013498980316300933),
        (-0.4, 0.3445782583896758),
        (0.0, 0.5),
        (1.2, 0.8849303297782918),
        (5.0, 0.9999997133484281),
    ];
    const NORMAL_QUANTILE: [(f64, f64); 9] = [
        (1e-300, -37.0470962993612),
        (1e-12, -7.034483825301131),
        (0.001, -3.090232306167813),
        (0.025, -1.9599639845400545),
        (0.3, -0.5244005127080409),
        (0.5, 0.0),
        (0.8, 0.8416212335729143),
        (0.975, 1.959963984540054),
        (0.999999999, 5.997807019601637),
    ];

    fn assert_close(got: f64, want: f64, rel: f64, what: &str) {
        let tol = if want == 0.0 { 1e-15 } else { rel * want.abs() };
        assert!(
            (got - want).abs() <= tol,
            "{what}: got {got:e}, want {want:e}"
        );
    }

    #[test]
    fn chi2_quantile_matches_scipy_and_inverts_the_cdf() {
        for (p, k, want) in CHI2_QUANTILE {
            let got = chi2_quantile(p, k).unwrap();
            assert_close(got, want, 1e-11, &format!("χ²⁻¹({p}; {k})"));
            assert_close(chi2_cdf(got, k).unwrap(), p, 1e-12, "χ² round trip");
        }
        assert!(chi2_quantile(0.0, 2.0).is_err() && chi2_quantile(1.0, 2.0).is_err());
    }

    #[test]
    fn student_t_matches_scipy_and_the_cauchy_case() {
        for (t, nu, want) in STUDENT_T_CDF {
            assert_close(student_t_cdf(t, nu).unwrap(), want, 1e-12, "t cdf");
        }
        for (p, nu, want) in STUDENT_T_QUANTILE {
            assert_close(
                student_t_quantile(p, nu).unwrap(),
                want,
                1e-11,
                "t quantile",
            );
        }
        // ν = 1 is the Cauchy distribution: F(t) = ½ + atan(t)/π.
        for t in [-7.0, -0.2, 3.3] {
            let cauchy = 0.5 + f64::atan(t) / std::f64::consts::PI;
            assert_close(student_t_cdf(t, 1.0).unwrap(), cauchy, 1e-13, "Cauchy");
        }
    }

    #[test]
    fn normal_distribution_matches_scipy_and_is_symmetric() {
        for (x, want) in NORMAL_CDF {
            // e^(−x²/2) loses |x²/2| ulps of relative precision in the far tail
            let rel = if x < -10.0 { 1e-12 } else { 1e-13 };
            assert_close(normal_cdf(x), want, rel, &format!("Φ({x})"));
            assert!((normal_cdf(x) + normal_cdf(-x) - 1.0).abs() < 1e-15);
        }
        for (p, want) in NORMAL_QUANTILE {
            let got = normal_quantile(p).unwrap();
            assert!(
                (got - want).abs() <= 1e-13 * want.abs().max(1.0),
                "Φ⁻¹({p}) = {got}"
            );
        }
        assert!(normal_quantile(0.0).is_err() && normal_quantile(f64::NAN).is_err());
    }
}
