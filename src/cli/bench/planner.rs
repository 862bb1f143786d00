use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct PlannerArgs {}

pub fn run(_args: PlannerArgs) -> Result<()> {
    bail!("'handeye bench planner' is not built yet (issue #6)")
}
