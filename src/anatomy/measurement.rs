//! The anatomical measurements a request may name, as fields of [`ShapeAnatomy`] in mm.

use super::shape::ShapeAnatomy;

/// A measurement a target may name (the fields of [`ShapeAnatomy`] in mm).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Measurement {
    /// `annulus_mm`.
    Annulus,
    /// `sinus_mm`.
    Sinus,
    /// `stj_mm`.
    Stj,
    /// `sinus_height_mm`.
    SinusHeight,
    /// `ascending_mm`.
    Ascending,
    /// `length_mm`.
    Length,
    /// `max_diameter_mm`.
    MaxDiameter,
}

impl Measurement {
    /// Every measurement, in order.
    pub const ALL: [Self; 7] = [
        Self::Annulus,
        Self::Sinus,
        Self::Stj,
        Self::SinusHeight,
        Self::Ascending,
        Self::Length,
        Self::MaxDiameter,
    ];

    /// The name used in requests and in [`ShapeAnatomy`].
    pub fn name(self) -> &'static str {
        match self {
            Self::Annulus => "annulus_mm",
            Self::Sinus => "sinus_mm",
            Self::Stj => "stj_mm",
            Self::SinusHeight => "sinus_height_mm",
            Self::Ascending => "ascending_mm",
            Self::Length => "length_mm",
            Self::MaxDiameter => "max_diameter_mm",
        }
    }

    /// Parses a name.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Its value on a measured shape (the root landmarks are absent on a plain vessel).
    pub fn value(self, a: &ShapeAnatomy) -> Option<f64> {
        match self {
            Self::Annulus => a.annulus_mm,
            Self::Sinus => a.sinus_mm,
            Self::Stj => a.stj_mm,
            Self::SinusHeight => a.sinus_height_mm,
            Self::Ascending => a.ascending_mm,
            Self::Length => Some(a.length_mm),
            Self::MaxDiameter => Some(a.max_diameter_mm),
        }
    }

    /// The accepted names, for error messages.
    pub fn names() -> String {
        Self::ALL.map(Self::name).join(", ")
    }
}
