//! Reading a scenario file: TOML into the [`Scenario`] types, then the semantic checks,
//! every failure located in the file.
//!
//! Every table rejects unknown keys and every required key must be present; errors name the
//! file, the line and column, and the field path (`blocks[1].size_mm`), e.g.
//!
//! ```text
//! scenarios/bad.toml:14:1: blocks[0]: unknown field `colour`, expected one of `name`, `kind`, ...
//! ```

use std::path::Path;

use toml::de::DeTable;

use super::config::Scenario;
use super::error::ScenarioError;
use super::locate::{error_at, path_at, path_string, span_of};

impl Scenario {
    /// Reads and validates a scenario file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, ScenarioError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| ScenarioError {
            file: path.to_path_buf(),
            line: 0,
            column: 0,
            field: "(file)".into(),
            message: format!("cannot read: {e}"),
        })?;
        Self::parse(&text, path)
    }

    /// Parses and validates scenario text; `file` is used in error messages only.
    ///
    /// ```
    /// let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenarios/pick_cube.toml")).unwrap();
    /// let bad = text.replace("seed =", "sead =");
    /// let err = handeye_sim::scenario::Scenario::parse(&bad, "pick_cube.toml".as_ref()).unwrap_err();
    /// assert!(err.to_string().contains("sead"), "{err}");
    /// ```
    pub fn parse(text: &str, file: &Path) -> Result<Self, ScenarioError> {
        let doc = DeTable::parse(text).map_err(|e| error_at(file, text, None, e.span(), e.message()))?;
        let scenario: Scenario = toml::from_str(text).map_err(|e| {
            let field = e.span().map(|s| path_at(&doc, s.start)).unwrap_or_default();
            error_at(file, text, Some(field), e.span(), e.message())
        })?;
        scenario.validate().map_err(|(path, message)| {
            let span = span_of(&doc, &path);
            error_at(file, text, Some(path_string(&path)), span, &message)
        })?;
        Ok(scenario)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PICK_CUBE: &str = include_str!("../../../scenarios/pick_cube.toml");

    fn parse(text: &str) -> Result<Scenario, ScenarioError> {
        Scenario::parse(text, Path::new("test.toml"))
    }

    fn line_of(text: &str, needle: &str) -> usize {
        text.lines().position(|l| l.contains(needle)).expect("needle in text") + 1
    }

    #[test]
    fn shipped_scenario_parses() {
        let s = parse(PICK_CUBE).unwrap();
        assert_eq!(s.cameras.len(), 2);
        assert_eq!(s.substeps_per_frame(), 8);
        assert_eq!(s.blocks[s.target_index()].name, "cube");
    }

    #[test]
    fn unknown_field_names_field_and_line() {
        let text = PICK_CUBE.replace("yaw_deg = 25.0", "yaw_deg = 25.0\ncolour = 3");
        let e = parse(&text).unwrap_err();
        assert!(e.message.contains("colour"), "{e}");
        assert_eq!(e.line, line_of(&text, "colour"), "{e}");
        assert!(e.field.starts_with("blocks[0]"), "{e}");
    }

    #[test]
    fn missing_field_is_named() {
        let text = PICK_CUBE.replace("rate_hz = 240", "");
        let e = parse(&text).unwrap_err();
        assert!(e.message.contains("rate_hz"), "{e}");
        assert!(e.to_string().starts_with("test.toml:"), "{e}");
    }

    #[test]
    fn wrong_type_names_field_path_and_line() {
        let text = PICK_CUBE.replace("focal_px = 1800.0\nresolution = [640, 480]\nnoise_sigma = 1.5\nblur_sigma_px = 0.0\n\n[[blocks]]",
            "focal_px = 1800.0\nresolution = [640, \"480\"]\nnoise_sigma = 1.5\nblur_sigma_px = 0.0\n\n[[blocks]]");
        assert_ne!(text, PICK_CUBE);
        let e = parse(&text).unwrap_err();
        assert_eq!(e.line, line_of(&text, "\"480\""), "{e}");
        assert!(e.field.contains("cameras[1].resolution"), "{e}");
    }

    #[test]
    fn out_of_range_value_points_at_its_key() {
        let text = PICK_CUBE.replace("size_mm = [40.0, 40.0, 40.0]", "size_mm = [40.0, 40.0, 80.0]");
        let e = parse(&text).unwrap_err();
        assert_eq!(e.field, "blocks[0].size_mm", "{e}");
        assert_eq!(e.line, line_of(&text, "size_mm"), "{e}");
        assert!(e.message.contains("20..60"), "{e}");
    }

    #[test]
    fn dangling_reference_and_bad_event_are_reported() {
        let text = PICK_CUBE.replace("target = \"cube\"", "target = \"sphere\"");
        let e = parse(&text).unwrap_err();
        assert_eq!(e.field, "task.target");
        assert!(e.message.contains("sphere"));

        let ev = format!("{PICK_CUBE}\n[[events]]\nat_s = 3.0\nkind = \"camera_bump\"\ncamera = \"middle\"\n");
        let e = parse(&ev).unwrap_err();
        assert_eq!(e.field, "events[0].camera", "{e}");
        assert_eq!(e.line, line_of(&ev, "\"middle\""), "{e}");

        let ev = format!("{PICK_CUBE}\n[[events]]\nat_s = 3.0\nkind = \"camera_bump\"\ncamera = \"left\"\nrotation = [1, 2, 3]\n");
        let e = parse(&ev).unwrap_err();
        assert!(e.message.contains("rotation"), "{e}");
        assert_eq!(e.line, line_of(&ev, "at_s = 3.0") - 1, "{e}");

        let ev = format!("{PICK_CUBE}\n[[events]]\nat_s = 3.0\nkind = \"earthquake\"\n");
        let e = parse(&ev).unwrap_err();
        assert!(e.message.contains("earthquake"), "{e}");
    }

    #[test]
    fn syntax_error_has_a_line() {
        let text = PICK_CUBE.replace("seed = 1", "seed = = 1");
        let e = parse(&text).unwrap_err();
        assert_eq!(e.line, line_of(&text, "seed = = 1"), "{e}");
    }

    #[test]
    fn camera_count_and_focal_rules() {
        let one_cam = PICK_CUBE.split("[[cameras]]\nname = \"right\"").next().unwrap().to_string()
            + &PICK_CUBE[PICK_CUBE.find("[[blocks]]").unwrap()..];
        let e = parse(&one_cam).unwrap_err();
        assert_eq!(e.field, "cameras");
        let both = PICK_CUBE.replacen("focal_px = 1800.0", "focal_px = 1800.0\nvfov_deg = 20.0", 1);
        let e = parse(&both).unwrap_err();
        assert_eq!(e.field, "cameras[0]", "{e}");
    }
}
