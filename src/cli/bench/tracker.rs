use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct TrackerArgs {}

pub fn run(_args: TrackerArgs) -> Result<()> {
    bail!("'handeye bench tracker' is not built yet (issue #4)")
}
