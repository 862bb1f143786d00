use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct PlanArgs {}

pub fn run(_args: PlanArgs) -> Result<()> {
    bail!("'handeye plan' is not built yet (issue #6)")
}
