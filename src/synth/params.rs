//! Shape parameters of a parametric aortic root and how they are drawn from published
//! normal adult ranges.
//!
//! Every length is drawn as `lo + (hi − lo)·t` with `t = 0.8·size + 0.2·own`, where `size`
//! is one bell-shaped body-size factor shared by the whole shape and `own` is independent per
//! parameter. The shared factor reproduces the strong correlation between the levels of a real
//! root (large annulus ⇒ large sinus), keeps the ratios near the published ones
//! (STJ/annulus ≈ 1.15, sinus/annulus ≈ 1.4 at the centre of the ranges, Vriz et al. 2014) and
//! guarantees by construction the ordering of a normal root: the sinus is wider than the
//! annulus major axis and the STJ by at least 3 mm (checked by [`AorticRootParams::validate`])
//! and wider than the ascending aorta (Schaefer et al., Heart 2008;94:1634–1638:
//! the normal "N" root shape).
//!
//! All draws use only `next_u64` and IEEE arithmetic (no `ln`/`cos`), so a seed gives the same
//! shape on every platform.

use rand::Rng;
use serde::{Deserialize, Serialize};

/// A closed interval of plausible values, in the parameter's unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// Smallest value.
    pub lo: f64,
    /// Largest value.
    pub hi: f64,
}

impl Range {
    const fn new(lo: f64, hi: f64) -> Self {
        Self { lo, hi }
    }
    /// True when `x` lies in the closed interval.
    pub fn contains(&self, x: f64) -> bool {
        (self.lo..=self.hi).contains(&x)
    }
    fn at(&self, t: f64) -> f64 {
        self.lo + (self.hi - self.lo) * t
    }
}

/// Mean annulus diameter (mean of the major and minor axes), mm. Normal adults by 2-D echo
/// (Roman et al., Am J Cardiol 1989;64:507–512) and by TTE in 1 043 healthy adults
/// (Vriz et al., Am J Cardiol 2014;114:921–927): about 20–29 mm.
pub const ANNULUS_DIAMETER: Range = Range::new(20.0, 29.0);
/// Annulus minor/major axis ratio. The annulus is oval in multislice CT
/// (Tops et al., JACC Cardiovasc Imaging 2008;1:321–330), typical ratios 0.75–0.95.
pub const ANNULUS_ELLIPTICITY: Range = Range::new(0.75, 0.95);
/// Sinus of Valsalva diameter, mm (twice the largest centre-to-wall distance). Roman et al.
/// 1989; Devereux et al., Am J Cardiol 2012;110:1189–1194 (normal range 21–43 mm, adult
/// central range about 29–39 mm).
pub const SINUS_DIAMETER: Range = Range::new(29.0, 39.0);
/// Sinus height (annulus plane to sinotubular junction), mm. Swanson & Clark, Circ Res
/// 1974;35:871–882; Berdajs et al., Cardiovasc Surg 2002;10:320–327: about 17–24 mm.
pub const SINUS_HEIGHT: Range = Range::new(17.0, 24.0);
/// Sinotubular-junction diameter, mm. Roman et al. 1989; Vriz et al. 2014: about 24–33 mm.
pub const STJ_DIAMETER: Range = Range::new(24.0, 33.0);
/// Proximal ascending-aorta diameter, mm. Roman et al. 1989; CT normals of Mao et al.,
/// Acad Radiol 2008;15:827–834: about 25–36 mm.
pub const ASCENDING_DIAMETER: Range = Range::new(25.0, 36.0);
/// Length of the ascending segment along its centreline (STJ towards the brachiocephalic
/// origin), mm. Sugawara et al., JACC Cardiovasc Imaging 2008;1:739–748 report a few
/// centimetres that lengthen with age; 45–75 mm.
pub const ASCENDING_LENGTH: Range = Range::new(45.0, 75.0);
/// Radius of the ascending centreline arc, mm. A modelling choice, not a published range:
/// at least three tube radii so the swept surface can never fold onto itself.
pub const BEND_RADIUS: Range = Range::new(60.0, 120.0);
/// Orientation of the bending plane about the root axis, degrees (any direction).
pub const BENDING_PLANE: Range = Range::new(0.0, 360.0);
/// Relative bulge of each sinus lobe (the largest lobe is 1). The non-coronary sinus is
/// usually largest (Kunzelman et al., J Thorac Cardiovasc Surg 1994;107:162–170); lobes
/// differ by up to about a quarter.
pub const LOBE_SCALE: Range = Range::new(0.75, 1.0);
/// Rotation of the first lobe centre from the annulus major axis, degrees (one lobe period).
pub const LOBE_ROTATION: Range = Range::new(0.0, 120.0);
/// Length of the straight outflow-tract stub below the annulus, mm. A modelling choice.
pub const LVOT_LENGTH: Range = Range::new(5.0, 10.0);

