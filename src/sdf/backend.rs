//! The one place where the compute backend and its device are chosen.
//!
//! burn 0.22 has no backend type parameter: every tensor carries a run-time [`Device`]. The
//! project supports two pure-Rust CPU backends, selected by [`Backend`] (a CLI / config value)
//! and turned into a device only by [`Backend::device`], so switching backends (or adding a GPU
//! one later) is an edit to this file alone.

use std::fmt;
use std::str::FromStr;

use burn::tensor::Device;

/// A compute backend that can run the SDF network.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// burn's Flex backend (gemm matrix kernels with AVX-512 when the CPU has it): the fastest
    /// on the reference machine for training and inference, hence the default.
    #[default]
    Flex,
    /// burn's NdArray backend (matrixmultiply kernels); deprecated upstream, kept to compare
    /// and as a fallback.
    NdArray,
}

/// Why a backend cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BackendError {
    /// The backend's cargo feature was not enabled when this binary was built.
    #[error("backend `{0}` is not compiled into this binary (enable the cargo feature `{0}`)")]
    NotCompiled(Backend),
    /// The name does not denote a known backend.
    #[error("unknown backend `{0}`: expected `flex` or `ndarray`")]
    Unknown(String),
}

impl Backend {
    /// Every backend, compiled in or not.
    pub const ALL: [Backend; 2] = [Backend::Flex, Backend::NdArray];

    /// The lower-case name used on the command line and in manifests.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Flex => "flex",
            Backend::NdArray => "ndarray",
        }
    }

    /// Whether this binary was built with the backend.
    pub fn is_compiled(self) -> bool {
        match self {
            Backend::Flex => cfg!(feature = "flex"),
            Backend::NdArray => cfg!(feature = "ndarray"),
        }
    }

    /// The device for this backend: with autodiff for training (`autodiff = true`), plain for
    /// inference. Float tensors use the backend's default dtype (f32).
    pub fn device(self, autodiff: bool) -> Result<Device, BackendError> {
        let device = match self {
            #[cfg(feature = "flex")]
            Backend::Flex => Device::flex(),
            #[cfg(feature = "ndarray")]
            #[allow(deprecated)] // kept deliberately as the comparison backend
            Backend::NdArray => Device::ndarray(),
            #[allow(unreachable_patterns)]
            other => return Err(BackendError::NotCompiled(other)),
        };
        Ok(if autodiff { device.autodiff() } else { device })
    }
}

impl fmt::Display for Backend {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Backend {
    type Err = BackendError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Backend::ALL
            .into_iter()
            .find(|b| b.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| BackendError::Unknown(s.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_names_are_rejected() {
        for b in Backend::ALL {
            assert_eq!(b.name().parse::<Backend>(), Ok(b));
        }
        assert_eq!("NdArray".parse::<Backend>(), Ok(Backend::NdArray));
        assert!(matches!("cuda".parse::<Backend>(), Err(BackendError::Unknown(s)) if s == "cuda"));
    }

    #[test]
    fn compiled_backends_give_devices_with_and_without_autodiff() {
        for b in Backend::ALL.into_iter().filter(|b| b.is_compiled()) {
            assert!(b.device(true).unwrap().is_autodiff());
            assert!(!b.device(false).unwrap().is_autodiff());
        }
    }
}
