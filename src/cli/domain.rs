//! The `--domain` flag shared by every subcommand that joins the shared-memory services.

use clap::Args;
use handeye_wire::Domain;

/// Flatten into a subcommand's arguments: `#[command(flatten)] domain: DomainArgs`.
#[derive(Args, Debug, Clone)]
pub struct DomainArgs {
    /// Shared-memory domain to join. Processes see each other's services only within one
    /// domain (its files in /dev/shm start with `iox2_<domain>_`), so separate systems or test
    /// runs on one machine never mix. Lower-case letters, digits and '-', at most 32.
    #[arg(long, env = "HANDEYE_DOMAIN", default_value = handeye_wire::DEFAULT_DOMAIN, value_name = "NAME")]
    pub domain: Domain,
}