/// Parameters of one parametric aortic root, in millimetres and degrees.
///
/// Frame: the annulus centre is the origin, the outflow axis is +z, the annulus major axis
/// is +x. These values are the ground truth written beside every generated mesh.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AorticRootParams {
    /// Mean annulus diameter, (major + minor)/2.
    pub annulus_diameter_mm: f64,
    /// Annulus minor/major axis ratio (1 = circle).
    pub annulus_ellipticity: f64,
    /// Twice the largest distance from the centreline to the wall in the sinus region.
    pub sinus_diameter_mm: f64,
    /// Distance along the axis from the annulus plane to the sinotubular junction.
    pub sinus_height_mm: f64,
    /// Diameter of the (circular) sinotubular junction.
    pub stj_diameter_mm: f64,
    /// Diameter of the ascending aorta after the STJ→ascending taper.
    pub ascending_diameter_mm: f64,
    /// Arc length of the curved ascending segment, starting at the STJ.
    pub ascending_length_mm: f64,
    /// Radius of the ascending centreline arc.
    pub bend_radius_mm: f64,
    /// Direction the ascending segment bends towards, degrees from +x about +z.
    pub bending_plane_deg: f64,
    /// Bulge of the three sinus lobes relative to the largest (which is exactly 1).
    pub lobe_scales: [f64; 3],
    /// Angle of the first lobe centre from +x, degrees; the others follow at +120° and +240°.
    pub lobe_rotation_deg: f64,
    /// Length of the straight outflow-tract stub below the annulus.
    pub lvot_length_mm: f64,
}

/// Why a parameter set cannot be built into a surface.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamsError {
    /// A value is NaN, infinite or not positive where it must be.
    #[error("parameter `{name}` = {value} must be a finite positive number")]
    NotPositive {
        /// Field name.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
    /// Two parameters contradict each other.
    #[error("inconsistent parameters: {0}")]
    Inconsistent(String),
}

impl AorticRootParams {
    /// Annulus major and minor diameters derived from the mean and the ratio.
    pub fn annulus_axes_mm(&self) -> (f64, f64) {
        let e = self.annulus_ellipticity;
        let major = 2.0 * self.annulus_diameter_mm / (1.0 + e);
        (major, major * e)
    }

