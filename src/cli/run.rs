use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct RunArgs {}

pub fn run(_args: RunArgs) -> Result<()> {
    bail!("'handeye run' is not built yet (issue #5)")
}
