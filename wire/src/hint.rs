//! The operator hint (`hint.json`): the target facet's outline in both views, as an operator
//! clicks it, and the block's extent behind the facet. It is part of the contract between an
//! operator tool (the simulator writes one; a person or `handeye hint` may too) and the
//! daemon, which reads it once at start-up.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// Version of the hint file format this crate reads and writes.
pub const HINT_VERSION: u32 = 1;

/// `hint.json`, version [`HINT_VERSION`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OperatorHint {
    /// Format version, [`HINT_VERSION`].
    pub version: u32,
    /// Facet corners in the left image, pixels (pixel centres at integers), in order around
    /// it (3..=8).
    pub left_px: Vec<[f64; 2]>,
    /// The same physical corners, same order, in the right image.
    pub right_px: Vec<[f64; 2]>,
    /// Extent of the object behind the facet along its normal (the grasp width), mm.
    pub depth_mm: f64,
    /// Free text: where the hint came from.
    #[serde(default)]
    pub note: String,
}

#[derive(Debug, thiserror::Error)]
pub enum HintError {
    #[error("{file}: cannot read: {source}")]
    Read { file: PathBuf, source: std::io::Error },
    #[error("{file}: {message}")]
    Parse { file: PathBuf, message: String },
    #[error("{file}: {field}: {message}")]
    Invalid { file: PathBuf, field: &'static str, message: String },
}

impl OperatorHint {
    pub fn load(path: &Path) -> Result<Self, HintError> {
        let text = std::fs::read_to_string(path).map_err(|source| HintError::Read { file: path.to_path_buf(), source })?;
        Self::parse(&text, path)
    }

    pub fn parse(text: &str, file: &Path) -> Result<Self, HintError> {
        let hint: Self = serde_json::from_str(text).map_err(|e| HintError::Parse { file: file.to_path_buf(), message: e.to_string() })?;
        let bad = |field, message: String| Err(HintError::Invalid { file: file.to_path_buf(), field, message });
        if hint.version != HINT_VERSION {
            return bad("version", format!("{} (this daemon reads version 1)", hint.version));
        }
        if !(3..=8).contains(&hint.left_px.len()) {
            return bad("left_px", format!("{} corners (3..=8 expected)", hint.left_px.len()));
        }
        if hint.right_px.len() != hint.left_px.len() {
            return bad("right_px", format!("{} corners, but left_px has {}", hint.right_px.len(), hint.left_px.len()));
        }
        if hint.left_px.iter().chain(&hint.right_px).flatten().any(|v| !v.is_finite()) {
            return bad("left_px", "a corner is not a finite number".into());
        }
        if !(hint.depth_mm.is_finite() && hint.depth_mm > 0.0) {
            return bad("depth_mm", format!("{} (a positive number of millimetres expected)", hint.depth_mm));
        }
        Ok(hint)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checks_fields_and_names_them() {
        let ok = r#"{"version":1,"left_px":[[1,2],[3,4],[5,7]],"right_px":[[1,2],[3,4],[5,7]],"depth_mm":40}"#;
        assert_eq!(OperatorHint::parse(ok, Path::new("h.json")).unwrap().depth_mm, 40.0);
        for (text, field) in [
            (r#"{"version":1,"left_px":[[1,2],[3,4]],"right_px":[[1,2],[3,4]],"depth_mm":40}"#, "left_px"),
            (r#"{"version":1,"left_px":[[1,2],[3,4],[5,7]],"right_px":[[1,2],[3,4]],"depth_mm":40}"#, "right_px"),
            (r#"{"version":1,"left_px":[[1,2],[3,4],[5,7]],"right_px":[[1,2],[3,4],[5,7]],"depth_mm":-1}"#, "depth_mm"),
            (r#"{"version":2,"left_px":[[1,2],[3,4],[5,7]],"right_px":[[1,2],[3,4],[5,7]],"depth_mm":4}"#, "version"),
            (r#"{"version":1,"left_px":[[1,2],[3,4],[5,7]],"right_px":[[1,2],[3,4],[5,7]],"depht_mm":4}"#, "depht_mm"),
        ] {
            let err = OperatorHint::parse(text, Path::new("h.json")).unwrap_err().to_string();
            assert!(err.contains("h.json") && err.contains(field), "{err}");
        }
    }
}
