//! Zip archives of training meshes (`POST /v1/models`): the members are returned as named
//! files for the usual mesh validation. Archives are untrusted: the entry count per archive
//! and the uncompressed size of all archives of one request together are bounded while
//! reading (declared sizes can lie; a bound per archive would let one request hold as many
//! times the bound in memory as it sends archives), paths that would leave the archive are
//! refused, and directories and macOS metadata are skipped.

use std::io::Read;

use super::error::ApiError;

/// Bounds on the archives of one request.
#[derive(Debug, Clone, Copy)]
pub struct ArchiveLimits {
    /// Most entries of one archive (directories included).
    pub entries: usize,
    /// Most bytes after decompression, over all members of all the request's archives.
    pub bytes: usize,
}

/// The archives of one request unpacked so far: their members and how many bytes they
/// expanded to, which the next archive's members count on.
#[derive(Debug, Default)]
pub struct Unpacked {
    /// `(name, bytes)` with names `<archive>/<member path>`.
    pub files: Vec<(String, Vec<u8>)>,
    /// Bytes after decompression so far.
    pub expanded: usize,
}

/// Whether `name` or the first bytes say "zip".
pub fn looks_like_zip(name: Option<&str>, bytes: &[u8]) -> bool {
    name.is_some_and(|n| n.to_ascii_lowercase().ends_with(".zip"))
        || bytes.starts_with(b"PK\x03\x04")
}

/// Adds the mesh files of the archive `archive` (named for messages) to `unpacked`, within
/// what the request's earlier archives left of `limits.bytes`.
pub fn unpack(
    archive: &str,
    bytes: &[u8],
    limits: ArchiveLimits,
    unpacked: &mut Unpacked,
) -> Result<(), ApiError> {
    let mut zip = open(archive, bytes, limits)?;
    let field = format!("files[{archive}]");
    let earlier = unpacked.expanded;
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
        let room = limits.bytes - unpacked.expanded;
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
            let what = if earlier > 0 {
                format!("{archive} and the archives before it expand")
            } else {
                format!("{archive} expands")
            };
            return Err(ApiError::ArchiveTooLarge(format!(
                "{what} to more than {} bytes, the bound on all archives of one request",
                limits.bytes
            )));
        }
        unpacked.expanded += read;
        unpacked.files.push((member, content));
    }
    Ok(())
}

/// How many mesh files `unpack` would return, read from the archive's directory without
/// decompressing anything (to refuse an archive holding the wrong number of files first).
pub fn count_files(archive: &str, bytes: &[u8], limits: ArchiveLimits) -> Result<usize, ApiError> {
    let zip = open(archive, bytes, limits)?;
    Ok(zip
        .file_names()
        .filter(|name| match name {
            Ok(name) => !name.ends_with('/') && !is_metadata(std::path::Path::new(name.as_ref())),
            // `unpack` refuses it, naming the archive; counted so a count rule cannot hide that.
            Err(_) => true,
        })
        .count())
}

/// Opens an archive, refusing one that is unreadable or has too many entries.
fn open<'a>(
    archive: &str,
    bytes: &'a [u8],
    limits: ArchiveLimits,
) -> Result<zip::ZipArchive<std::io::Cursor<&'a [u8]>>, ApiError> {
    let zip = zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(|e| {
        ApiError::invalid(
            format!("files[{archive}]"),
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
    Ok(zip)
}

/// macOS resource forks and Finder files that archivers add next to the real files.
fn is_metadata(path: &std::path::Path) -> bool {
    let in_macosx = path.components().any(|c| c.as_os_str() == "__MACOSX");
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    in_macosx || name.starts_with("._") || name == ".DS_Store"
}
