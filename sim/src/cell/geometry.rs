//! Block shapes: corners, faces and edges of the polyhedral blocks, in the block's own frame.
//!
//! One description serves physics (colliders), rendering (triangles with a shade per face)
//! and ground truth (face polygons, 3-D edges), so the three can never disagree.
//!
//! Block frame: metres, origin at the centre of the block's bounding box, z up when the block
//! rests on its bottom face; `size = [x, y, z]` is the bounding box.

use glam::DVec3;

use crate::scenario::BlockKind;

/// One planar face of a block.
#[derive(Debug, Clone)]
pub struct Face {
    /// Stable name, e.g. `"top"`, `"+x"`, `"slope"`.
    pub name: &'static str,
    /// Corner indices into [`BlockShape::corners`], counter-clockwise seen from outside.
    pub corners: Vec<usize>,
    /// Outward unit normal, block frame.
    pub normal: DVec3,
    /// Corner (position in `corners`) to fan-triangulate from; a fan from a reflex corner
    /// covers an L exactly, a fan from corner 0 covers any convex face.
    pub fan_from: usize,
}

/// An edge between two faces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Edge {
    /// Corner indices.
    pub a: usize,
    pub b: usize,
    /// The two faces that meet here (indices into [`BlockShape::faces`]).
    pub faces: [usize; 2],
}

/// The polyhedron of one block.
#[derive(Debug, Clone)]
pub struct BlockShape {
    pub kind: BlockKind,
    /// Bounding box, metres.
    pub size_m: DVec3,
    pub corners: Vec<DVec3>,
    pub faces: Vec<Face>,
    pub edges: Vec<Edge>,
    /// Convex pieces whose union is the solid (one for convex kinds), as cuboids
    /// `(centre, half extents)` or, for the wedge, `None` (use [`BlockShape::corners`] as a hull).
    pub cuboids: Vec<(DVec3, DVec3)>,
}

impl BlockShape {
    pub fn new(kind: BlockKind, size_m: DVec3) -> Self {
        let h = size_m * 0.5;
        let (corners, faces, cuboids) = match kind {
            BlockKind::Cube | BlockKind::Bar => cuboid(h),
            BlockKind::Wedge => wedge(h),
            BlockKind::LBlock => l_block(h),
        };
        let edges = edges_of(&faces);
        Self { kind, size_m, corners, faces, edges, cuboids }
    }

