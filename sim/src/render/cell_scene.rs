//! The scene of a work cell: meshes of the table, the blocks, the arm with its gripper and
//! tracked plate, and the occluders, each attached to the body (or event) that moves it.

use glam::{DAffine3, DVec3};

use super::scene::{Attach, ID_FINGERS, ID_NONE, ID_PLATE, Mesh, Scene, SceneObject, block_face_id};
use crate::cell::arm::{Arm, FINGER_THICKNESS_M, FINGER_WIDTH_M, PALM_HALF_THICKNESS_M, PALM_HALF_WIDTH_M};
use crate::cell::geometry::BlockShape;
use crate::cell::kinematics::{FINGER_LENGTH_M, FOREARM_M, PALM_LENGTH_M, SHOULDER_HEIGHT_M, UPPER_ARM_M, WRIST_LINK_M};
use crate::cell::world::{TABLE_THICKNESS_M, World};
use crate::scenario::{Event, Scenario};

/// Width of the dark border around the plate's light rectangle, metres.
pub const PLATE_BORDER_M: f64 = 0.007;
/// Albedos of the gripper plate: light rectangle and dark border.
pub const PLATE_LIGHT: f32 = 0.95;
pub const PLATE_DARK: f32 = 0.06;

const ARM_SHADE: f32 = 0.38;
const ARM_SIDE: f32 = 0.28;

impl Scene {
    /// Meshes for the scenario's table, blocks, arm and occluders.
    pub fn build(scenario: &Scenario, world: &World) -> Self {
        let mut objects = Vec::new();
        let t = &scenario.table;
        let mut table = Mesh::default();
        let top = t.shade as f32;
        let side = (t.shade * 0.7) as f32;
        table.cuboid(
            DVec3::new(t.center_m[0], t.center_m[1], -TABLE_THICKNESS_M / 2.0),
            DVec3::new(t.size_m[0] / 2.0, t.size_m[1] / 2.0, TABLE_THICKNESS_M / 2.0),
            [side, side, side, side, top, side],
            [false, false, false, false, false, true],
            ID_NONE,
        );
        objects.push(SceneObject { mesh: table, attach: Attach::Fixed(DAffine3::IDENTITY) });

        for (bi, b) in world.blocks.iter().enumerate() {
            objects.push(SceneObject { mesh: block_mesh(&b.shape, &b.shades, bi), attach: Attach::Body(b.body) });
        }
        objects.extend(arm_objects(&world.arm));

        for (ei, e) in scenario.events.iter().enumerate() {
            if let Event::Occluder { size_mm, shade, .. } = e {
                let mut m = Mesh::default();
                let s = *shade as f32;
                let half = DVec3::from_array(*size_mm) * 0.0005;
                m.cuboid(DVec3::ZERO, half, [s, s * 0.8, s * 0.9, s * 0.7, s, s * 0.6], [false; 6], ID_NONE);
                objects.push(SceneObject { mesh: m, attach: Attach::Occluder(ei) });
            }
        }
        if let Some(p) = &scenario.pointer {
            objects.push(SceneObject { mesh: pointer_mesh(p.shade as f32), attach: Attach::Pointer });
        }
        Self { objects }
    }
}

/// The operator's forearm and pointing finger, in the hand's frame (origin at the fingertip,
/// +x back along the finger towards the elbow, +y across the hand, +z its back): a finger,
/// the hand and a sleeved forearm, all centred on the x axis, so the finger's axis is the
/// axis of the whole silhouette. Skin of albedo `skin`; the sleeve is darker. Lit by the
/// one shading model like everything else.
pub fn pointer_mesh(skin: f32) -> Mesh {
    let mut m = Mesh::default();
    let sleeve = skin * 0.55;
    // (from x, to x, half width y, half thickness z, albedo), metres.
    let parts = [(0.0, 0.08, 0.009, 0.008, skin), (0.08, 0.17, 0.042, 0.016, skin), (0.17, 0.47, 0.036, 0.032, sleeve)];
    for (x0, x1, hy, hz, a) in parts {
        m.cuboid(DVec3::new((x0 + x1) / 2.0, 0.0, 0.0), DVec3::new((x1 - x0) / 2.0, hy, hz), [a; 6], [false; 6], ID_NONE);
    }
    m
}

/// Mesh of block `index` with its face shades and ids.
pub fn block_mesh(shape: &BlockShape, shades: &[f64], index: usize) -> Mesh {
    let mut m = Mesh::default();
    for (fi, f) in shape.faces.iter().enumerate() {
        let pts: Vec<DVec3> = f.corners.iter().map(|&c| shape.corners[c]).collect();
        m.polygon(&pts, f.normal, f.fan_from, shades.get(fi).copied().unwrap_or(0.6) as f32, block_face_id(index, fi));
    }
    m
}

