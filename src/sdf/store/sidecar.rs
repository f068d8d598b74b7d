//! Files kept beside a model's weights after training (`anchors.json`, `refits.json`).
//!
//! Each is versioned JSON that names its format and the SHA-256 of the weights it was made
//! for, because latents fitted for one network mean nothing to another: a file for other
//! weights is refused, not used. A missing file means "none yet". Writes go to a temporary
//! name and are renamed, so a reader never sees half a file and a crash loses at most the
//! write in progress.

use std::path::Path;

use serde::Serialize;
use serde::de::DeserializeOwned;

/// One kind of sidecar file.
#[derive(Debug, Clone, Copy)]
pub struct Sidecar {
    /// File name inside the model directory.
    pub file: &'static str,
    /// Value of its `format` field.
    pub format: &'static str,
    /// The layout this build reads and writes.
    pub version: u32,
    /// What the file holds, for messages ("anchors", "refits").
    pub kind: &'static str,
}

/// Why a sidecar file cannot be read or written.
#[derive(Debug, thiserror::Error)]
pub enum SidecarError {
    /// The file cannot be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The operating-system error.
        source: std::io::Error,
    },
    /// The file breaks a rule.
    #[error("{path} is not a valid {kind} file: {reason}")]
    Invalid {
        /// The file.
        path: String,
        /// What the file holds.
        kind: &'static str,
        /// The broken rule.
        reason: String,
    },
}

/// The fields every sidecar file starts with.
#[derive(serde::Deserialize)]
struct Header {
    format: String,
    format_version: u32,
    weights_sha256: String,
}

impl Sidecar {
    /// Reads the file in `dir`: `None` when there is none; refused when it is not this
    /// kind's format and version or belongs to weights other than `weights_sha256`.
    pub fn read<T: DeserializeOwned>(
        &self,
        dir: &Path,
        weights_sha256: &str,
    ) -> Result<Option<T>, SidecarError> {
        let path = dir.join(self.file);
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => {
                return Err(SidecarError::Io {
                    path: path.display().to_string(),
                    source,
                });
            }
        };
        let invalid = |reason: String| self.invalid(dir, reason);
        let header: Header =
            serde_json::from_slice(&bytes).map_err(|e| invalid(format!("not readable: {e}")))?;
        if header.format != self.format {
            return Err(invalid(format!("\"format\" is not \"{}\"", self.format)));
        }
        if header.format_version != self.version {
            return Err(invalid(format!(
                "format version {} (this build reads {})",
                header.format_version, self.version
            )));
        }
        if header.weights_sha256 != weights_sha256 {
            return Err(invalid(
                "it belongs to other weights (weights_sha256 differs from the manifest)".into(),
            ));
        }
        serde_json::from_slice(&bytes)
            .map(Some)
            .map_err(|e| invalid(format!("not readable: {e}")))
    }

    /// The error for a file in `dir` whose content breaks `reason`.
    pub fn invalid(&self, dir: &Path, reason: String) -> SidecarError {
        SidecarError::Invalid {
            path: dir.join(self.file).display().to_string(),
            kind: self.kind,
            reason,
        }
    }

    /// Writes `value` as the file in `dir` (temporary file, then rename).
    pub fn write<T: Serialize>(&self, dir: &Path, value: &T) -> Result<(), SidecarError> {
        let path = dir.join(self.file);
        let tmp = dir.join(format!(".{}.tmp", self.file));
        let io = |source| SidecarError::Io {
            path: path.display().to_string(),
            source,
        };
        let json = serde_json::to_vec_pretty(value).map_err(|e| io(std::io::Error::other(e)))?;
        std::fs::write(&tmp, json).map_err(io)?;
        std::fs::rename(&tmp, &path).map_err(io)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOTES: Sidecar = Sidecar {
        file: "notes.json",
        format: "aortagen-notes",
        version: 2,
        kind: "notes",
    };

    #[derive(Debug, PartialEq, Serialize, serde::Deserialize)]
    struct Notes {
        format: String,
        format_version: u32,
        weights_sha256: String,
        items: Vec<u32>,
    }

    fn notes(format: &str, version: u32, sha: &str) -> Notes {
        Notes {
            format: format.into(),
            format_version: version,
            weights_sha256: sha.into(),
            items: vec![3, 1],
        }
    }

    #[test]
    fn a_missing_file_is_none_and_a_written_one_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(NOTES.read::<Notes>(dir.path(), "aa").unwrap(), None);
        let written = notes("aortagen-notes", 2, "aa");
        NOTES.write(dir.path(), &written).unwrap();
        assert_eq!(NOTES.read(dir.path(), "aa").unwrap(), Some(written));
        assert!(!dir.path().join(".notes.json.tmp").exists());
    }

    #[test]
    fn a_file_of_another_format_version_or_model_is_refused_naming_the_rule() {
        let dir = tempfile::tempdir().unwrap();
        let cases = [
            (notes("aortagen-anchors", 2, "aa"), "\"format\" is not"),
            (notes("aortagen-notes", 1, "aa"), "format version 1"),
            (notes("aortagen-notes", 2, "bb"), "other weights"),
        ];
        for (file, rule) in cases {
            NOTES.write(dir.path(), &file).unwrap();
            let err = NOTES.read::<Notes>(dir.path(), "aa").unwrap_err();
            let text = err.to_string();
            assert!(text.contains("not a valid notes file"), "{text}");
            assert!(text.contains(rule), "{text}");
        }
        std::fs::write(dir.path().join("notes.json"), b"{\"format\": 1}").unwrap();
        let err = NOTES.read::<Notes>(dir.path(), "aa").unwrap_err();
        assert!(err.to_string().contains("not readable"), "{err}");
        // A right header over a wrong body is refused too.
        std::fs::write(
            dir.path().join("notes.json"),
            br#"{"format":"aortagen-notes","format_version":2,"weights_sha256":"aa","items":"x"}"#,
        )
        .unwrap();
        let err = NOTES.read::<Notes>(dir.path(), "aa").unwrap_err();
        assert!(err.to_string().contains("not readable"), "{err}");
    }
}
