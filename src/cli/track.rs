use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct TrackArgs {}

pub fn run(_args: TrackArgs) -> Result<()> {
    bail!("'handeye track' is not built yet (issue #4)")
}
