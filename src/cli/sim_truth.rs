//! `handeye sim --truth-out FILE.jsonl`: the hinted facet's true outline in both views, one
//! JSON line per published frame, written beside a recording for tests that judge a
//! tracker against ground truth. The daemon never reads it (it is no service, only a file).
//!
//! Each line: `{"frame_id", "sim_time_ns", "block", "face", "left_px", "right_px"}` with the
//! facet's corners projected by the simulator's cameras (pixel centres at integers, the
//! hint's corner order), computed after the frame was published and before physics moves
//! on, so it is the frame's geometry. Occlusion is not judged here: a line is the whole face.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};
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
    /// The first write error (the run goes on; it is reported at the end).
    error: Option<std::io::Error>,
}

impl TruthWriter {
    pub fn create(path: &Path, block: usize, face: usize, inner: Option<Box<dyn Driver>>) -> Result<Self> {
        let out = BufWriter::new(File::create(path).with_context(|| format!("creating {}", path.display()))?);
        Ok(Self { inner, out, block, face, error: None })
    }

    /// Flushes the file; the first error met while writing, if any.
    pub fn finish(mut self, path: &Path) -> Result<()> {
        if let Some(e) = self.error.take() {
            return Err(e).with_context(|| format!("writing {}", path.display()));
        }
        self.out.flush().with_context(|| format!("writing {}", path.display()))
    }

    fn line(&self, sim: &Simulator, frame_id: u64) -> serde_json::Value {
        let b = &sim.world.blocks[self.block];
        let (_, pose) = sim.block_pose(self.block);
        let face = &b.shape.faces[self.face];
        let views: Vec<Vec<[f64; 2]>> = sim
            .events
            .cameras
            .iter()
            .map(|cam| face.corners.iter().filter_map(|&c| cam.project(pose.transform_point3(b.shape.corners[c]))).collect())
            .collect();
        serde_json::json!({
            "frame_id": frame_id,
            "sim_time_ns": sim.now_ns(),
            "block": b.name,
            "face": face.name,
            "left_px": views[0],
            "right_px": views[1],
        })
    }
}

impl Driver for TruthWriter {
    fn command(&mut self, sim: &mut Simulator, frame_id: u64) -> Option<RobotCommand> {
        let line = self.line(sim, frame_id);
        if self.error.is_none()
            && let Err(e) = writeln!(self.out, "{line}")
        {
            self.error = Some(e);
        }
        self.inner.as_mut().and_then(|d| d.command(sim, frame_id))
    }
}
