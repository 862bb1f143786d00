//! `handeye sim --truth-out FILE.jsonl`: the hinted facet's true outline in both views, one
//! JSON line per published frame, written beside a recording for tests that judge a
//! tracker against ground truth. The daemon never reads it (it is no service, only a file).
//!
//! Each line: `{"frame_id", "sim_time_ns", "block", "face", "left_px", "right_px",
//! "occluded_px"}` with the facet's corners projected by the simulator's cameras (pixel
//! centres at integers, the hint's corner order), computed after the frame was published and
//! before physics moves on, so it is the frame's geometry. `occluded_px` (per view) counts
//! the pixels well inside the polygon (at least 1 px from its edges) where the renderer's
//! face-id pass shows something else than the facet: 0 means unoccluded. The id pass is a
//! second renderer of the writer's own (the truth costs a render per frame; tests only).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};
use handeye_sim::render::Renderer;
use handeye_sim::render::scene::block_face_id;
use handeye_sim::run::Driver;
use handeye_sim::simulator::Simulator;
use handeye_wire::RobotCommand;

/// Writes the truth line of every frame it is asked about, then lets `inner` (if any)
/// answer the frame.
pub struct TruthWriter {
    inner: Option<Box<dyn Driver>>,
    out: BufWriter<File>,
    block: usize,
    face: usize,
    /// The first write or render error (the run goes on; it is reported at the end).
    error: Option<anyhow::Error>,
    /// The face-id renderer (started at the first frame) and its buffers.
    ids: Option<(Renderer, Vec<u32>)>,
}

impl TruthWriter {
    pub fn create(path: &Path, block: usize, face: usize, inner: Option<Box<dyn Driver>>) -> Result<Self> {
        let out = BufWriter::new(File::create(path).with_context(|| format!("creating {}", path.display()))?);
        Ok(Self { inner, out, block, face, error: None, ids: None })
    }

    /// Flushes the file; the first error met while writing, if any.
    pub fn finish(mut self, path: &Path) -> Result<()> {
        if let Some(e) = self.error.take() {
            return Err(e.context(format!("writing {}", path.display())));
        }
        self.out.flush().with_context(|| format!("writing {}", path.display()))
    }

    /// Per view, the pixels well inside `polygons` that show something else than the facet.
    fn occluded_px(&mut self, sim: &Simulator, polygons: &[Vec<[f64; 2]>]) -> Result<[u64; 2]> {
        if self.ids.is_none() {
            let r = Renderer::for_scene_with(&sim.scene, &sim.events.cameras, false).context("starting the truth's face-id renderer")?;
            let n = r.frame_bytes();
            self.ids = Some((r, vec![0; n]));
        }
        let Some((renderer, ids)) = self.ids.as_mut() else { return Ok([0; 2]) };
        let mut poses = Vec::new();
        sim.object_poses(&mut poses);
        renderer.render_ids(&sim.frame_input(&poses), ids)?;
        let (w, h) = (renderer.width() as usize, renderer.height() as usize);
        let id = block_face_id(self.block, self.face);
        let mut out = [0u64; 2];
        for (v, poly) in polygons.iter().enumerate().take(2) {
            let plane = &ids[v * w * h..(v + 1) * w * h];
            let (x0, x1) = poly.iter().fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p[0]), a.1.max(p[0])));
            let (y0, y1) = poly.iter().fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p[1]), a.1.max(p[1])));
            for y in (y0.ceil().max(0.0) as usize)..=(y1.floor().min(h as f64 - 1.0).max(0.0) as usize) {
                for x in (x0.ceil().max(0.0) as usize)..=(x1.floor().min(w as f64 - 1.0).max(0.0) as usize) {
                    if inside_by(poly, [x as f64, y as f64], 1.0) && plane[y * w + x] != id {
                        out[v] += 1;
                    }
                }
            }
        }
        Ok(out)
    }

    fn line(&mut self, sim: &Simulator, frame_id: u64) -> serde_json::Value {
        let b = &sim.world.blocks[self.block];
        let (_, pose) = sim.block_pose(self.block);
        let face = &b.shape.faces[self.face];
        let views: Vec<Vec<[f64; 2]>> = sim
            .events
            .cameras
            .iter()
            .map(|cam| face.corners.iter().filter_map(|&c| cam.project(pose.transform_point3(b.shape.corners[c]))).collect())
            .collect();
        let occluded = match self.occluded_px(sim, &views) {
            Ok(o) => serde_json::json!(o),
            Err(e) => {
                self.error.get_or_insert(e);
                serde_json::Value::Null
            }
        };
        serde_json::json!({
            "frame_id": frame_id,
            "sim_time_ns": sim.now_ns(),
            "block": b.name,
            "face": face.name,
            "left_px": views[0],
            "right_px": views[1],
            "occluded_px": occluded,
        })
    }
}

impl Driver for TruthWriter {
    fn command(&mut self, sim: &mut Simulator, frame_id: u64) -> Option<RobotCommand> {
        let line = self.line(sim, frame_id);
        if self.error.is_none()
            && let Err(e) = writeln!(self.out, "{line}")
        {
            self.error = Some(e.into());
        }
        self.inner.as_mut().and_then(|d| d.command(sim, frame_id))
    }
}

/// Whether `p` lies inside the convex polygon `poly` at least `margin` px from every edge
/// (either winding).
fn inside_by(poly: &[[f64; 2]], p: [f64; 2], margin: f64) -> bool {
    let n = poly.len();
    if n < 3 {
        return false;
    }
    let area2: f64 = (0..n).map(|i| poly[i][0] * poly[(i + 1) % n][1] - poly[(i + 1) % n][0] * poly[i][1]).sum();
    let sign = area2.signum();
    (0..n).all(|i| {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
        let len = ex.hypot(ey);
        len > 0.0 && sign * (ex * (p[1] - a[1]) - ey * (p[0] - a[0])) / len >= margin
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inside_by_keeps_a_margin_from_every_edge_in_either_winding() {
        let square = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        let reversed: Vec<[f64; 2]> = square.iter().rev().copied().collect();
        for poly in [&square[..], &reversed[..]] {
            assert!(inside_by(poly, [5.0, 5.0], 1.0));
            assert!(inside_by(poly, [1.0, 5.0], 1.0));
            assert!(!inside_by(poly, [0.5, 5.0], 1.0));
            assert!(!inside_by(poly, [11.0, 5.0], 1.0));
        }
    }
}
