use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct TransportArgs {}

pub fn run(_args: TransportArgs) -> Result<()> {
    bail!("'handeye bench transport' is not built yet (issue #2)")
}
