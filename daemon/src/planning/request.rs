//! A plan request from the daemon's configuration. The plan phase builds its request here,
//! and `handeye plan --run DIR` rebuilds the same request from a run's report (its
//! `daemon.toml`, `plan.json` and the saved pair), so that a replay plans exactly as the
//! daemon did and a planner change can be tried on a failing run's pair in seconds.

use handeye_vision::affine::AffineStereo;
use handeye_vision::grasp::{GraspConfig, GripperModel};
use handeye_vision::image::ImageBuf;
use handeye_vision::planner::PlannerConfig;
use nalgebra::{Matrix4x3, Vector3, Vector4};

use super::{PlanCalibration, PlanRequest, PlanSummary, SceneLimits, PLANNER_FROM_TRACKER_PX};
use crate::config::DaemonConfig;

/// Why a run's report cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error("plan.json has no `{0}`: the report was written before the plan kept its whole geometry (cage, lever, model); rerun the seed to get one")]
    Missing(&'static str),
    #[error("plan.json: `model` is not an affine model ({0})")]
    Model(String),
}

/// Everything the phase knows at the plan besides the configuration.
pub struct PlanMoment {
    pub images: [ImageBuf; 2],
    pub calibration: PlanCalibration,
    /// The gripper's image region in each view, tracker pixels.
    pub masks: [Vec<[f64; 2]>; 2],
    pub indicated_m: Option<[f64; 3]>,
    /// Its one-sigma radius, m (0: given as a coordinate).
    pub indicated_sigma_m: f64,
    /// Features entirely above this height are the arm, m.
    pub max_height_m: f64,
}

/// The request the plan phase hands the worker, from the configuration and the moment.
pub fn plan_request(cfg: &DaemonConfig, moment: PlanMoment) -> PlanRequest {
    let p = &cfg.plan;
    let mut planner = PlannerConfig::default();
    planner.matching.epipolar_tol_px = p.stereo.epipolar_tol_px;
    let grasp = GraspConfig {
        gripper: GripperModel {
            finger_thickness_m: p.grasp.finger_thickness_m,
            finger_breadth_m: p.grasp.finger_breadth_m,
            jaw_opening_m: Some(cfg.gripper.max_opening_m.max(cfg.gripper.max_grasp_width_m)),
            max_width_m: cfg.gripper.max_grasp_width_m,
            ..GripperModel::default()
        },
        max_view_angle_rad: p.grasp.max_view_angle_deg.min(90.0).to_radians(),
        parallel_tolerance_rad: p.grasp.parallel_tolerance_deg.min(45.0).to_radians(),
        object_tolerance_m: p.grasp.object_tolerance_m,
        ..GraspConfig::default()
    };
    PlanRequest {
        images: moment.images,
        calibration: moment.calibration,
        masks: moment.masks,
        mask_margin_px: p.mask.mask_margin_px,
        scene: SceneLimits {
            indicated_m: moment.indicated_m,
            indicated_sigma_m: moment.indicated_sigma_m,
            ambiguity_sigmas: p.grasp.point_ambiguity_sigmas,
            max_height_m: moment.max_height_m,
            max_distance_m: p.grasp.max_site_distance_m,
            join_m: p.scene.join_m,
            table_z_m: cfg.grasp.table_z_m,
            front_faces_to_table_z_m: p.scene.hypothesise_front_faces.then_some(cfg.grasp.table_z_m),
            rear_edges_from_image: p.scene.rear_edges_from_image,
        },
        planner,
        grasp,
        disparity_margin: p.stereo.disparity_margin,
        disparity_margin_px: p.stereo.disparity_margin_px,
    }
}

