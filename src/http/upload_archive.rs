//! Zip archives of training meshes (`POST /v1/models`): the members are returned as named
//! files for the usual mesh validation. Archives are untrusted: the entry count and the
//! total uncompressed size are bounded while reading (declared sizes can lie), paths that
//! would leave the archive are refused, and directories and macOS metadata are skipped.

use std::io::Read;

use super::error::ApiError;

/// Bounds on one archive.
#[derive(Debug, Clone, Copy)]
pub struct ArchiveLimits {
    /// Most entries (directories included).
    pub entries: usize,
    /// Most bytes after decompression, over all members.
    pub bytes: usize,
}

/// Whether `name` or the first bytes say "zip".
pub fn looks_like_zip(name: Option<&str>, bytes: &[u8]) -> bool {
    name.is_some_and(|n| n.to_ascii_lowercase().ends_with(".zip"))
        || bytes.starts_with(b"PK\x03\x04")
}

/// The mesh files in the archive `archive` (named for messages), as `(name, bytes)` with
/// names `<archive>/<member path>`.
pub fn unpack(
    archive: &str,
    bytes: &[u8],
    limits: ArchiveLimits,
) -> Result<Vec<(String, Vec<u8>)>, ApiError> {
    let field = format!("files[{archive}]");
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(|e| {
        ApiError::invalid(
            &field,
            "zip",
            format!("{archive} is not a readable zip archive: {e}"),
        )
    })?;
    if zip.len() > limits.entries {
        return Err(ApiError::ArchiveTooLarge(format!(
            "{archive} has {} entries; at most {} are accepted",
            zip.len(),
            limits.entries
        )));
    }
    let mut files = Vec::new();
    let mut total = 0usize;
    for i in 0..zip.len() {
        let mut entry = zip.by_index(i).map_err(|e| {
            ApiError::invalid(
                &field,
                "zip",
                format!("{archive}: entry {i} is unreadable: {e}"),
            )
        })?;
        let raw_name = entry
            .name()
            .map_err(|e| {
                ApiError::invalid(
                    &field,
                    "zip",
                    format!("{archive}: entry {i} has no readable name: {e}"),
                )
            })?
            .into_owned();
        let member = format!("{archive}/{raw_name}");
        let Some(path) = entry.enclosed_name() else {
            return Err(ApiError::invalid(
                format!("files[{member}]"),
                "path",
                format!("{member}: the path leaves the archive"),
            ));
        };
        if entry.is_dir() || is_metadata(&path) {
            continue;
        }
        let room = limits.bytes - total;
        let mut content = Vec::new();
        let read = (&mut entry)
            .take(room as u64 + 1)
            .read_to_end(&mut content)
            .map_err(|e| {
                ApiError::invalid(
                    format!("files[{member}]"),
                    "zip",
                    format!("{member}: cannot decompress: {e}"),
                )
            })?;
        if read > room {
            return Err(ApiError::ArchiveTooLarge(format!(
                "{archive} expands to more than {} bytes",
                limits.bytes
            )));
        }
        total += read;
        files.push((member, content));
    }
    Ok(files)
}

/// macOS resource forks and Finder files that archivers add next to the real files.
fn is_metadata(path: &std::path::Path) -> bool {
    let in_macosx = path.components().any(|c| c.as_os_str() == "__MACOSX");
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    in_macosx || name.starts_with("._") || name == ".DS_Store"
}
