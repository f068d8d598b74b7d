//! The anatomical measurements ("features", as SIMCor's tables call them) a validation
//! compares, one value per shape in mm, mm² or mm³: the aortic-root and vessel
//! measurements of [`crate::anatomy`] plus the surface area and enclosed volume, which
//! every closed shape has even where the root landmarks are not found.
//!
//! Measurement tables may use SIMCor's column names for the aortic-root features
//! (ecrin-github/SIMCor, its example feature tables): `D_an` is our `annulus_mm`, `D_sinus`
//! `sinus_mm`, `D_stj` `stj_mm`, `H_sinus` `sinus_height_mm`. Its other columns (`D_lvot`,
//! `AVA`, `angle`, `ratio_lvot_over_an_area`) describe the outflow tract and the valve,
//! which aortagen does not measure: a table may carry them, and the validation says they
//! were not compared.

use serde::{Deserialize, Serialize};

use crate::anatomy::measurement::Measurement;
use crate::anatomy::shape::ShapeAnatomy;

/// One compared measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(into = "String", try_from = "String")]
pub enum Feature {
    /// A root or vessel measurement in mm.
    Anatomy(Measurement),
    /// Surface area, mm².
    Area,
    /// Enclosed volume, mm³.
    Volume,
}

/// SIMCor's names of features aortagen measures, with ours.
pub const SIMCOR_NAMES: [(&str, Measurement); 4] = [
    ("D_an", Measurement::Annulus),
    ("D_sinus", Measurement::Sinus),
    ("D_stj", Measurement::Stj),
    ("H_sinus", Measurement::SinusHeight),
];

/// SIMCor's feature names aortagen does not measure (accepted in tables, not compared).
pub const SIMCOR_UNMEASURED: [&str; 4] = ["D_lvot", "AVA", "angle", "ratio_lvot_over_an_area"];

impl Feature {
    /// Every feature, in report order.
    pub const ALL: [Self; 9] = [
        Self::Anatomy(Measurement::Annulus),
        Self::Anatomy(Measurement::Sinus),
        Self::Anatomy(Measurement::Stj),
        Self::Anatomy(Measurement::SinusHeight),
        Self::Anatomy(Measurement::Ascending),
        Self::Anatomy(Measurement::Length),
        Self::Anatomy(Measurement::MaxDiameter),
        Self::Area,
        Self::Volume,
    ];

    /// Its name in requests and reports (`annulus_mm`, …, `area_mm2`, `volume_mm3`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Anatomy(m) => m.name(),
            Self::Area => "area_mm2",
            Self::Volume => "volume_mm3",
        }
    }

    /// Its unit as printed.
    pub fn unit(self) -> &'static str {
        match self {
            Self::Anatomy(_) => "mm",
            Self::Area => "mm²",
            Self::Volume => "mm³",
        }
    }

    /// The power of mm it is measured in (1, 2 or 3).
    pub fn dimension(self) -> u32 {
        match self {
            Self::Anatomy(_) => 1,
            Self::Area => 2,
            Self::Volume => 3,
        }
    }

    /// The feature our name or SIMCor's names.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|f| f.name() == name)
            .or_else(|| {
                SIMCOR_NAMES
                    .iter()
                    .find(|(simcor, _)| *simcor == name)
                    .map(|(_, m)| Self::Anatomy(*m))
            })
    }

    /// Every accepted name, for error messages.
    pub fn names() -> String {
        let ours = Self::ALL.map(Self::name).join(", ");
        let simcor: Vec<&str> = SIMCOR_NAMES.iter().map(|(s, _)| *s).collect();
        format!("{ours} (or SIMCor's {})", simcor.join(", "))
    }
}

impl From<Feature> for String {
    fn from(f: Feature) -> Self {
        f.name().to_owned()
    }
}

impl TryFrom<String> for Feature {
    type Error = String;

    fn try_from(name: String) -> Result<Self, String> {
        Self::parse(&name).ok_or_else(|| format!("{name:?} is not a measurement"))
    }
}

/// The values of every feature of one shape (`None` where it was not measured).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FeatureValues(pub std::collections::BTreeMap<Feature, f64>);

impl FeatureValues {
    /// The features of a measured shape with its area (mm²) and volume (mm³).
    pub fn of_shape(anatomy: Option<&ShapeAnatomy>, area_mm2: f64, volume_mm3: f64) -> Self {
        let mut values = std::collections::BTreeMap::new();
        if let Some(a) = anatomy {
            for m in Measurement::ALL {
                if let Some(v) = m.value(a).filter(|v| v.is_finite()) {
                    values.insert(Feature::Anatomy(m), v);
                }
            }
        }
        for (f, v) in [(Feature::Area, area_mm2), (Feature::Volume, volume_mm3)] {
            if v.is_finite() && v > 0.0 {
                values.insert(f, v);
            }
        }
        Self(values)
    }

    /// One feature's value, if measured.
    pub fn get(&self, feature: Feature) -> Option<f64> {
        self.0.get(&feature).copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn our_names_and_simcor_names_parse_and_serialise_as_ours() {
        assert_eq!(
            Feature::parse("D_an"),
            Some(Feature::Anatomy(Measurement::Annulus))
        );
        assert_eq!(
            Feature::parse("H_sinus"),
            Some(Feature::Anatomy(Measurement::SinusHeight))
        );
        assert_eq!(Feature::parse("volume_mm3"), Some(Feature::Volume));
        assert_eq!(Feature::parse("D_lvot"), None);
        for f in Feature::ALL {
            assert_eq!(Feature::parse(f.name()), Some(f));
            let json = serde_json::to_string(&f).unwrap();
            assert_eq!(serde_json::from_str::<Feature>(&json).unwrap(), f);
        }
        assert!(serde_json::from_str::<Feature>("\"D_an\"").is_ok());
        assert!(Feature::names().contains("D_stj"));
    }

    #[test]
    fn a_vessel_without_root_landmarks_has_only_its_vessel_features() {
        let vessel = ShapeAnatomy {
            method: "vessel".into(),
            annulus_mm: None,
            sinus_mm: None,
            stj_mm: None,
            sinus_height_mm: None,
            ascending_mm: None,
            length_mm: 80.0,
            max_diameter_mm: 30.0,
            root_error: Some("no sinus".into()),
            measurement_version: crate::anatomy::shape::MEASUREMENT_VERSION,
        };
        let v = FeatureValues::of_shape(Some(&vessel), 100.0, f64::NAN);
        assert_eq!(v.get(Feature::Anatomy(Measurement::Length)), Some(80.0));
        assert_eq!(v.get(Feature::Anatomy(Measurement::Annulus)), None);
        assert_eq!(
            (v.get(Feature::Area), v.get(Feature::Volume)),
            (Some(100.0), None)
        );
        assert_eq!(FeatureValues::of_shape(None, 1.0, 2.0).0.len(), 2);
    }
}