    /// Checks that the surface is well defined: positive sizes, sinus wider than annulus
    /// and STJ, ellipticity in (0, 1], lobes in (0, 1] with a largest lobe of exactly 1,
    /// and a bend radius of at least twice the largest tube radius (no self-intersection).
    pub fn validate(&self) -> Result<(), ParamsError> {
        let positive = [
            ("annulus_diameter_mm", self.annulus_diameter_mm),
            ("annulus_ellipticity", self.annulus_ellipticity),
            ("sinus_diameter_mm", self.sinus_diameter_mm),
            ("sinus_height_mm", self.sinus_height_mm),
            ("stj_diameter_mm", self.stj_diameter_mm),
            ("ascending_diameter_mm", self.ascending_diameter_mm),
            ("ascending_length_mm", self.ascending_length_mm),
            ("bend_radius_mm", self.bend_radius_mm),
            ("lvot_length_mm", self.lvot_length_mm),
            ("lobe_scales[0]", self.lobe_scales[0]),
            ("lobe_scales[1]", self.lobe_scales[1]),
            ("lobe_scales[2]", self.lobe_scales[2]),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(ParamsError::NotPositive { name, value });
            }
        }
        for (name, value) in [
            ("bending_plane_deg", self.bending_plane_deg),
            ("lobe_rotation_deg", self.lobe_rotation_deg),
        ] {
            if !value.is_finite() {
                return Err(ParamsError::NotPositive { name, value });
            }
        }
        let inconsistent = |msg: String| Err(ParamsError::Inconsistent(msg));
        if self.annulus_ellipticity > 1.0 {
            return inconsistent(format!(
                "annulus_ellipticity {} is a minor/major ratio and cannot exceed 1",
                self.annulus_ellipticity
            ));
        }
        let max_lobe = self.lobe_scales.iter().copied().fold(0.0, f64::max);
        if max_lobe != 1.0 {
            return inconsistent(format!(
                "the largest of lobe_scales {:?} must be exactly 1",
                self.lobe_scales
            ));
        }
        let (major, _) = self.annulus_axes_mm();
        if self.sinus_diameter_mm <= major.max(self.stj_diameter_mm) {
            return inconsistent(format!(
                "sinus_diameter_mm {} must exceed the annulus major axis {major:.2} and the STJ {}",
                self.sinus_diameter_mm, self.stj_diameter_mm
            ));
        }
        let widest = 0.5 * self.stj_diameter_mm.max(self.ascending_diameter_mm);
        if self.bend_radius_mm < 2.0 * widest {
            return inconsistent(format!(
                "bend_radius_mm {} must be at least twice the ascending tube radius {widest:.2}",
                self.bend_radius_mm
            ));
        }
        Ok(())
    }
}

/// Uniform in [0, 1) from the top 53 bits: exact, platform-independent arithmetic.
fn unit<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Draws one parameter set. Deterministic for a given generator state.
pub fn sample_params<R: Rng + ?Sized>(rng: &mut R) -> AorticRootParams {
    // Bell-shaped body-size factor in [0, 1] (mean of three uniforms).
    let size = (unit(rng) + unit(rng) + unit(rng)) / 3.0;
    let mut correlated = |range: Range| range.at(0.8 * size + 0.2 * unit(rng));
    let annulus_diameter_mm = correlated(ANNULUS_DIAMETER);
    let sinus_diameter_mm = correlated(SINUS_DIAMETER);
    let sinus_height_mm = correlated(SINUS_HEIGHT);
    let stj_diameter_mm = correlated(STJ_DIAMETER);
    let ascending_diameter_mm = correlated(ASCENDING_DIAMETER);
    let ascending_length_mm = correlated(ASCENDING_LENGTH);
    let annulus_ellipticity = ANNULUS_ELLIPTICITY.at(unit(rng));
    let bend_radius_mm = BEND_RADIUS.at(unit(rng));
    let bending_plane_deg = BENDING_PLANE.at(unit(rng));
    let lobe_rotation_deg = LOBE_ROTATION.at(unit(rng));
    let lvot_length_mm = LVOT_LENGTH.at(unit(rng));
    // One lobe (chosen at random) is the largest; the other two are a little smaller.
    let largest = (rng.next_u64() % 3) as usize;
    let mut lobe_scales = [1.0; 3];
    for (k, scale) in lobe_scales.iter_mut().enumerate() {
        if k != largest {
            *scale = LOBE_SCALE.at(unit(rng));
        }
    }
    AorticRootParams {
        annulus_diameter_mm,
        annulus_ellipticity,
        sinus_diameter_mm,
        sinus_height_mm,
        stj_diameter_mm,
        ascending_diameter_mm,
        ascending_length_mm,
        bend_radius_mm,
        bending_plane_deg,
        lobe_scales,
        lobe_rotation_deg,
        lvot_length_mm,
    }
}
