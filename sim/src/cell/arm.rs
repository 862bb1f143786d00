//! The physical arm: a rapier multibody (reduced coordinates) of five revolute joints with
//! position motors and a parallel-jaw gripper of two prismatic fingers with force-limited
//! motors, built from the dimensions in [`crate::cell::kinematics`].
//!
//! Body frames at the joint zero configuration are all aligned with the robot frame (the arm
//! stretched along +x, the gripper pointing along +x); see `kinematics` for the joint
//! conventions. Palm frame: x along the tool axis (from the roll flange towards the finger
//! tips), y the finger closing axis and the normal of the tracked plate (on the palm's +y face).
//!
//! What made grasping work (CRATE_NOTES §3.5 plus what this arm needed, each observed):
//! multibody self-contacts off; force-based, stiff arm motors (acceleration-based ones left
//! the light wrist soft enough to twist under a grasp); force-based finger motors on ~0.1 kg
//! fingers squeezing at 5 N, closed gently by the controller; contacts 4x stiffer than
//! rapier's default; blocks that never sleep; the palm kept above the grasp height.
//! The arm links have gravity scale 0: the controller is modelled with ideal gravity
//! compensation, as industrial controllers have; payloads still load the arm and the
//! controller's integral term removes the sag they cause.

use glam::{DMat3, DQuat, DVec3, Quat, Vec3};
use rapier3d::prelude::*;

use crate::cell::kinematics::{self, FINGER_LENGTH_M, PALM_LENGTH_M, WRIST_LINK_M};

/// Collision groups of the work cell.
pub mod groups {
    use rapier3d::prelude::Group;
    pub const TABLE: Group = Group::GROUP_1;
    pub const BLOCK: Group = Group::GROUP_2;
    /// Turret, upper arm, forearm, wrist: meet blocks only (they pass over the table).
    pub const ARM: Group = Group::GROUP_3;
    /// Palm and fingers: meet blocks and the table.
    pub const HAND: Group = Group::GROUP_4;
}

/// Finger travel: each finger's inner face moves 0..40 mm from the centre line.
pub const FINGER_TRAVEL_M: f64 = 0.040;
/// Finger cross-section: thickness along the closing axis and width across it.
pub const FINGER_THICKNESS_M: f64 = 0.012;
pub const FINGER_WIDTH_M: f64 = 0.020;
/// Half width of the palm across the fingers and half its thickness, metres.
pub const PALM_HALF_WIDTH_M: f64 = 0.056;
pub const PALM_HALF_THICKNESS_M: f64 = 0.028;
/// Finger squeeze force when closed, newtons. With friction ~1 it holds ~10 N, ten times the
/// heaviest block; squeezing harder (15-20 N) made rapier's contact solver push light blocks
/// out of the jaws in a third of the trials, 3-7 N held in all of them.
pub const GRIP_FORCE_N: f64 = 5.0;
/// Finger motor target when closing: past the centre line, so the motor always squeezes.
pub const FINGER_CLOSE_TARGET_M: f64 = -0.010;

/// Arm joint motors: force-based (N·m/rad, N·m·s/rad) and stiff, like a geared servo.
/// Acceleration-based gains scale with the link's effective inertia, which left the light
/// wrist so soft that a grasp twisted it by 0.1 rad.
const ARM_STIFFNESS: f32 = 20_000.0;
const ARM_DAMPING: f32 = 400.0;
/// Torque limits per joint, N·m: enough to accelerate the (gravity-compensated) links
/// briskly, small enough that a blocked arm pushes with tens of newtons, not hundreds.
const ARM_MAX_TORQUE_NM: [f32; 5] = [40.0, 60.0, 40.0, 15.0, 5.0];
const FINGER_STIFFNESS: f32 = 2_000.0;
const FINGER_DAMPING: f32 = 100.0;
const FINGER_DENSITY: f32 = 6_000.0;

/// Tool point in the palm frame.
pub fn tool_in_palm() -> DVec3 {
    DVec3::new(PALM_LENGTH_M + FINGER_LENGTH_M, 0.0, 0.0)
}

