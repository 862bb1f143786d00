//! What the cameras see: flat-shaded triangle meshes, each attached to a physics body (or a
//! scripted pose), with a face id per triangle for ground truth. Built once per simulator
//! (from the work cell, [`super::cell_scene`]); poses come from physics every frame.

use glam::{DAffine3, DVec3};

use crate::cell::geometry::BlockShape;
use crate::scenario::BlockKind;

/// Face id of nothing in particular (table, arm links, background).
pub const ID_NONE: u32 = 0;
/// Face id of the gripper plate's light rectangle (the face the daemon tracks).
pub const ID_PLATE: u32 = 0x1000;
/// Face ids of the two fingers' camera-facing sides (+y finger, -y finger).
pub const ID_FINGERS: [u32; 2] = [0x1001, 0x1002];

/// Face id of face `face` of block `block`.
pub fn block_face_id(block: usize, face: usize) -> u32 {
    1 + (block as u32) * 16 + face as u32
}

/// The block and face of a face id, if it is one.
pub fn decode_block_face(id: u32) -> Option<(usize, usize)> {
    (id != ID_NONE && id < ID_PLATE).then(|| (((id - 1) / 16) as usize, ((id - 1) % 16) as usize))
}

/// One vertex of a flat-shaded triangle, in its object's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshVertex {
    pub pos: [f32; 3],
    pub normal: [f32; 3],
    pub shade: f32,
    pub id: u32,
}

/// Triangles (three vertices each) of one object.
#[derive(Debug, Clone, Default)]
pub struct Mesh {
    pub vertices: Vec<MeshVertex>,
}

impl Mesh {
    /// Adds a planar polygon (counter-clockwise seen from outside, convex or fanned from
    /// corner `fan_from`).
    pub fn polygon(&mut self, pts: &[DVec3], normal: DVec3, fan_from: usize, shade: f32, id: u32) {
        let n = pts.len();
        let v = |p: DVec3| MeshVertex { pos: p.as_vec3().to_array(), normal: normal.as_vec3().to_array(), shade, id };
        for k in 1..n - 1 {
            self.vertices.push(v(pts[fan_from % n]));
            self.vertices.push(v(pts[(fan_from + k) % n]));
            self.vertices.push(v(pts[(fan_from + k + 1) % n]));
        }
    }

    /// Adds an axis-aligned box; `shades` in the order +x, -x, +y, -y, +z, -z; `skip` faces
    /// (same order) are left out (e.g. one another mesh draws).
    pub fn cuboid(&mut self, centre: DVec3, half: DVec3, shades: [f32; 6], skip: [bool; 6], id: u32) {
        let shape = BlockShape::new(BlockKind::Bar, half * 2.0);
        let order = ["+x", "-x", "+y", "-y", "top", "bottom"];
        for (k, name) in order.iter().enumerate() {
            if skip[k] {
                continue;
            }
            let Some(f) = shape.faces.iter().find(|f| f.name == *name) else { continue };
            let pts: Vec<DVec3> = f.corners.iter().map(|&c| shape.corners[c] + centre).collect();
            self.polygon(&pts, f.normal, 0, shades[k], id);
        }
    }
}

/// Where an object's pose comes from.
#[derive(Debug, Clone, Copy)]
pub enum Attach {
    Fixed(DAffine3),
    Body(rapier3d::prelude::RigidBodyHandle),
    /// Index into the scenario's events (an occluder).
    Occluder(usize),
    /// The operator's pointing hand (`[pointer]`), posed by its gesture.
    Pointer,
}

/// One drawable object.
#[derive(Debug, Clone)]
pub struct SceneObject {
    pub mesh: Mesh,
    pub attach: Attach,
}

/// Everything drawable in the work cell.
#[derive(Debug, Clone, Default)]
pub struct Scene {
    pub objects: Vec<SceneObject>,
}

impl Scene {
    /// Total vertex count (for sizing GPU buffers once).
    pub fn vertex_count(&self) -> usize {
        self.objects.iter().map(|o| o.mesh.vertices.len()).sum()
    }
}
