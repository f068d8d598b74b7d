//! Which sampler draws a cohort's latents: the paper's convex combinations of training
//! latents (the default), or a density model fitted to the training latents
//! ([`crate::latent_models`]) that aims at the population instead of its convex hull.
//!
//! [`SamplerFields`] is the request's `sampler` object (and the command line's `--sampler`
//! flags) as it arrives; [`SamplerChoice::parse`] checks its rules once, naming the field
//! (`sampler.truncation`, …), and fills the defaults. A density sampler is fitted to the
//! training latents *and* their unit-ball transforms jointly ([`joint`]), so every drawn
//! latent comes with the size and position it is served in (mm).
//!
//! How a density sampler combines with the other request fields:
//! * the mixture of a shape is the sampled latent followed by the anchors, so `arity` is
//!   1 + the number of anchors (it may be left out); `weights`/`weighting` weigh the sampled
//!   latent and the anchors exactly as they weigh training shapes and anchors;
//! * `selection: spread` and `latent_noise` > 0 belong to convex combinations and are
//!   refused (the sampler's own parameters set its spread);
//! * `min_novelty` redraws and `targets` candidates are further draws from the sampler
//!   with the attempt seeds of the seed scheme; targeted candidates are plain draws (no
//!   guided picks, no weight refinement: there are no mixed training shapes to steer).

pub mod joint;

use serde::{Deserialize, Serialize};

use super::RequestError;
use crate::latent_models::SamplerConfig;
use crate::latent_models::gaussian::PcaGaussianConfig;
use crate::latent_models::mixture::{ComponentCount, PcaMixtureConfig};
use crate::latent_models::pca::ModeSelection;
use crate::latent_models::shrinkage::Shrinkage;

/// Largest number of mixture components a request may ask for.
pub const MAX_COMPONENTS: i64 = 16;
/// Components the BIC chooses among when the request names neither count.
pub const DEFAULT_MAX_COMPONENTS: usize = 4;
/// Fewest leading modes a mixture may model.
pub const MIN_MIXTURE_MODES: i64 = 1;
/// Leading principal modes the mixture models by default.
pub const DEFAULT_MIXTURE_MODES: usize = 4;

/// The sampler kinds.
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    Eq,
    Serialize,
    Deserialize,
    utoipa::ToSchema,
    clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum SamplerKind {
    /// Convex combinations of `arity` training latents (the seed paper's generator).
    #[default]
    Convex,
    /// A Gaussian in the training latents' principal components, optionally truncated at
    /// ±c σ per mode (the statistical-shape-model practice for virtual TAVI cohorts).
    PcaGaussian,
    /// A Gaussian mixture on the leading whitened principal components (the other modes
    /// independent normal), components given or chosen by BIC.
    PcaMixture,
}

/// How the Gaussian's covariance is estimated from the training latents.
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    Eq,
    Serialize,
    Deserialize,
    utoipa::ToSchema,
    clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum CovarianceEstimate {
    /// The sample covariance, shrunk by `shrinkage` if given.
    #[default]
    Sample,
    /// Ledoit–Wolf: shrunk towards a multiple of the identity by the intensity the
    /// latents themselves suggest (with about as many latents as dimensions the sample
    /// covariance is too narrow in its trailing modes).
    LedoitWolf,
}

/// Which latents a density sampler is fitted to.
#[derive(
    Debug,
    Clone,
    Copy,
    Default,
    PartialEq,
    Eq,
    Serialize,
    Deserialize,
    utoipa::ToSchema,
    clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum LatentSource {
    /// The latents training optimised jointly with the network.
    #[default]
    Training,
    /// The training shapes fitted again with the network frozen (`aortagen refit`), as a
    /// new patient is fitted: they spread the way new patients land in latent space.
    Refitted,
}

