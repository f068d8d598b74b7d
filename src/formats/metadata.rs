//! What a written mesh says about itself (units, generator, frame, sign convention,
//! provenance), and how a units statement is found again in a file's comments.

/// The coordinate frame recorded with every written mesh.
pub const COORDINATE_FRAME_NOTE: &str = "right-handed x, y, z: the source data's own frame \
    and origin, or the model's unit-ball frame (centred, radius 1) when the unit is 'unit'";

/// The sign convention recorded with every written mesh.
pub const SIGN_CONVENTION_NOTE: &str = "signed distance f < 0 inside, f > 0 outside; \
    triangles counter-clockwise seen from outside (outward normals)";

/// What a written mesh says about itself: units, the software that made it and any
/// provenance (model id, weights, seed, ...) as free JSON.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MeshMetadata {
    /// Length unit of the coordinates: "mm" for shapes in their own units, "unit" for
    /// unit-ball coordinates.
    pub units: String,
    /// Software and version, e.g. "aortagen 0.1.0".
    pub generator: String,
    /// Provenance or any other JSON; `null` when there is nothing to record.
    pub extras: serde_json::Value,
}

impl MeshMetadata {
    /// Metadata with the given units, this software as generator and no extras.
    pub fn new(units: impl Into<String>) -> Self {
        Self {
            units: units.into(),
            generator: format!("aortagen {}", crate::VERSION),
            extras: serde_json::Value::Null,
        }
    }

    /// The JSON object stored in glTF `extras` and, compactly, in text comments.
    pub fn to_json(&self) -> serde_json::Value {
        let mut obj = serde_json::json!({
            "units": self.units,
            "generator": self.generator,
            "coordinate_frame": COORDINATE_FRAME_NOTE,
            "sign_convention": SIGN_CONVENTION_NOTE,
        });
        if !self.extras.is_null() {
            obj["provenance"] = self.extras.clone();
        }
        obj
    }

    /// Comment lines for text-capable formats (OBJ `#`, PLY `comment`); the units line
    /// comes first so that readers (ours included) find it.
    pub(crate) fn comment_lines(&self) -> Vec<String> {
        let mut lines = vec![
            format!("units {}", self.units),
            format!("generator {}", self.generator),
            format!("coordinate frame: {COORDINATE_FRAME_NOTE}"),
            format!("sign convention: {SIGN_CONVENTION_NOTE}"),
        ];
        if !self.extras.is_null() {
            lines.push(format!("provenance {}", self.extras));
        }
        // One comment per line, whatever the strings hold.
        lines
            .into_iter()
            .map(|l| l.replace(['\n', '\r'], " "))
            .collect()
    }
}

impl Default for MeshMetadata {
    /// Unit-ball coordinates, this software, no provenance.
    fn default() -> Self {
        Self::new("unit")
    }
}

/// Finds a units statement such as "units mm", "units: mm" or "units=mm" in free text.
pub(crate) fn units_in(text: &str) -> Option<String> {
    let lower = text.to_ascii_lowercase();
    let mut from = 0;
    while let Some(pos) = lower[from..].find("units") {
        let start = from + pos;
        let end = start + "units".len();
        from = end;
        let word_start = start == 0 || !lower.as_bytes()[start - 1].is_ascii_alphanumeric();
        let rest = &text[end..];
        let separated = rest.starts_with([':', '=', ' ', '\t']);
        if !word_start || !separated {
            continue;
        }
        let value: String = rest
            .trim_start_matches([':', '=', ' ', '\t'])
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        if !value.is_empty() {
            return Some(value);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_are_found_in_the_usual_spellings() {
        assert_eq!(
            units_in("SynthAorta surface, units mm").as_deref(),
            Some("mm")
        );
        assert_eq!(units_in("UNITS: m").as_deref(), Some("m"));
        assert_eq!(units_in("units=unit").as_deref(), Some("unit"));
        assert_eq!(units_in("one unit is 105 mm"), None);
        assert_eq!(units_in("subunits mm"), None);
        assert_eq!(units_in("units"), None);
    }
}