/// Handles of the arm's bodies and joints in the physics world.
#[derive(Debug, Clone)]
pub struct Arm {
    /// Fixed base plate on the table.
    pub base: RigidBodyHandle,
    /// Turret, upper arm, forearm, wrist, palm.
    pub links: [RigidBodyHandle; 5],
    /// Fingers on the palm's +y and -y sides.
    pub fingers: [RigidBodyHandle; 2],
    joints: [MultibodyJointHandle; 5],
    finger_joints: [MultibodyJointHandle; 2],
}

/// What the arm's sensors read: joint encoders and finger positions, plus the tool pose
/// computed from the palm body (the physical truth, not the controller's intent).
#[derive(Debug, Clone, Copy)]
pub struct ArmReading {
    pub q_rad: [f64; 5],
    pub dq_radps: [f64; 5],
    /// Inner-face offset of each finger from the centre line, metres.
    pub finger_m: [f64; 2],
    pub finger_vel_mps: [f64; 2],
    pub tool_m: DVec3,
    pub palm_rot: DMat3,
}

impl ArmReading {
    pub fn yaw_rad(&self) -> f64 {
        kinematics::yaw_of(&self.palm_rot)
    }

    /// Distance between the finger pads, metres.
    pub fn gripper_width_m(&self) -> f64 {
        self.finger_m[0] + self.finger_m[1]
    }
}

/// Motor set-points for one control tick.
#[derive(Debug, Clone, Copy)]
pub struct MotorTargets {
    pub q_rad: [f64; 5],
    pub finger_m: [f64; 2],
}

fn v3(v: DVec3) -> Vec3 {
    v.as_vec3()
}