/// A cohort request's `sampler` as it arrives.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SamplerFields {
    /// Which sampler.
    pub kind: SamplerKind,
    /// `pca_gaussian`: redraw each mode's normal variate until it lies within ±c (c > 0);
    /// absent: no truncation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truncation: Option<f64>,
    /// `pca_gaussian`: multiplies every mode's standard deviation (> 0, default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_scale: Option<f64>,
    /// `pca_gaussian`: how the covariance is estimated (default `sample`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covariance: Option<CovarianceEstimate>,
    /// `pca_gaussian` with the `sample` covariance: pull it towards a multiple of the
    /// identity by this intensity, in [0, 1] (default 0), keeping the total variance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shrinkage: Option<f64>,
    /// Density samplers: keep the fewest leading modes that explain this share of the
    /// latents' variance, in (0, 1] (default 1: every mode with variance).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub variance_share: Option<f64>,
    /// `pca_mixture`: exactly this many components (1–16).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub components: Option<i64>,
    /// `pca_mixture`: choose the component count by BIC from 1 to this (1–16, default 4)
    /// when `components` is absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_components: Option<i64>,
    /// `pca_mixture`: leading modes the mixture models (≥ 1, default 4).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mixture_modes: Option<i64>,
    /// Density samplers: the latents the density is fitted to (default `training`;
    /// `refitted` needs a model whose training shapes were re-fitted).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latents: Option<LatentSource>,
}

/// A checked sampler.
#[derive(Debug, Clone, PartialEq)]
pub enum SamplerChoice {
    /// Convex combinations of training latents.
    Convex,
    /// A density model of the training shapes' latents (with their transforms), fitted to
    /// the latents the source names.
    Density(SamplerConfig, LatentSource),
}

impl SamplerChoice {
    /// Checks `fields` (absent: convex); every parameter must belong to its kind.
    pub fn parse(fields: Option<&SamplerFields>) -> Result<Self, RequestError> {
        let Some(f) = fields else {
            return Ok(Self::Convex);
        };
        let only = |name: &str, given: bool, kinds: &str| -> Result<(), RequestError> {
            match given {
                false => Ok(()),
                true => Err(RequestError::new(
                    format!("sampler.{name}"),
                    "sampler-parameter",
                    format!("applies to the {kinds} sampler only, not {}", f.kind.name()),
                )),
            }
        };
        let gaussian = f.kind == SamplerKind::PcaGaussian;
        let mixture = f.kind == SamplerKind::PcaMixture;
        only(
            "truncation",
            f.truncation.is_some() && !gaussian,
            "pca_gaussian",
        )?;
        only(
            "sigma_scale",
            f.sigma_scale.is_some() && !gaussian,
            "pca_gaussian",
        )?;
        only(
            "covariance",
            f.covariance.is_some() && !gaussian,
            "pca_gaussian",
        )?;
        only(
            "shrinkage",
            f.shrinkage.is_some() && !gaussian,
            "pca_gaussian",
        )?;
        let density = "pca_gaussian or pca_mixture";
        only(
            "variance_share",
            f.variance_share.is_some() && !(gaussian || mixture),
            density,
        )?;
        only(
            "components",
            f.components.is_some() && !mixture,
            "pca_mixture",
        )?;
        only(
            "max_components",
            f.max_components.is_some() && !mixture,
            "pca_mixture",
        )?;
        only(
            "mixture_modes",
            f.mixture_modes.is_some() && !mixture,
            "pca_mixture",
        )?;
        only(
            "latents",
            f.latents.is_some() && !(gaussian || mixture),
            density,
        )?;
        let modes = mode_selection(f.variance_share)?;
        let latents = f.latents.unwrap_or_default();
        Ok(match f.kind {
            SamplerKind::Convex => Self::Convex,
            SamplerKind::PcaGaussian => Self::Density(
                SamplerConfig::PcaGaussian(PcaGaussianConfig {
                    modes,
                    truncation: positive("truncation", f.truncation)?,
                    sigma_scale: positive("sigma_scale", f.sigma_scale)?.unwrap_or(1.0),
                    shrinkage: shrinkage(f)?,
                }),
                latents,
            ),
            SamplerKind::PcaMixture => Self::Density(
                SamplerConfig::PcaMixture(mixture_config(f, modes)?),
                latents,
            ),
        })
    }

