//! What the servo did, for telemetry, the outcome and the report's plot; and the grip the
//! grasp ended with.

use serde::{Deserialize, Serialize};

/// One servo step for the report's plot.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ServoTraceRow {
    pub step: u32,
    pub frame: u64,
    /// `[π1, π2, π3, s − s*, t − t*, ρ]`.
    pub error: [f64; 6],
    /// Estimated remaining offset: translation norm (m) and yaw (rad).
    pub offset_m: f64,
    pub offset_yaw_rad: f64,
}

/// The servo's record. Allocated up front: recording a step allocates nothing.
#[derive(Debug)]
pub struct ServoRecord {
    trace: Vec<ServoTraceRow>,
    steps: u32,
    /// Last measured servo error (NaN outside the servo).
    error: [f64; 6],
    /// Jaw opening after closing on the target, m.
    grip_width_m: Option<f64>,
    /// How the block moved in the jaws while lifted, in words (`phase/grasp.rs`).
    held_block_moved: Option<String>,
}

impl ServoRecord {
    /// Room for `max_steps` steps (and two more).
    pub fn new(max_steps: u32) -> Self {
        Self { trace: Vec::with_capacity(max_steps as usize + 2), steps: 0, error: [f64::NAN; 6], grip_width_m: None, held_block_moved: None }
    }

    /// A new servo starts: the trace and the step count begin again.
    pub fn restart(&mut self) {
        self.trace.clear();
        self.steps = 0;
    }

    pub fn set_steps(&mut self, steps: u32) {
        self.steps = steps;
    }

    /// The error measured at this step.
    pub fn set_error(&mut self, error: &[f64]) {
        for (dst, src) in self.error.iter_mut().zip(error) {
            *dst = *src;
        }
    }

    /// Adds a row to the trace while it has room (it never grows).
    pub fn push(&mut self, row: ServoTraceRow) {
        if self.trace.len() < self.trace.capacity() {
            self.trace.push(row);
        }
    }

    pub fn steps(&self) -> u32 {
        self.steps
    }

    pub fn error(&self) -> [f64; 6] {
        self.error
    }

    pub fn trace(&self) -> &[ServoTraceRow] {
        &self.trace
    }

    pub fn set_grip_width_m(&mut self, width_m: f64) {
        self.grip_width_m = Some(width_m);
    }

    pub fn grip_width_m(&self) -> Option<f64> {
        self.grip_width_m
    }

    pub fn set_held_block_moved(&mut self, words: String) {
        self.held_block_moved = Some(words);
    }

    pub fn held_block_moved(&self) -> Option<&str> {
        self.held_block_moved.as_deref()
    }
}
