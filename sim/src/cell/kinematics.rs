//! Kinematics of the 5-DOF arm (base yaw, shoulder, elbow, wrist pitch, wrist roll): the
//! dimensions, joint limits, analytic inverse kinematics for a gripper pointing straight down,
//! and forward kinematics. Pure math in f64; the physical arm in [`crate::cell::arm`] is built from
//! the same constants.
//!
//! Robot frame: metres, z up, origin at the arm's base on the table top. The *tool point* lies
//! midway between the finger tips. Tool *yaw* is the rotation about z of the gripper when it
//! points down: at yaw 0 the fingers close along the robot y axis and the gripper's tracked
//! plate faces +y (its normal is the closing axis; at the shipped scenarios' home yaw of -90°
//! it faces +x, towards the cameras).
//!
//! Joint angles (radians): `q[0]` base yaw about +z (0 = arm along +x); `q[1]` shoulder, the
//! upper arm's elevation above horizontal; `q[2]` elbow, relative (negative = elbow up, the
//! only branch used); `q[3]` wrist pitch, relative (the tool axis has elevation
//! `q[1] + q[2] + q[3]`, so pointing down needs the sum to be -90°); `q[4]` wrist roll about
//! the tool axis (tool yaw = `q[0] - q[4]` when pointing down).

use glam::{DMat3, DVec3};

/// Height of the shoulder axis above the table, metres.
pub const SHOULDER_HEIGHT_M: f64 = 0.30;
/// Shoulder axis to elbow axis, metres.
pub const UPPER_ARM_M: f64 = 0.30;
/// Elbow axis to wrist pitch axis, metres.
pub const FOREARM_M: f64 = 0.28;
/// Wrist pitch axis to the roll flange (top of the palm), metres.
pub const WRIST_LINK_M: f64 = 0.04;
/// Height of the palm along the tool axis, metres.
pub const PALM_LENGTH_M: f64 = 0.06;
/// Finger length below the palm, metres.
pub const FINGER_LENGTH_M: f64 = 0.07;
/// Wrist pitch axis to the tool point, metres.
pub const WRIST_TO_TOOL_M: f64 = WRIST_LINK_M + PALM_LENGTH_M + FINGER_LENGTH_M;

/// Lowest tool point the controller accepts (finger tips just above the table), metres.
pub const MIN_TOOL_Z_M: f64 = 0.004;
/// Closest horizontal distance of the tool point to the base axis, metres.
pub const MIN_RADIUS_M: f64 = 0.15;
/// Margin kept from a fully stretched arm (a singular configuration), metres.
pub const REACH_MARGIN_M: f64 = 0.01;

/// Joint limits, radians.
pub const JOINT_MIN_RAD: [f64; 5] = [-170f64.to_radians(), -20f64.to_radians(), -165f64.to_radians(), -150f64.to_radians(), -170f64.to_radians()];
pub const JOINT_MAX_RAD: [f64; 5] = [170f64.to_radians(), 135f64.to_radians(), -5f64.to_radians(), 60f64.to_radians(), 170f64.to_radians()];
/// Joint speed limits, rad/s.
pub const JOINT_MAX_SPEED_RADPS: [f64; 5] = [1.6, 1.6, 2.0, 3.0, 3.0];

/// Tool pose with the gripper pointing down: position of the tool point and yaw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolPose {
    pub pos_m: DVec3,
    pub yaw_rad: f64,
}

/// Why a tool pose cannot be reached.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum IkError {
    #[error("target is out of the arm's reach ({0})")]
    OutOfReach(&'static str),
    #[error("joint {joint} would need {angle_deg:.1}°, outside its limits")]
    JointLimit { joint: usize, angle_deg: f64 },
    #[error("target is not a finite number")]
    NotFinite,
}

/// Wraps an angle into (-π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let mut a = a % std::f64::consts::TAU;
    if a > std::f64::consts::PI {
        a -= std::f64::consts::TAU;
    } else if a <= -std::f64::consts::PI {
        a += std::f64::consts::TAU;
    }
    a
}

/// Joint angles that put the tool point at `pose` with the gripper pointing down (elbow up).
///
/// ```
/// use handeye_sim::cell::kinematics::{ik, fk, ToolPose};
/// let pose = ToolPose { pos_m: glam::DVec3::new(0.35, 0.05, 0.03), yaw_rad: 0.3 };
/// let q = ik(pose).unwrap();
/// let back = fk(&q);
/// assert!((back.tool_m - pose.pos_m).length() < 1e-9);
/// ```
pub fn ik(pose: ToolPose) -> Result<[f64; 5], IkError> {
    let p = pose.pos_m;
    if !(p.is_finite() && pose.yaw_rad.is_finite()) {
        return Err(IkError::NotFinite);
    }
    if p.z < MIN_TOOL_Z_M {
        return Err(IkError::OutOfReach("below the lowest tool height"));
    }
    let r = p.x.hypot(p.y);
    if r < MIN_RADIUS_M {
        return Err(IkError::OutOfReach("too close to the base axis"));
    }
    let base = p.y.atan2(p.x);
    // Wrist pitch axis straight above the tool point; solve the planar two-link chain to it.
    let wz = p.z + WRIST_TO_TOOL_M - SHOULDER_HEIGHT_M;
    let d2 = r * r + wz * wz;
    let d = d2.sqrt();
    if d > UPPER_ARM_M + FOREARM_M - REACH_MARGIN_M {
        return Err(IkError::OutOfReach("beyond the arm's stretch"));
    }
    if d < (UPPER_ARM_M - FOREARM_M).abs() + REACH_MARGIN_M {
        return Err(IkError::OutOfReach("too close to the shoulder"));
    }
    let c2 = ((d2 - UPPER_ARM_M * UPPER_ARM_M - FOREARM_M * FOREARM_M) / (2.0 * UPPER_ARM_M * FOREARM_M)).clamp(-1.0, 1.0);
    let elbow = -c2.acos(); // elbow up
    let shoulder = wz.atan2(r) - (FOREARM_M * elbow.sin()).atan2(UPPER_ARM_M + FOREARM_M * elbow.cos());
    let pitch = -std::f64::consts::FRAC_PI_2 - shoulder - elbow;
    let roll = wrap_angle(base - pose.yaw_rad);
    let q = [base, shoulder, elbow, pitch, roll];
    for (j, &a) in q.iter().enumerate() {
        if a < JOINT_MIN_RAD[j] || a > JOINT_MAX_RAD[j] {
            return Err(IkError::JointLimit { joint: j, angle_deg: a.to_degrees() });
        }
    }
    Ok(q)
}