/// The request a run's plan was made from: its configuration, its `plan.json` and the pair
/// it saved (`plan_left.png`, `plan_right.png`, masked already; masking again changes
/// nothing: the fill's boundary is the same pixels).
pub fn replay_request(cfg: &DaemonConfig, summary: &PlanSummary, images: [ImageBuf; 2]) -> Result<PlanRequest, ReplayError> {
    let inputs = &summary.inputs;
    let lever_m = inputs.lever_m.ok_or(ReplayError::Missing("lever_m"))?;
    if inputs.cage_robot_m.is_empty() {
        return Err(ReplayError::Missing("cage_robot_m"));
    }
    let scene_model = summary.geometry.model.as_ref().ok_or(ReplayError::Missing("model"))?;
    let model = tracker_model(&affine_from_json(scene_model)?, &lever_m);
    // Reports written before the height was kept: the parked tool's height from the
    // configuration, else the cage's top (the calibration returns the arm to where it started,
    // above the blocks).
    let park_z = [&cfg.plan.park_m, &cfg.calibration.park_m].into_iter().find(|p| p.len() == 3).map(|p| p[2]);
    let cage_top = inputs.cage_robot_m.iter().map(|p| p[2]).fold(f64::NEG_INFINITY, f64::max);
    let max_height_m = inputs.max_height_m.unwrap_or_else(|| park_z.unwrap_or(cage_top) - cfg.plan.scene.arm_clearance_m);
    let moment = PlanMoment {
        images,
        calibration: PlanCalibration {
            model,
            cage_robot_m: inputs.cage_robot_m.iter().map(|p| Vector3::from(*p)).collect(),
            cage_image_px: inputs.cage_image_px.clone(),
            lever_m,
        },
        masks: inputs.masks_px.clone(),
        indicated_m: inputs.indicated_m,
        indicated_sigma_m: inputs.indicated_sigma_m.unwrap_or(0.0),
        max_height_m,
    };
    Ok(plan_request(cfg, moment))
}

/// The calibration's own model (tool positions to tracker pixels) from the scene model the
/// plan used (`super::scene_model`'s inverse).
fn tracker_model(scene: &AffineStereo, lever_m: &[f64; 3]) -> AffineStereo {
    let shift = scene.m * Vector3::from(*lever_m) + Vector4::repeat(PLANNER_FROM_TRACKER_PX);
    AffineStereo { c: scene.c - shift, ..scene.clone() }
}

fn affine_from_json(v: &serde_json::Value) -> Result<AffineStereo, ReplayError> {
    let bad = |what: &str| ReplayError::Model(what.to_string());
    let rows: Vec<Vec<f64>> = serde_json::from_value(v["m"].clone()).map_err(|_| bad("`m` must be 4 rows of 3 numbers"))?;
    if rows.len() != 4 || rows.iter().any(|r| r.len() != 3) {
        return Err(bad("`m` must be 4 rows of 3 numbers"));
    }
    let c: [f64; 4] = serde_json::from_value(v["c"].clone()).map_err(|_| bad("`c` must be 4 numbers"))?;
    let disparity_range_px: [f64; 2] = serde_json::from_value(v["disparity_range_px"].clone()).map_err(|_| bad("`disparity_range_px` must be 2 numbers"))?;
    let residual_rms_px = v["residual_rms_px"].as_f64().unwrap_or(0.0);
    Ok(AffineStereo { m: Matrix4x3::from_fn(|r, k| rows[r][k]), c: Vector4::from(c), residual_rms_px, disparity_range_px })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::planning::scene_model;

    #[test]
    fn the_tracker_model_comes_back_from_the_scene_model_the_plan_saved() {
        let model = AffineStereo {
            m: Matrix4x3::from_fn(|r, k| (r * 3 + k) as f64 * 100.0 + 7.0 * k as f64 - 50.0 * r as f64),
            c: Vector4::new(320.0, 240.0, 300.0, 241.0),
            residual_rms_px: 0.3,
            disparity_range_px: [-30.0, 10.0],
        };
        let lever = [0.01, -0.1, -0.056];
        let saved = scene_model(&model, &lever);
        let json = serde_json::json!({
            "m": (0..4).map(|r| [saved.m[(r, 0)], saved.m[(r, 1)], saved.m[(r, 2)]]).collect::<Vec<_>>(),
            "c": [saved.c[0], saved.c[1], saved.c[2], saved.c[3]],
            "disparity_range_px": saved.disparity_range_px,
            "residual_rms_px": saved.residual_rms_px,
        });
        let back = tracker_model(&affine_from_json(&json).unwrap(), &lever);
        assert!((back.m - model.m).abs().max() < 1e-9);
        assert!((back.c - model.c).abs().max() < 1e-9, "{} vs {}", back.c, model.c);
        assert_eq!(back.disparity_range_px, model.disparity_range_px);
    }

    #[test]
    fn a_report_without_the_cage_names_what_is_missing() {
        let cfg = DaemonConfig::default();
        let images = [ImageBuf::new(4, 4), ImageBuf::new(4, 4)];
        let err = replay_request(&cfg, &PlanSummary::default(), images).err().expect("no cage: no replay");
        assert!(err.to_string().contains("lever_m"), "{err}");
    }
}
