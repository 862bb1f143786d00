use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct MonitorArgs {}

pub fn run(_args: MonitorArgs) -> Result<()> {
    bail!("'handeye monitor' is not built yet (issue #2)")
}
