use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct RenderArgs {}

pub fn run(_args: RenderArgs) -> Result<()> {
    bail!("'handeye bench render' is not built yet (issue #3)")
}
