use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct FeedArgs {}

pub fn run(_args: FeedArgs) -> Result<()> {
    bail!("'handeye feed' is not built yet (issue #2)")
}