    /// Triangles of one face as corner-index triples (counter-clockwise from outside).
    pub fn face_triangles(&self, face: usize) -> impl Iterator<Item = [usize; 3]> + '_ {
        let f = &self.faces[face];
        let n = f.corners.len();
        (1..n - 1).map(move |k| {
            let i = |j: usize| f.corners[(f.fan_from + j) % n];
            [i(0), i(k), i(k + 1)]
        })
    }

    /// Area of a face, m².
    pub fn face_area_m2(&self, face: usize) -> f64 {
        self.face_triangles(face)
            .map(|[a, b, c]| {
                let (a, b, c) = (self.corners[a], self.corners[b], self.corners[c]);
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }
}

fn face(name: &'static str, corners: &[usize], pts: &[DVec3], fan_from: usize) -> Face {
    // Newell's method: robust normal for any simple polygon, convex or not.
    let mut n = DVec3::ZERO;
    for i in 0..corners.len() {
        let p = pts[corners[i]];
        let q = pts[corners[(i + 1) % corners.len()]];
        n += DVec3::new((p.y - q.y) * (p.z + q.z), (p.z - q.z) * (p.x + q.x), (p.x - q.x) * (p.y + q.y));
    }
    Face { name, corners: corners.to_vec(), normal: n.normalize(), fan_from }
}

type ShapeParts = (Vec<DVec3>, Vec<Face>, Vec<(DVec3, DVec3)>);

fn cuboid(h: DVec3) -> ShapeParts {
    // Corner i has x sign from bit 0, y from bit 1, z from bit 2.
    let pts: Vec<DVec3> = (0..8)
        .map(|i| {
            DVec3::new(
                if i & 1 != 0 { h.x } else { -h.x },
                if i & 2 != 0 { h.y } else { -h.y },
                if i & 4 != 0 { h.z } else { -h.z },
            )
        })
        .collect();
    let faces = vec![
        face("+x", &[1, 3, 7, 5], &pts, 0),
        face("-x", &[0, 4, 6, 2], &pts, 0),
        face("+y", &[2, 6, 7, 3], &pts, 0),
        face("-y", &[0, 1, 5, 4], &pts, 0),
        face("top", &[4, 5, 7, 6], &pts, 0),
        face("bottom", &[0, 2, 3, 1], &pts, 0),
    ];
    (pts, faces, vec![(DVec3::ZERO, h)])
}

fn wedge(h: DVec3) -> ShapeParts {
    // Profile in x-z: A(-x,-z) B(+x,-z) C(+x,+z); extruded to y = -h.y (0..3) and +h.y (3..6).
    let profile = [(-h.x, -h.z), (h.x, -h.z), (h.x, h.z)];
    let mut pts = Vec::new();
    for y in [-h.y, h.y] {
        for (x, z) in profile {
            pts.push(DVec3::new(x, y, z));
        }
    }
    let faces = vec![
        face("-y", &[0, 1, 2], &pts, 0),
        face("+y", &[3, 5, 4], &pts, 0),
        face("bottom", &[0, 3, 4, 1], &pts, 0),
        face("+x", &[1, 4, 5, 2], &pts, 0),
        face("slope", &[0, 2, 5, 3], &pts, 0),
    ];
    (pts, faces, Vec::new())
}

fn l_block(h: DVec3) -> ShapeParts {
    // Profile in x-z, counter-clockwise seen from -y: A(-x,-z) B(+x,-z) C(+x,+z) D(0,+z)
    // E(0,0) F(-x,0); E is the reflex corner. Extruded to y = -h.y (0..6) and +h.y (6..12).
    let profile = [(-h.x, -h.z), (h.x, -h.z), (h.x, h.z), (0.0, h.z), (0.0, 0.0), (-h.x, 0.0)];
    let mut pts = Vec::new();
    for y in [-h.y, h.y] {
        for (x, z) in profile {
            pts.push(DVec3::new(x, y, z));
        }
    }
    let faces = vec![
        face("-y", &[0, 1, 2, 3, 4, 5], &pts, 4),
        // Seen from +y the profile runs the other way round; the reflex corner E is at index 2.
        face("+y", &[6, 11, 10, 9, 8, 7], &pts, 2),
        face("bottom", &[0, 6, 7, 1], &pts, 0),
        face("+x", &[1, 7, 8, 2], &pts, 0),
        face("top", &[2, 8, 9, 3], &pts, 0),
        face("step", &[3, 9, 10, 4], &pts, 0),
        face("low_top", &[4, 10, 11, 5], &pts, 0),
        face("-x", &[5, 11, 6, 0], &pts, 0),
    ];
    // Two cuboids: the low leg over the whole length, the tall leg over the +x half.
    let low = (DVec3::new(0.0, 0.0, -h.z * 0.5), DVec3::new(h.x, h.y, h.z * 0.5));
    let tall = (DVec3::new(h.x * 0.5, 0.0, h.z * 0.5), DVec3::new(h.x * 0.5, h.y, h.z * 0.5));
    (pts, faces, vec![low, tall])
}

fn edges_of(faces: &[Face]) -> Vec<Edge> {
    let mut edges: Vec<Edge> = Vec::new();
    for (fi, f) in faces.iter().enumerate() {
        let n = f.corners.len();
        for i in 0..n {
            let (a, b) = (f.corners[i], f.corners[(i + 1) % n]);
            let key = (a.min(b), a.max(b));
            if let Some(e) = edges.iter_mut().find(|e| (e.a, e.b) == key) {
                e.faces[1] = fi;
            } else {
                edges.push(Edge { a: key.0, b: key.1, faces: [fi, usize::MAX] });
            }
        }
    }
    edges
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check_closed_solid(shape: &BlockShape, volume_m3: f64) {
        // Every edge borders exactly two faces (a closed surface), and the divergence theorem
        // with the outward normals gives the expected volume: catches flipped windings.
        for e in &shape.edges {
            assert!(e.faces[1] != usize::MAX, "{:?} edge {:?} borders one face", shape.kind, e);
            assert_ne!(e.faces[0], e.faces[1]);
        }
        let mut vol = 0.0;
        for (fi, f) in shape.faces.iter().enumerate() {
            let p0 = shape.corners[f.corners[0]];
            vol += p0.dot(f.normal) * shape.face_area_m2(fi) / 3.0;
            for [a, b, c] in shape.face_triangles(fi) {
                let n = (shape.corners[b] - shape.corners[a]).cross(shape.corners[c] - shape.corners[a]);
                assert!(n.dot(f.normal) > 0.0, "{:?} face {} triangle winds inward", shape.kind, f.name);
            }
        }
        assert!((vol - volume_m3).abs() < 1e-12, "{:?}: volume {vol} != {volume_m3}", shape.kind);
    }

    #[test]
    fn shapes_are_closed_with_outward_faces_and_right_volume() {
        let s = DVec3::new(0.04, 0.03, 0.02);
        let v = s.x * s.y * s.z;
        check_closed_solid(&BlockShape::new(BlockKind::Bar, s), v);
        check_closed_solid(&BlockShape::new(BlockKind::Wedge, s), v / 2.0);
        check_closed_solid(&BlockShape::new(BlockKind::LBlock, s), v * 0.75);
        for kind in [BlockKind::Cube, BlockKind::Bar, BlockKind::Wedge, BlockKind::LBlock] {
            let shape = BlockShape::new(kind, s);
            assert_eq!(shape.faces.len(), kind.face_count());
        }
    }

    #[test]
    fn l_block_cuboids_cover_its_volume() {
        let s = DVec3::new(0.04, 0.03, 0.02);
        let shape = BlockShape::new(BlockKind::LBlock, s);
        let vol: f64 = shape.cuboids.iter().map(|(_, h)| 8.0 * h.x * h.y * h.z).sum();
        assert!((vol - 0.75 * s.x * s.y * s.z).abs() < 1e-12);
    }
}