/// Forward kinematics: where the links are for joint angles `q`.
#[derive(Debug, Clone, Copy)]
pub struct ArmPose {
    /// Tool point, robot frame.
    pub tool_m: DVec3,
    /// Orientation of the palm (columns: tool direction, finger closing axis, plate normal).
    pub palm_rot: DMat3,
    /// Wrist pitch axis centre.
    pub wrist_m: DVec3,
}

impl ArmPose {
    /// Tool yaw read from the finger axis (meaningful when pointing down).
    pub fn yaw_rad(&self) -> f64 {
        yaw_of(&self.palm_rot)
    }
}

/// Tool yaw from a palm orientation: the finger axis (column 1) is (-sin yaw, cos yaw, 0).
pub fn yaw_of(palm_rot: &DMat3) -> f64 {
    let y = palm_rot.y_axis;
    (-y.x).atan2(y.y)
}

/// Angle between the tool direction (palm column 0) and straight down, radians.
pub fn tilt_of(palm_rot: &DMat3) -> f64 {
    palm_rot.x_axis.dot(DVec3::NEG_Z).clamp(-1.0, 1.0).acos()
}

/// Forward kinematics of joint angles `q`.
pub fn fk(q: &[f64; 5]) -> ArmPose {
    let (sb, cb) = q[0].sin_cos();
    let out = DVec3::new(cb, sb, 0.0);
    let a1 = q[1];
    let a2 = a1 + q[2];
    let a3 = a2 + q[3];
    let planar = |angle: f64, len: f64| out * (len * angle.cos()) + DVec3::Z * (len * angle.sin());
    let shoulder = DVec3::new(0.0, 0.0, SHOULDER_HEIGHT_M);
    let wrist = shoulder + planar(a1, UPPER_ARM_M) + planar(a2, FOREARM_M);
    let tool = wrist + planar(a3, WRIST_TO_TOOL_M);
    // Rz(base) * Ry(-a3) * Rx(roll): pitch joints turn about -y so positive angles raise links.
    let rot = DMat3::from_rotation_z(q[0]) * DMat3::from_rotation_y(-a3) * DMat3::from_rotation_x(q[4]);
    ArmPose { tool_m: tool, palm_rot: rot, wrist_m: wrist }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ik_round_trips_through_fk_across_the_workspace() {
        for x in [0.2, 0.3, 0.4, 0.5] {
            for y in [-0.2, 0.0, 0.15] {
                for z in [0.01, 0.1, 0.25] {
                    for yaw in [-1.0, 0.0, 0.7] {
                        let pose = ToolPose { pos_m: DVec3::new(x, y, z), yaw_rad: yaw };
                        let q = ik(pose).unwrap_or_else(|e| panic!("{pose:?}: {e}"));
                        let a = fk(&q);
                        assert!((a.tool_m - pose.pos_m).length() < 1e-9, "{pose:?} -> {:?}", a.tool_m);
                        assert!(wrap_angle(a.yaw_rad() - yaw).abs() < 1e-9);
                        assert!(tilt_of(&a.palm_rot) < 1e-9, "gripper must point down");
                        // Plate normal (column 2) points along yaw: +x at yaw 0.
                        let n = a.palm_rot.z_axis;
                        assert!((n - DVec3::new(yaw.cos(), yaw.sin(), 0.0)).length() < 1e-9);
                    }
                }
            }
        }
    }

    #[test]
    fn ik_refuses_what_it_cannot_reach() {
        let at = |x, y, z| ik(ToolPose { pos_m: DVec3::new(x, y, z), yaw_rad: 0.0 });
        assert!(matches!(at(0.9, 0.0, 0.1), Err(IkError::OutOfReach(_))));
        assert!(matches!(at(0.3, 0.0, -0.01), Err(IkError::OutOfReach(_))));
        assert!(matches!(at(0.05, 0.0, 0.1), Err(IkError::OutOfReach(_))));
        assert!(matches!(at(f64::NAN, 0.0, 0.1), Err(IkError::NotFinite)));
        // Behind the base: base yaw beyond ±170°.
        assert!(matches!(at(-0.3, 0.01, 0.1), Err(IkError::JointLimit { joint: 0, .. })));
    }

    #[test]
    fn wrap_angle_stays_in_range() {
        for a in [-10.0, -3.2, -1.0, 0.0, 3.1, 3.2, 7.0] {
            let w = wrap_angle(a);
            assert!(w > -std::f64::consts::PI - 1e-12 && w <= std::f64::consts::PI + 1e-12);
            assert!(((w - a) / std::f64::consts::TAU).round() * std::f64::consts::TAU - (w - a) < 1e-9);
        }
    }
}
