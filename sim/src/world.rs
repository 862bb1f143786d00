//! The physics work cell: a fixed table (top face at z = 0), dynamic blocks with friction and
//! the arm, stepped by rapier at the scenario's fixed rate.

use glam::{DMat3, DQuat, DVec3, Vec3};
use rapier3d::prelude::*;

use crate::arm::{self, Arm, groups};
use crate::geometry::BlockShape;
use handeye_vision::rng::SplitMix64;
use crate::scenario::{BlockConfig, Scenario};

/// Contact stiffness (natural frequency, Hz) and damping ratio between dynamic bodies; twice
/// the frequency against fixed ones (the table).
const CONTACT_HZ: f32 = 120.0;
const CONTACT_DAMPING_RATIO: f32 = 10.0;

/// Thickness of the table slab, metres.
pub const TABLE_THICKNESS_M: f64 = 0.04;

/// One block: its shape, shades and physics body.
#[derive(Debug, Clone)]
pub struct Block {
    pub name: String,
    pub shape: BlockShape,
    /// Albedo per face (same order as `shape.faces`).
    pub shades: Vec<f64>,
    pub body: RigidBodyHandle,
    /// Height of the block frame's origin when resting on its bottom face, metres.
    pub rest_z_m: f64,
}

/// The physics world and the handles into it.
pub struct World {
    pub physics: PhysicsWorld,
    pub table: RigidBodyHandle,
    pub blocks: Vec<Block>,
    pub arm: Arm,
}

impl World {
    /// Builds the work cell of `scenario` with the arm at joint angles `q0`.
    pub fn new(scenario: &Scenario, q0: [f64; 5]) -> Self {
        let mut physics = PhysicsWorld::new();
        physics.gravity = Vec3::new(0.0, 0.0, -scenario.physics.gravity_mps2 as f32);
        physics.integration_parameters.dt = scenario.physics_dt_s() as f32;
        // rapier's default contacts (30 Hz) are tuned for piles of human-sized bodies; a 40 g
        // block squeezed by the gripper sank ~15 mm into the fingers. Four times stiffer
        // contacts (same damping ratio) keep penetration well under a millimetre.
        physics.integration_parameters.contact_softness = SpringCoefficients::new(CONTACT_HZ, CONTACT_DAMPING_RATIO);
        physics.integration_parameters.static_contact_softness = SpringCoefficients::new(2.0 * CONTACT_HZ, CONTACT_DAMPING_RATIO);

        let t = &scenario.table;
        let table = physics.insert_body(RigidBodyBuilder::fixed().translation(Vec3::new(
            t.center_m[0] as f32,
            t.center_m[1] as f32,
            (-TABLE_THICKNESS_M / 2.0) as f32,
        )));
        physics.insert_collider(
            ColliderBuilder::cuboid((t.size_m[0] / 2.0) as f32, (t.size_m[1] / 2.0) as f32, (TABLE_THICKNESS_M / 2.0) as f32)
                .friction(t.friction as f32)
                .collision_groups(InteractionGroups::new(groups::TABLE, groups::BLOCK | groups::HAND, InteractionTestMode::And)),
            Some(table),
        );

        // Insertion order is fixed (table, blocks in file order, arm): rapier is bit-identical
        // only for identical insertion order.
        let blocks = scenario.blocks.iter().enumerate().map(|(i, b)| insert_block(&mut physics, scenario, i, b)).collect();
        let arm = Arm::build(&mut physics, q0);
        Self { physics, table, blocks, arm }
    }

    /// One physics step.
    pub fn step(&mut self) {
        self.physics.step();
    }

    /// Pose of a body, f64.
    pub fn body_pose(&self, h: RigidBodyHandle) -> (DVec3, DMat3) {
        arm::body_pose(&self.physics, h)
    }

    /// Moves a block by `delta_m` in x-y and turns it by `yaw_rad` about its own vertical,
    /// at once (scenario "target nudge"); its velocity is zeroed.
    pub fn nudge_block(&mut self, index: usize, delta_m: [f64; 2], yaw_rad: f64) {
        let Some(block) = self.blocks.get(index) else { return };
        if let Some(body) = self.physics.bodies.get_mut(block.body) {
            let pose = *body.position();
            let rot = glam::Quat::from_rotation_z(yaw_rad as f32) * pose.rotation;
            let pos = pose.translation + Vec3::new(delta_m[0] as f32, delta_m[1] as f32, 0.0);
            body.set_position(Pose::from_parts(pos, rot), true);
            body.set_linvel(Vec3::ZERO, true);
            body.set_angvel(Vec3::ZERO, true);
        }
    }
}

/// Default face shades: well-spread levels in a seeded order, so neighbouring faces differ.
pub fn random_shades(seed: u64, count: usize) -> Vec<f64> {
    let mut rng = SplitMix64::new(seed);
    let mut levels: Vec<f64> = (0..count).map(|i| 0.35 + 0.6 * i as f64 / (count.max(2) - 1) as f64).collect();
    for i in (1..levels.len()).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        levels.swap(i, j);
    }
    levels
}

fn insert_block(physics: &mut PhysicsWorld, scenario: &Scenario, index: usize, b: &BlockConfig) -> Block {
    let size = DVec3::from_array(b.size_mm) * 1e-3;
    let shape = BlockShape::new(b.kind, size);
    let rest_z_m = size.z / 2.0;
    let shades = match &b.shades {
        Some(s) => s.clone(),
        None => random_shades(b.shade_seed.unwrap_or_else(|| handeye_vision::rng::mix64(scenario.seed ^ (index as u64 + 1))), shape.faces.len()),
    };
    let rot = DQuat::from_rotation_z(b.yaw_deg.to_radians());
    let body = physics.insert_body(
        // Blocks never sleep: a sleeping block squeezed by the fingers (a multibody) slid out
        // of the grasp in most trials (rapier 0.36), an awake one held in every trial.
        RigidBodyBuilder::dynamic()
            .can_sleep(false)
            .translation(Vec3::new(b.position_m[0] as f32, b.position_m[1] as f32, rest_z_m as f32))
            .rotation(rot.to_scaled_axis().as_vec3()),
    );
    let groups = InteractionGroups::new(groups::BLOCK, Group::ALL, InteractionTestMode::And);
    let material = |c: ColliderBuilder| c.density(b.density_kg_m3 as f32).friction(b.friction as f32).collision_groups(groups);
    if shape.cuboids.is_empty() {
        let pts: Vec<Vec3> = shape.corners.iter().map(|c| c.as_vec3()).collect();
        let hull = ColliderBuilder::convex_hull(&pts).expect("block corners span a volume (sizes are validated >= 20 mm)");
        physics.insert_collider(material(hull), Some(body));
    } else {
        for (centre, half) in &shape.cuboids {
            let c = ColliderBuilder::cuboid(half.x as f32, half.y as f32, half.z as f32).translation(centre.as_vec3());
            physics.insert_collider(material(c), Some(body));
        }
    }
    Block { name: b.name.clone(), shape, shades, body, rest_z_m }
}