    /// Whether shapes are convex combinations of training latents.
    pub fn is_convex(&self) -> bool {
        matches!(self, Self::Convex)
    }

    /// The latents a density sampler is fitted to (none: convex combinations).
    pub fn latent_source(&self) -> Option<LatentSource> {
        match self {
            Self::Convex => None,
            Self::Density(_, latents) => Some(*latents),
        }
    }

    /// The sampler with every default filled in, as provenance records it (none: convex).
    pub fn recorded(&self) -> Option<SamplerFields> {
        let Self::Density(config, latents) = self else {
            return None;
        };
        let share = |modes: &ModeSelection| match modes {
            ModeSelection::VarianceShare(s) => Some(*s),
            _ => Some(1.0),
        };
        Some(match config {
            SamplerConfig::PcaGaussian(g) => SamplerFields {
                kind: SamplerKind::PcaGaussian,
                truncation: g.truncation,
                sigma_scale: Some(g.sigma_scale),
                covariance: Some(match g.shrinkage {
                    Some(Shrinkage::LedoitWolf) => CovarianceEstimate::LedoitWolf,
                    _ => CovarianceEstimate::Sample,
                }),
                shrinkage: match g.shrinkage {
                    Some(Shrinkage::Intensity(rho)) => Some(rho),
                    _ => None,
                },
                variance_share: share(&g.modes),
                latents: Some(*latents),
                ..SamplerFields::default()
            },
            SamplerConfig::PcaMixture(m) => {
                let (components, max_components) = match m.components {
                    ComponentCount::Fixed(k) => (Some(k as i64), None),
                    ComponentCount::Bic(k) => (None, Some(k as i64)),
                };
                SamplerFields {
                    kind: SamplerKind::PcaMixture,
                    variance_share: share(&m.modes),
                    components,
                    max_components,
                    mixture_modes: Some(m.mixture_modes as i64),
                    latents: Some(*latents),
                    ..SamplerFields::default()
                }
            }
        })
    }
}

impl SamplerKind {
    /// The request's name of the kind.
    pub fn name(self) -> &'static str {
        match self {
            Self::Convex => "convex",
            Self::PcaGaussian => "pca_gaussian",
            Self::PcaMixture => "pca_mixture",
        }
    }
}

fn mixture_config(
    f: &SamplerFields,
    modes: ModeSelection,
) -> Result<PcaMixtureConfig, RequestError> {
    let count = |name: &str, v: i64| -> Result<usize, RequestError> {
        match (1..=MAX_COMPONENTS).contains(&v) {
            true => Ok(v as usize),
            false => Err(RequestError::new(
                format!("sampler.{name}"),
                "range",
                format!("must be between 1 and {MAX_COMPONENTS}, got {v}"),
            )),
        }
    };
    if f.components.is_some() && f.max_components.is_some() {
        return Err(RequestError::new(
            "sampler.max_components",
            "exclusive",
            "give either components (a fixed count) or max_components (chosen by BIC), not both",
        ));
    }
    let components = match (f.components, f.max_components) {
        (Some(k), _) => ComponentCount::Fixed(count("components", k)?),
        (None, Some(k)) => ComponentCount::Bic(count("max_components", k)?),
        (None, None) => ComponentCount::Bic(DEFAULT_MAX_COMPONENTS),
    };
    let mixture_modes = match f.mixture_modes {
        None => DEFAULT_MIXTURE_MODES,
        Some(m) if m >= MIN_MIXTURE_MODES => usize::try_from(m).unwrap_or(usize::MAX),
        Some(m) => {
            let msg = format!("must be at least {MIN_MIXTURE_MODES}, got {m}");
            return Err(RequestError::new("sampler.mixture_modes", "range", msg));
        }
    };
    Ok(PcaMixtureConfig {
        modes,
        mixture_modes,
        components,
        ..PcaMixtureConfig::default()
    })
}