impl Arm {
    /// Builds the arm in `world` with joint angles `q0` and the gripper open.
    pub fn build(world: &mut PhysicsWorld, q0: [f64; 5]) -> Self {
        use kinematics::{FOREARM_M, SHOULDER_HEIGHT_M, UPPER_ARM_M};
        let arm_groups = InteractionGroups::new(groups::ARM, groups::BLOCK, InteractionTestMode::And);
        let hand_groups = InteractionGroups::new(groups::HAND, groups::BLOCK | groups::TABLE, InteractionTestMode::And);
        let link = |at: DVec3| RigidBodyBuilder::dynamic().translation(v3(at)).gravity_scale(0.0).can_sleep(false);
        let boxc = |half: DVec3, centre: DVec3| {
            ColliderBuilder::cuboid(half.x as f32, half.y as f32, half.z as f32).translation(v3(centre))
        };

        let base = world.insert_body(RigidBodyBuilder::fixed());
        world.insert_collider(
            boxc(DVec3::new(0.08, 0.08, 0.01), DVec3::new(0.0, 0.0, 0.01)).collision_groups(arm_groups),
            Some(base),
        );

        let shoulder = DVec3::new(0.0, 0.0, SHOULDER_HEIGHT_M);
        let elbow = shoulder + DVec3::X * UPPER_ARM_M;
        let wrist = elbow + DVec3::X * FOREARM_M;
        let flange = wrist + DVec3::X * WRIST_LINK_M;

        let turret = world.insert_body(link(DVec3::ZERO));
        world.insert_collider(
            boxc(DVec3::new(0.05, 0.05, SHOULDER_HEIGHT_M / 2.0 - 0.02), DVec3::new(0.0, 0.0, SHOULDER_HEIGHT_M / 2.0))
                .density(1500.0)
                .collision_groups(arm_groups),
            Some(turret),
        );
        let upper = world.insert_body(link(shoulder));
        world.insert_collider(
            boxc(DVec3::new(UPPER_ARM_M / 2.0, 0.03, 0.03), DVec3::X * (UPPER_ARM_M / 2.0))
                .density(1200.0)
                .collision_groups(arm_groups),
            Some(upper),
        );
        let fore = world.insert_body(link(elbow));
        world.insert_collider(
            boxc(DVec3::new(FOREARM_M / 2.0, 0.025, 0.025), DVec3::X * (FOREARM_M / 2.0))
                .density(1200.0)
                .collision_groups(arm_groups),
            Some(fore),
        );
        let wrist_body = world.insert_body(link(wrist));
        world.insert_collider(
            boxc(DVec3::new(WRIST_LINK_M / 2.0, 0.025, 0.025), DVec3::X * (WRIST_LINK_M / 2.0))
                .density(1200.0)
                .collision_groups(arm_groups),
            Some(wrist_body),
        );
        let palm = world.insert_body(link(flange));
        world.insert_collider(
            boxc(
                DVec3::new(PALM_LENGTH_M / 2.0, PALM_HALF_WIDTH_M, PALM_HALF_THICKNESS_M),
                DVec3::X * (PALM_LENGTH_M / 2.0),
            )
            .density(1200.0)
            .friction(0.8)
            .collision_groups(hand_groups),
            Some(palm),
        );
        let mut fingers = [palm; 2];
        for (i, side) in [1.0, -1.0].into_iter().enumerate() {
            let f = world.insert_body(link(flange + DVec3::X * PALM_LENGTH_M));
            world.insert_collider(
                boxc(
                    DVec3::new(FINGER_LENGTH_M / 2.0, FINGER_THICKNESS_M / 2.0, FINGER_WIDTH_M / 2.0),
                    DVec3::new(FINGER_LENGTH_M / 2.0, side * FINGER_THICKNESS_M / 2.0, 0.0),
                )
                .density(FINGER_DENSITY)
                .friction(1.2)
                .collision_groups(hand_groups),
                Some(f),
            );
            fingers[i] = f;
        }

        let revolute = |axis: Vec3, anchor: DVec3, max_torque: f32| {
            RevoluteJointBuilder::new(axis)
                .local_anchor1(v3(anchor))
                .local_anchor2(Vec3::ZERO)
                .contacts_enabled(false)
                .motor_model(MotorModel::ForceBased)
                .motor_position(0.0, ARM_STIFFNESS, ARM_DAMPING)
                .motor_max_force(max_torque)
        };
        let mbj = &mut world.multibody_joints;
        let insert = |mbj: &mut MultibodyJointSet, a, b, j: RevoluteJointBuilder| {
            mbj.insert(a, b, j, true).expect("the arm is a tree: every joint inserts")
        };
        let t = ARM_MAX_TORQUE_NM;
        let j0 = insert(mbj, base, turret, revolute(Vec3::Z, DVec3::ZERO, t[0]));
        let j1 = insert(mbj, turret, upper, revolute(Vec3::NEG_Y, shoulder, t[1]));
        let j2 = insert(mbj, upper, fore, revolute(Vec3::NEG_Y, DVec3::X * UPPER_ARM_M, t[2]));
        let j3 = insert(mbj, fore, wrist_body, revolute(Vec3::NEG_Y, DVec3::X * FOREARM_M, t[3]));
        let j4 = insert(mbj, wrist_body, palm, revolute(Vec3::X, DVec3::X * WRIST_LINK_M, t[4]));
        let mut finger_joints = [j0; 2];
        for (i, axis) in [Vec3::Y, Vec3::NEG_Y].into_iter().enumerate() {
            let joint = PrismaticJointBuilder::new(axis)
                .local_anchor1(v3(DVec3::X * PALM_LENGTH_M))
                .local_anchor2(Vec3::ZERO)
                .limits([0.0, FINGER_TRAVEL_M as f32])
                .contacts_enabled(false)
                .motor_model(MotorModel::ForceBased)
                .motor_position(FINGER_TRAVEL_M as f32, FINGER_STIFFNESS, FINGER_DAMPING)
                .motor_max_force(GRIP_FORCE_N as f32);
            finger_joints[i] = mbj.insert(palm, fingers[i], joint, true).expect("fingers hang off the palm");
        }
        if let Some((mb, _)) = mbj.get_mut(j0) {
            mb.set_self_contacts_enabled(false);
        }

        let arm = Self { base, links: [turret, upper, fore, wrist_body, palm], fingers, joints: [j0, j1, j2, j3, j4], finger_joints };
        arm.set_configuration(world, q0, [FINGER_TRAVEL_M; 2]);
        arm.drive(world, &MotorTargets { q_rad: q0, finger_m: [FINGER_TRAVEL_M; 2] });
        arm
    }

