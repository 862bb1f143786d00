//! A failure as the daemon raises it: what kind of failure, and the sentence for the
//! operator. Whoever raises one classifies it there, where the cause is known; the hard loop
//! adds the phase it happened in and reports it as a [`handeye_wire::report::Failure`], so
//! that `handeye batch` groups runs with a `match` instead of reading their text.

use handeye_wire::report::{Failure, FailureKind};
use handeye_wire::Phase;

/// Why the arm stops: the kind, and the detail worded for the operator (it also goes into
/// the telemetry's reason, 96 bytes).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{detail}")]
pub struct Fault {
    pub kind: FailureKind,
    pub detail: String,
}

impl Fault {
    pub fn new(kind: FailureKind, detail: impl Into<String>) -> Self {
        Self { kind, detail: detail.into() }
    }

    /// The report's failure: this fault, raised in `phase`.
    pub fn in_phase(self, phase: Phase) -> Failure {
        Failure::new(phase.name(), self.kind, self.detail)
    }
}
