//! The cubic sample grid marching cubes runs on, and why a grid or its values cannot be
//! meshed.

/// Largest accepted resolution (keeps every vertex and edge index inside 32 bits).
pub const MAX_RESOLUTION: usize = 1024;

/// A cubic sample grid: `resolution` samples per axis spread evenly over `[min, max]`,
/// sample `(i, j, k)` stored at `i + R·(j + R·k)` (x fastest).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Grid {
    /// Samples per axis (R ≥ 2).
    pub resolution: usize,
    /// Coordinate of the first sample on every axis.
    pub min: f32,
    /// Coordinate of the last sample on every axis.
    pub max: f32,
}

/// Why a grid or its values cannot be meshed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GridError {
    /// Fewer than two samples per axis, or more than [`MAX_RESOLUTION`].
    #[error("grid resolution {0} is outside 2..={MAX_RESOLUTION}")]
    Resolution(usize),
    /// The bounds are not finite or not increasing.
    #[error("grid bounds [{min}, {max}] must be finite with min < max")]
    Bounds {
        /// Given lower bound.
        min: f32,
        /// Given upper bound.
        max: f32,
    },
    /// The value slice does not hold R³ samples.
    #[error("grid of resolution {resolution} needs {expected} values, got {found}")]
    Length {
        /// The grid's resolution.
        resolution: usize,
        /// R³.
        expected: usize,
        /// Length of the given slice.
        found: usize,
    },
    /// A sample is NaN or infinite.
    #[error("sample ({i}, {j}, {k}) has the non-finite value {value}")]
    NonFinite {
        /// x index.
        i: usize,
        /// y index.
        j: usize,
        /// z index.
        k: usize,
        /// The value found.
        value: f32,
    },
    /// The iso level is NaN or infinite.
    #[error("iso level {0} is not finite")]
    Iso(f32),
}

impl Grid {
    /// R samples per axis over the unit-ball box `[-1, 1]³` used for normalised shapes.
    pub fn new(resolution: usize) -> Self {
        Self {
            resolution,
            min: -1.0,
            max: 1.0,
        }
    }

    /// Checks the resolution and the bounds.
    pub fn validate(&self) -> Result<(), GridError> {
        if !(2..=MAX_RESOLUTION).contains(&self.resolution) {
            return Err(GridError::Resolution(self.resolution));
        }
        if !(self.min.is_finite() && self.max.is_finite() && self.min < self.max) {
            return Err(GridError::Bounds {
                min: self.min,
                max: self.max,
            });
        }
        Ok(())
    }

    /// Number of samples, R³.
    pub fn sample_count(&self) -> usize {
        self.resolution.pow(3)
    }

    /// Distance between neighbouring samples.
    pub fn spacing(&self) -> f32 {
        (self.max - self.min) / (self.resolution - 1) as f32
    }

    /// Coordinate of sample index `i` on any axis (computed in f64, so the last sample is
    /// exactly `max`). Every path that samples the grid uses this, which keeps the dense and
    /// sparse extractions bit-identical.
    pub fn coordinate(&self, i: usize) -> f32 {
        let t = i as f64 / (self.resolution - 1) as f64;
        (f64::from(self.min) + t * (f64::from(self.max) - f64::from(self.min))) as f32
    }

    /// All R coordinates of one axis.
    pub fn coordinates(&self) -> Vec<f32> {
        (0..self.resolution).map(|i| self.coordinate(i)).collect()
    }

    /// Position of sample `(i, j, k)`.
    pub fn point(&self, i: usize, j: usize, k: usize) -> [f32; 3] {
        [self.coordinate(i), self.coordinate(j), self.coordinate(k)]
    }

    /// All sample positions in storage order (x fastest).
    pub fn points(&self) -> impl Iterator<Item = [f32; 3]> + '_ {
        let c = self.coordinates();
        let r = self.resolution;
        (0..self.sample_count()).map(move |n| [c[n % r], c[n / r % r], c[n / (r * r)]])
    }
}

impl Default for Grid {
    /// The paper's 256³ over `[-1, 1]³`.
    fn default() -> Self {
        Self::new(256)
    }
}
