use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct SnapshotArgs {}

pub fn run(_args: SnapshotArgs) -> Result<()> {
    bail!("'handeye snapshot' is not built yet (issue #3)")
}
