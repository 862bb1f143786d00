//! What the servo did, for telemetry, the outcome and the report's plot; and the grip the
//! grasp ended with.

use serde::{Deserialize, Serialize};

/// One servo step for the report's plot.
///
/// A step that failed has no offset (NaN), and one taken outside a measurement no error:
/// JSON has no NaN, so these are written as `null` and read back as NaN.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ServoTraceRow {
    pub step: u32,
    pub frame: u64,
    /// `[π1, π2, π3, s − s*, t − t*, ρ]`.
    #[serde(deserialize_with = "nan_if_null::array6")]
    pub error: [f64; 6],
    /// Estimated remaining offset: translation norm (m) and yaw (rad).
    #[serde(deserialize_with = "nan_if_null::value")]
    pub offset_m: f64,
    #[serde(deserialize_with = "nan_if_null::value")]
    pub offset_yaw_rad: f64,
}

/// Reading back the `null` serde_json writes for a NaN.
mod nan_if_null {
    use serde::{Deserialize, Deserializer};

    pub fn value<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
    }

    pub fn array6<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 6], D::Error> {
        Ok(<[Option<f64>; 6]>::deserialize(d)?.map(|v| v.unwrap_or(f64::NAN)))
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_steps_nan_offset_and_error_survive_the_json_round_trip() {
        // A servo that fails on its first step has no offset: daemon.json holds `null` there,
        // and reading it back failed ("invalid type: null, expected f64"), so the run's
        // report was lost and the batch counted a process failure (clutter3 seed 121).
        let row = ServoTraceRow { step: 1, frame: 1307, error: [0.5, f64::NAN, 0.0, 0.0, 0.0, 0.1], offset_m: f64::NAN, offset_yaw_rad: f64::NAN };
        let text = serde_json::to_string(&row).unwrap();
        assert!(text.contains("\"offset_m\":null"), "{text}");
        let back: ServoTraceRow = serde_json::from_str(&text).unwrap();
        assert!(back.offset_m.is_nan() && back.offset_yaw_rad.is_nan() && back.error[1].is_nan());
        assert_eq!((back.step, back.frame, back.error[0], back.error[5]), (1, 1307, 0.5, 0.1));
    }
}