    /// Puts the joints at `q` and the fingers at `finger_m` at once (start-up only).
    fn set_configuration(&self, world: &mut PhysicsWorld, q: [f64; 5], finger_m: [f64; 2]) {
        let PhysicsWorld { multibody_joints, bodies, .. } = world;
        let coords = self.joints.iter().zip(q).chain(self.finger_joints.iter().zip(finger_m));
        for (&h, value) in coords {
            if let Some((mb, id)) = multibody_joints.get_mut(h)
                && let Some(link) = mb.link_mut(id)
            {
                link.joint.apply_displacement(&[value as f32]);
            }
        }
        if let Some((mb, _)) = multibody_joints.get_mut(self.joints[0]) {
            mb.forward_kinematics(bodies, false);
            mb.update_rigid_bodies(bodies, true);
        }
    }

    /// Sets the motor targets of all joints.
    pub fn drive(&self, world: &mut PhysicsWorld, t: &MotorTargets) {
        for (&h, &q) in self.joints.iter().zip(&t.q_rad) {
            if let Some((mb, id)) = world.multibody_joints.get_mut(h)
                && let Some(link) = mb.link_mut(id)
            {
                link.joint.data.set_motor_position(JointAxis::AngX, q as f32, ARM_STIFFNESS, ARM_DAMPING);
            }
        }
        for (&h, &x) in self.finger_joints.iter().zip(&t.finger_m) {
            if let Some((mb, id)) = world.multibody_joints.get_mut(h)
                && let Some(link) = mb.link_mut(id)
            {
                link.joint.data.set_motor_position(JointAxis::LinX, x as f32, FINGER_STIFFNESS, FINGER_DAMPING);
            }
        }
    }

    /// Reads encoders, finger positions and the palm pose.
    pub fn read(&self, world: &PhysicsWorld) -> ArmReading {
        let coord = |h: MultibodyJointHandle, index: usize| -> (f64, f64) {
            world
                .multibody_joints
                .get(h)
                .and_then(|(mb, id)| {
                    let link = mb.link(id)?;
                    let vel = mb.joint_velocity(link);
                    Some((f64::from(link.joint.coords()[index]), vel.get(0).copied().map_or(0.0, f64::from)))
                })
                .unwrap_or((0.0, 0.0))
        };
        let mut r = ArmReading {
            q_rad: [0.0; 5],
            dq_radps: [0.0; 5],
            finger_m: [0.0; 2],
            finger_vel_mps: [0.0; 2],
            tool_m: DVec3::ZERO,
            palm_rot: DMat3::IDENTITY,
        };
        for (i, &h) in self.joints.iter().enumerate() {
            (r.q_rad[i], r.dq_radps[i]) = coord(h, 3);
        }
        for (i, &h) in self.finger_joints.iter().enumerate() {
            (r.finger_m[i], r.finger_vel_mps[i]) = coord(h, 0);
        }
        let (pos, rot) = body_pose(world, self.links[4]);
        r.palm_rot = rot;
        r.tool_m = pos + rot * tool_in_palm();
        r
    }
}

/// Position and orientation of a body, f64.
pub fn body_pose(world: &PhysicsWorld, h: RigidBodyHandle) -> (DVec3, DMat3) {
    match world.bodies.get(h) {
        Some(b) => {
            let p = b.position();
            (p.translation.as_dvec3(), DMat3::from_quat(quat_f64(p.rotation)))
        }
        None => (DVec3::ZERO, DMat3::IDENTITY),
    }
}

pub fn quat_f64(q: Quat) -> DQuat {
    DQuat::from_xyzw(f64::from(q.x), f64::from(q.y), f64::from(q.z), f64::from(q.w))
}
