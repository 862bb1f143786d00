use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct BatchArgs {}

pub fn run(_args: BatchArgs) -> Result<()> {
    bail!("'handeye batch' is not built yet (issue #7)")
}