fn arm_objects(arm: &Arm) -> Vec<SceneObject> {
    let mut out = Vec::new();
    let body = |h| Attach::Body(h);
    let sh = |top: f32, side: f32| [side, side, side, side, top, side * 0.8];

    let mut base = Mesh::default();
    base.cuboid(DVec3::new(0.0, 0.0, 0.01), DVec3::new(0.08, 0.08, 0.01), sh(0.3, 0.25), [false; 6], ID_NONE);
    out.push(SceneObject { mesh: base, attach: body(arm.base) });

    let mut turret = Mesh::default();
    turret.cuboid(
        DVec3::new(0.0, 0.0, SHOULDER_HEIGHT_M / 2.0),
        DVec3::new(0.05, 0.05, SHOULDER_HEIGHT_M / 2.0 - 0.02),
        sh(ARM_SHADE, ARM_SIDE),
        [false; 6],
        ID_NONE,
    );
    out.push(SceneObject { mesh: turret, attach: body(arm.links[0]) });

    for (link, len, half) in [(1, UPPER_ARM_M, 0.03), (2, FOREARM_M, 0.025), (3, WRIST_LINK_M, 0.025)] {
        let mut m = Mesh::default();
        m.cuboid(DVec3::X * (len / 2.0), DVec3::new(len / 2.0, half, half), sh(ARM_SHADE, ARM_SIDE), [false; 6], ID_NONE);
        out.push(SceneObject { mesh: m, attach: body(arm.links[link]) });
    }

    // Palm: dark box whose +y face (normal along the finger closing axis, towards the +y
    // finger) is the tracked plate, a light rectangle in a dark border.
    let mut palm = Mesh::default();
    let half = DVec3::new(PALM_LENGTH_M / 2.0, PALM_HALF_WIDTH_M, PALM_HALF_THICKNESS_M);
    let centre = DVec3::X * (PALM_LENGTH_M / 2.0);
    palm.cuboid(centre, half, [0.3, 0.3, 0.25, 0.25, 0.3, 0.2], [false, false, true, false, false, false], ID_NONE);
    plate(&mut palm, centre + DVec3::Y * half.y, half.x, half.z);
    out.push(SceneObject { mesh: palm, attach: body(arm.links[4]) });

    for (i, side) in [1.0, -1.0].into_iter().enumerate() {
        let mut m = Mesh::default();
        let half = DVec3::new(FINGER_LENGTH_M / 2.0, FINGER_THICKNESS_M / 2.0, FINGER_WIDTH_M / 2.0);
        let centre = DVec3::new(FINGER_LENGTH_M / 2.0, side * FINGER_THICKNESS_M / 2.0, 0.0);
        m.cuboid(centre, half, [0.6, 0.6, 0.7, 0.7, 0.5, 0.5], [false, false, false, false, true, false], ID_NONE);
        // The camera-facing side (+z in the palm frame) gets its own id for truth.
        let z = centre.z + half.z;
        let pts = [
            DVec3::new(centre.x - half.x, centre.y - half.y, z),
            DVec3::new(centre.x + half.x, centre.y - half.y, z),
            DVec3::new(centre.x + half.x, centre.y + half.y, z),
            DVec3::new(centre.x - half.x, centre.y + half.y, z),
        ];
        m.polygon(&pts, DVec3::Z, 0, 0.8, ID_FINGERS[i]);
        out.push(SceneObject { mesh: m, attach: body(arm.fingers[i]) });
    }
    out
}

/// The tracked plate on a face at `centre.y` (normal +y, the finger closing axis) with half
/// extents `hx` (along the tool axis) and `hz`: four dark border strips around a light
/// rectangle, all coplanar and non-overlapping.
fn plate(m: &mut Mesh, centre: DVec3, hx: f64, hz: f64) {
    let b = PLATE_BORDER_M;
    let quad = |m: &mut Mesh, x0: f64, x1: f64, z0: f64, z1: f64, shade: f32, id: u32| {
        let y = centre.y;
        // Counter-clockwise seen from +y: (x, z) with x then z is clockwise, so go z first.
        let pts = [
            DVec3::new(centre.x + x0, y, centre.z + z0),
            DVec3::new(centre.x + x0, y, centre.z + z1),
            DVec3::new(centre.x + x1, y, centre.z + z1),
            DVec3::new(centre.x + x1, y, centre.z + z0),
        ];
        m.polygon(&pts, DVec3::Y, 0, shade, id);
    };
    quad(m, -hx, hx, -hz, -hz + b, PLATE_DARK, ID_NONE);
    quad(m, -hx, hx, hz - b, hz, PLATE_DARK, ID_NONE);
    quad(m, -hx, -hx + b, -hz + b, hz - b, PLATE_DARK, ID_NONE);
    quad(m, hx - b, hx, -hz + b, hz - b, PLATE_DARK, ID_NONE);
    quad(m, -hx + b, hx - b, -hz + b, hz - b, PLATE_LIGHT, ID_PLATE);
}

/// The light rectangle of the plate, palm frame (on the palm's +y face, the side of the +y
/// finger; corners counter-clockwise seen from +y), for ground truth.
pub fn plate_corners_in_palm() -> [DVec3; 4] {
    let (hx, hz, b) = (PALM_LENGTH_M / 2.0, PALM_HALF_THICKNESS_M, PLATE_BORDER_M);
    let c = DVec3::new(hx, PALM_HALF_WIDTH_M, 0.0);
    [
        c + DVec3::new(-hx + b, 0.0, -hz + b),
        c + DVec3::new(-hx + b, 0.0, hz - b),
        c + DVec3::new(hx - b, 0.0, hz - b),
        c + DVec3::new(hx - b, 0.0, -hz + b),
    ]
}

/// Normal of the plate in the palm frame: the finger closing axis.
pub const PLATE_NORMAL_IN_PALM: DVec3 = DVec3::Y;

