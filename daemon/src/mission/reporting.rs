//! What the phases tell the operator: the status text for telemetry, and the report
//! material a cycle produced (a snapshot label, the plan with its images), handed out with
//! the cycle's command.

use crate::planning::PlanOutput;

/// Report material one cycle produced, for whoever writes the report.
#[derive(Debug, Default)]
pub struct ReportRequests {
    /// A snapshot of this cycle's frames was asked for, with this label.
    pub snapshot: Option<&'static str>,
    /// The plan with its images.
    pub plan: Option<Box<PlanOutput>>,
}

/// Status text and report requests. The status buffer is allocated once.
#[derive(Debug)]
pub struct Reporting {
    status: String,
    requests: ReportRequests,
}

impl Default for Reporting {
    fn default() -> Self {
        Self { status: String::with_capacity(128), requests: ReportRequests::default() }
    }
}

impl Reporting {
    /// Sets the status text without allocating (when it fits the buffer).
    pub fn set_status(&mut self, text: &str) {
        self.status.clear();
        self.status.push_str(text);
    }

    pub fn status(&self) -> &str {
        &self.status
    }

    /// Asks for a snapshot of this cycle's frames (the last ask of a cycle wins).
    pub fn snapshot(&mut self, label: &'static str) {
        self.requests.snapshot = Some(label);
    }

    /// Hands the plan with its images to the report.
    pub fn plan(&mut self, plan: Box<PlanOutput>) {
        self.requests.plan = Some(plan);
    }

    /// What was asked for since the last call.
    pub fn take_requests(&mut self) -> ReportRequests {
        std::mem::take(&mut self.requests)
    }
}
