use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct DaemonArgs {}

pub fn run(_args: DaemonArgs) -> Result<()> {
    bail!("'handeye daemon' is not built yet (issue #5)")
}
