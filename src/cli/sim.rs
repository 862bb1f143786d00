use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct SimArgs {}

pub fn run(_args: SimArgs) -> Result<()> {
    bail!("'handeye sim' is not built yet (issue #3)")
}
