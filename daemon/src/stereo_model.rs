//! `stereo_model.json`: the affine stereo model of a camera pair (METHOD.md §1, `w = M X +
//! c`), as the working daemon fits it in calibration and writes it into its report folder.
//! Observe mode ([`crate::observe`]) reads it (`--stereo-model`) to check that the two views' tracks are the same
//! facet: their corners must satisfy the model's epipolar constraint.

use std::path::{Path, PathBuf};

use handeye_vision::affine::{AffineStereo, EpipolarConstraint};
use nalgebra::{Matrix4x3, Vector4};
use serde::{Deserialize, Serialize};

/// Version of the file format.
pub const STEREO_MODEL_VERSION: u32 = 1;

/// `stereo_model.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StereoModelFile {
    pub version: u32,
    /// Rows `u`, `v`, `u'`, `v'` as linear functions of robot coordinates, px per m.
    pub m_px_per_m: [[f64; 3]; 4],
    /// Image coordinates of the robot origin, px.
    pub c_px: [f64; 4],
    /// The fit's RMS residual, px.
    pub residual_rms_px: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum StereoModelError {
    #[error("{file}: cannot read: {source}")]
    Read { file: PathBuf, source: std::io::Error },
    #[error("{file}: {message}")]
    Parse { file: PathBuf, message: String },
    #[error("{file}: {field}: {message}")]
    Invalid { file: PathBuf, field: &'static str, message: String },
}

impl StereoModelFile {
    pub fn from_model(model: &AffineStereo) -> Self {
        let mut m = [[0.0; 3]; 4];
        for (r, row) in m.iter_mut().enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                *v = model.m[(r, c)];
            }
        }
        Self { version: STEREO_MODEL_VERSION, m_px_per_m: m, c_px: [model.c[0], model.c[1], model.c[2], model.c[3]], residual_rms_px: model.residual_rms_px }
    }

    pub fn load(path: &Path) -> Result<Self, StereoModelError> {
        let text = std::fs::read_to_string(path).map_err(|source| StereoModelError::Read { file: path.to_path_buf(), source })?;
        let f: Self = serde_json::from_str(&text).map_err(|e| StereoModelError::Parse { file: path.to_path_buf(), message: e.to_string() })?;
        let bad = |field, message: String| Err(StereoModelError::Invalid { file: path.to_path_buf(), field, message });
        if f.version != STEREO_MODEL_VERSION {
            return bad("version", format!("{} (version {STEREO_MODEL_VERSION} expected)", f.version));
        }
        if f.m_px_per_m.iter().flatten().chain(&f.c_px).any(|v| !v.is_finite()) {
            return bad("m_px_per_m", "a value is not a finite number".into());
        }
        Ok(f)
    }

    /// The model's epipolar constraint.
    pub fn epipolar(&self) -> EpipolarConstraint {
        let m = Matrix4x3::from_fn(|r, c| self.m_px_per_m[r][c]);
        let model = AffineStereo { m, c: Vector4::from(self.c_px), residual_rms_px: self.residual_rms_px, disparity_range_px: [0.0, 0.0] };
        model.epipolar()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_written_model_reads_back_with_the_same_constraint_and_bad_files_name_the_field() {
        let m = Matrix4x3::new(900.0, 10.0, -20.0, 5.0, -30.0, -880.0, 870.0, 200.0, -25.0, 8.0, -28.0, -885.0);
        let model = AffineStereo { m, c: Vector4::new(320.0, 240.0, 300.0, 242.0), residual_rms_px: 0.3, disparity_range_px: [0.0, 0.0] };
        let dir = std::env::temp_dir().join(format!("stereo-model-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("stereo_model.json");
        std::fs::write(&path, serde_json::to_string(&StereoModelFile::from_model(&model)).unwrap()).unwrap();
        let back = StereoModelFile::load(&path).unwrap();
        let p = nalgebra::Vector3::new(0.1, -0.05, 0.2);
        let w = model.m * p + model.c;
        assert!(back.epipolar().residual_px(&[w[0], w[1], w[2], w[3]]).abs() < 1e-9);
        std::fs::write(&path, r#"{"version":2,"m_px_per_m":[[0,0,0],[0,0,0],[0,0,0],[0,0,0]],"c_px":[0,0,0,0],"residual_rms_px":0}"#).unwrap();
        let err = StereoModelFile::load(&path).unwrap_err().to_string();
        assert!(err.contains("stereo_model.json") && err.contains("version"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