/// The Gaussian's shrinkage: Ledoit–Wolf, a fixed intensity in [0, 1], or none.
fn shrinkage(f: &SamplerFields) -> Result<Option<Shrinkage>, RequestError> {
    match (f.covariance.unwrap_or_default(), f.shrinkage) {
        (CovarianceEstimate::LedoitWolf, Some(_)) => Err(RequestError::new(
            "sampler.shrinkage",
            "exclusive",
            "the ledoit_wolf covariance estimates its own shrinkage; give shrinkage only with \
             the sample covariance",
        )),
        (CovarianceEstimate::LedoitWolf, None) => Ok(Some(Shrinkage::LedoitWolf)),
        (CovarianceEstimate::Sample, None) => Ok(None),
        (CovarianceEstimate::Sample, Some(rho)) if (0.0..=1.0).contains(&rho) => {
            Ok(Some(Shrinkage::Intensity(rho)))
        }
        (CovarianceEstimate::Sample, Some(rho)) => Err(RequestError::new(
            "sampler.shrinkage",
            "range",
            format!("must be in [0, 1], got {rho}"),
        )),
    }
}

fn mode_selection(share: Option<f64>) -> Result<ModeSelection, RequestError> {
    match share {
        // A share of 1 keeps exactly the modes with variance.
        None => Ok(ModeSelection::AllNonZero),
        Some(1.0) => Ok(ModeSelection::AllNonZero),
        Some(s) if s > 0.0 && s < 1.0 => Ok(ModeSelection::VarianceShare(s)),
        Some(s) => Err(RequestError::new(
            "sampler.variance_share",
            "range",
            format!("must be in (0, 1], got {s}"),
        )),
    }
}

fn positive(name: &str, value: Option<f64>) -> Result<Option<f64>, RequestError> {
    match value {
        Some(v) if !(v.is_finite() && v > 0.0) => Err(RequestError::new(
            format!("sampler.{name}"),
            "positive",
            format!("must be a finite number > 0, got {v}"),
        )),
        other => Ok(other),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fields(kind: SamplerKind) -> SamplerFields {
        SamplerFields {
            kind,
            ..SamplerFields::default()
        }
    }

    #[test]
    fn defaults_are_filled_and_recorded() {
        assert_eq!(SamplerChoice::parse(None).unwrap(), SamplerChoice::Convex);
        assert_eq!(SamplerChoice::Convex.recorded(), None);
        let g = SamplerChoice::parse(Some(&fields(SamplerKind::PcaGaussian))).unwrap();
        let recorded = g.recorded().unwrap();
        assert_eq!(
            (
                recorded.sigma_scale,
                recorded.variance_share,
                recorded.truncation
            ),
            (Some(1.0), Some(1.0), None)
        );
        let m = SamplerChoice::parse(Some(&fields(SamplerKind::PcaMixture))).unwrap();
        let SamplerChoice::Density(SamplerConfig::PcaMixture(config), _) = &m else {
            panic!("{m:?}");
        };
        assert_eq!(
            config.components,
            ComponentCount::Bic(DEFAULT_MAX_COMPONENTS)
        );
        assert_eq!(m.recorded().unwrap().max_components, Some(4));
        let shrunk = |covariance, shrinkage| {
            SamplerChoice::parse(Some(&SamplerFields {
                covariance,
                shrinkage,
                ..fields(SamplerKind::PcaGaussian)
            }))
            .unwrap()
        };
        let lw = shrunk(Some(CovarianceEstimate::LedoitWolf), None);
        let fixed = shrunk(None, Some(0.3));
        let SamplerChoice::Density(SamplerConfig::PcaGaussian(config), _) = &fixed else {
            panic!("{fixed:?}");
        };
        assert_eq!(config.shrinkage, Some(Shrinkage::Intensity(0.3)));
        let refitted = SamplerChoice::parse(Some(&SamplerFields {
            latents: Some(LatentSource::Refitted),
            ..fields(SamplerKind::PcaMixture)
        }))
        .unwrap();
        assert_eq!(refitted.latent_source(), Some(LatentSource::Refitted));
        assert_eq!(g.latent_source(), Some(LatentSource::Training));
        assert_eq!(g.recorded().unwrap().latents, Some(LatentSource::Training));
        assert_eq!(SamplerChoice::Convex.latent_source(), None);
        // The recorded form parses back to the same sampler.
        for choice in [g, m, lw, fixed, refitted] {
            let again = SamplerChoice::parse(choice.recorded().as_ref()).unwrap();
            assert_eq!(again, choice);
        }
    }

    #[test]
    fn each_broken_rule_names_its_field() {
        let cases = [
            (
                SamplerFields {
                    truncation: Some(2.0),
                    ..fields(SamplerKind::PcaMixture)
                },
                "sampler.truncation",
                "sampler-parameter",
            ),
            (
                SamplerFields {
                    components: Some(2),
                    ..fields(SamplerKind::PcaGaussian)
                },
                "sampler.components",
                "sampler-parameter",
            ),
            (
                SamplerFields {
                    variance_share: Some(0.9),
                    ..fields(SamplerKind::Convex)
                },
                "sampler.variance_share",
                "sampler-parameter",
            ),
            (
                SamplerFields {
                    latents: Some(LatentSource::Refitted),
                    ..fields(SamplerKind::Convex)
                },
                "sampler.latents",
                "sampler-parameter",
            ),
            (
                SamplerFields {
                    truncation: Some(0.0),
                    ..fields(SamplerKind::PcaGaussian)
                },
                "sampler.truncation",
                "positive",
            ),
            (
                SamplerFields {
                    sigma_scale: Some(f64::NAN),
                    ..fields(SamplerKind::PcaGaussian)
                },
                "sampler.sigma_scale",
                "positive",
            ),
            (
                SamplerFields {
                    shrinkage: Some(0.2),
                    ..fields(SamplerKind::PcaMixture)
                },
                "sampler.shrinkage",
                "sampler-parameter",
            ),
            (
                SamplerFields {
                    shrinkage: Some(1.01),
                    ..fields(SamplerKind::PcaGaussian)
                },
                "sampler.shrinkage",
                "range",
            ),
            (
                SamplerFields {
                    shrinkage: Some(0.2),
                    covariance: Some(CovarianceEstimate::LedoitWolf),
                    ..fields(SamplerKind::PcaGaussian)
                },
                "sampler.shrinkage",
                "exclusive",
            ),
            (
                SamplerFields {
                    variance_share: Some(1.5),
                    ..fields(SamplerKind::PcaGaussian)
                },
                "sampler.variance_share",
                "range",
            ),
            (
                SamplerFields {
                    components: Some(0),
                    ..fields(SamplerKind::PcaMixture)
                },
                "sampler.components",
                "range",
            ),
            (
                SamplerFields {
                    components: Some(2),
                    max_components: Some(3),
                    ..fields(SamplerKind::PcaMixture)
                },
                "sampler.max_components",
                "exclusive",
            ),
            (
                SamplerFields {
                    mixture_modes: Some(0),
                    ..fields(SamplerKind::PcaMixture)
                },
                "sampler.mixture_modes",
                "range",
            ),
        ];
        for (f, field, rule) in cases {
            let err = SamplerChoice::parse(Some(&f)).unwrap_err();
            assert_eq!((err.field.as_str(), err.rule), (field, rule), "{f:?}");
        }
    }
}
