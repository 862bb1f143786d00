//! Domains keep separate handeye systems (or parallel test runs) from seeing each other's
//! services, and [`WireNode`] is the one iceoryx2 node a process uses inside a domain.
//!
//! A domain name becomes the iceoryx2 file prefix `iox2_<domain>_`: every shared-memory
//! segment in `/dev/shm` and every management file under `/tmp/iceoryx2/` of that domain
//! starts with it. Two processes talk only if they use the same domain.

use std::rc::Rc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Once;
use std::time::Duration;

use iceoryx2::config::Config;
use iceoryx2::node::NodeCreationFailure;
use iceoryx2::prelude::*;
use thiserror::Error;

/// Environment variable that names the domain when no `--domain` flag is given.
pub const DOMAIN_ENV: &str = "HANDEYE_DOMAIN";
/// The domain used when neither `--domain` nor `HANDEYE_DOMAIN` names one.
pub const DEFAULT_DOMAIN: &str = "handeye";
/// Longest domain name accepted (iceoryx2 builds file names from it).
pub const MAX_DOMAIN_LEN: usize = 32;

/// Why a domain name was refused.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum DomainError {
    #[error("domain name is empty")]
    Empty,
    #[error("domain name '{name}' is longer than {MAX_DOMAIN_LEN} characters")]
    TooLong { name: String },
    #[error(
        "domain name '{name}' contains '{bad}': use lower-case letters, digits and '-' only \
         (no '_', which separates the domain in shared-memory file names)"
    )]
    BadChar { name: String, bad: char },
}

/// A validated domain name: 1 to 32 characters of `a-z`, `0-9` and `-`.
///
/// ```
/// use handeye_wire::Domain;
/// let d = Domain::new("test-42").unwrap();
/// assert_eq!(d.prefix(), "iox2_test-42_");
/// assert!(Domain::new("Bad_Name").is_err());
/// ```
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Domain {
    name: String,
}

impl Domain {
    pub fn new(name: &str) -> Result<Self, DomainError> {
        if name.is_empty() {
            return Err(DomainError::Empty);
        }
        if name.len() > MAX_DOMAIN_LEN {
            return Err(DomainError::TooLong { name: name.to_owned() });
        }
        if let Some(bad) = name.chars().find(|c| !(c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '-')) {
            return Err(DomainError::BadChar { name: name.to_owned(), bad });
        }
        Ok(Self { name: name.to_owned() })
    }

    /// The domain named by `HANDEYE_DOMAIN`, or [`DEFAULT_DOMAIN`] when it is unset.
    pub fn from_env() -> Result<Self, DomainError> {
        match std::env::var(DOMAIN_ENV) {
            Ok(name) => Self::new(&name),
            Err(_) => Self::new(DEFAULT_DOMAIN),
        }
    }

    /// A fresh domain for one test or benchmark run: `<stem>-<pid>-<counter>`, so that parallel
    /// runs never share services. `stem` is cut to keep the name within the length limit.
    pub fn unique(stem: &str) -> Self {
        static COUNTER: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let nanos = crate::monotonic_ns() % 1_000_000;
        let tail = format!("-{}-{n}-{nanos}", std::process::id());
        let stem: String = stem
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_lowercase() } else { '-' })
            .take(MAX_DOMAIN_LEN.saturating_sub(tail.len()))
            .collect();
        let stem = if stem.is_empty() { "t".to_owned() } else { stem };
        Self { name: format!("{stem}{tail}") }
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// The iceoryx2 file prefix of this domain, `iox2_<name>_`.
    pub fn prefix(&self) -> String {
        format!("iox2_{}_", self.name)
    }

    /// The iceoryx2 configuration every handeye node of this domain uses: iceoryx2's defaults
    /// with the domain prefix. Built in code, so no config file is read (and iceoryx2's
    /// "No config file was loaded" warning never appears).
    pub fn iceoryx2_config(&self) -> Config {
        let mut cfg = Config::default();
        // The name was validated to be short ASCII without '/', so it is a valid file name.
        cfg.global.prefix = FileName::new(self.prefix().as_bytes())
            .unwrap_or_else(|e| panic!("validated domain prefix rejected by iceoryx2: {e:?}"));
        cfg
    }
}

impl std::fmt::Display for Domain {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name)
    }
}

impl std::str::FromStr for Domain {
    type Err = DomainError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::new(s)
    }
}

/// Why a [`WireNode`] could not be created.
#[derive(Debug, Error)]
pub enum NodeError {
    #[error("node name '{name}' is not valid for iceoryx2")]
    BadName { name: String },
    #[error(
        "could not create the iceoryx2 node '{name}' in domain '{domain}' ({source}); \
         check that /dev/shm and /tmp/iceoryx2 are writable"
    )]
    Create { name: String, domain: String, source: NodeCreationFailure },
}

/// Set once a SIGINT or SIGTERM has been seen; iceoryx2 reports each signal only once.
static TERMINATION: AtomicBool = AtomicBool::new(false);
static LOG_INIT: Once = Once::new();

/// Sets iceoryx2's own log level once per process: `IOX2_LOG_LEVEL` if set, else `Warn`.
pub fn init_iceoryx2_logging() {
    LOG_INIT.call_once(|| set_log_level_from_env_or(LogLevel::Warn));
}

pub(crate) struct NodeInner {
    pub(crate) node: Node<ipc::Service>,
    pub(crate) domain: Domain,
}

/// The iceoryx2 node of one process in one domain. Cheap to clone (shared); not `Send`, like
/// every iceoryx2 `ipc::Service` port: keep it, and the ports made from it, on one thread.
///
/// Creating a node installs iceoryx2's SIGINT/SIGTERM handler: Ctrl-C no longer kills the
/// process but is reported by [`WireNode::termination_requested`] (and by the waits of the
/// publishers and subscribers), so every loop ends cleanly and releases its shared memory.
#[derive(Clone)]
pub struct WireNode {
    pub(crate) inner: Rc<NodeInner>,
}

impl WireNode {
    /// Creates a node called `name` (shown by iceoryx2 tools) in `domain`. Removes the stale
    /// resources of dead nodes of this domain on the way (iceoryx2's default).
    pub fn create(domain: &Domain, name: &str) -> Result<Self, NodeError> {
        init_iceoryx2_logging();
        let node_name = NodeName::new(name).map_err(|_| NodeError::BadName { name: name.to_owned() })?;
        let node = NodeBuilder::new()
            .name(&node_name)
            .config(&domain.iceoryx2_config())
            .create::<ipc::Service>()
            .map_err(|source| NodeError::Create { name: name.to_owned(), domain: domain.to_string(), source })?;
        // iceoryx2 installs its signal handler lazily, on the first termination check: do it
        // now so that Ctrl-C is caught from the start.
        if node.wait(Duration::ZERO).is_err() {
            TERMINATION.store(true, Ordering::Relaxed);
        }
        Ok(Self { inner: Rc::new(NodeInner { node, domain: domain.clone() }) })
    }

    pub fn domain(&self) -> &Domain {
        &self.inner.domain
    }

    /// The underlying iceoryx2 node, for services this crate does not wrap.
    pub fn iceoryx2(&self) -> &Node<ipc::Service> {
        &self.inner.node
    }

    /// True once SIGINT or SIGTERM has been received by this process (sticky).
    pub fn termination_requested(&self) -> bool {
        if TERMINATION.load(Ordering::Relaxed) {
            return true;
        }
        if self.inner.node.wait(Duration::ZERO).is_err() {
            TERMINATION.store(true, Ordering::Relaxed);
            return true;
        }
        false
    }

    /// Sleeps for `d`; returns `false` (early) when termination was requested.
    pub fn sleep(&self, d: Duration) -> bool {
        if self.termination_requested() {
            return false;
        }
        if self.inner.node.wait(d).is_err() {
            TERMINATION.store(true, Ordering::Relaxed);
            return false;
        }
        true
    }

    /// Removes the resources of dead nodes (SIGKILLed processes) of this domain; returns how
    /// many were removed. Publishers and subscribers call this themselves when they need to.
    pub fn cleanup_dead_nodes(&self) -> usize {
        self.inner.node.try_cleanup_dead_nodes().cleanups as usize
    }
}

/// Removes every file of `domain` from `/dev/shm` and from iceoryx2's root directory
/// (`/tmp/iceoryx2/`), returning how many were removed.
///
/// Only for domains that no process uses any more — tests call it when they finish, because
/// iceoryx2 deliberately leaves one small management segment per domain behind. Never call it
/// for a domain in use: the running processes would lose their shared memory.
pub fn remove_domain_files(domain: &Domain) -> std::io::Result<usize> {
    let prefix = domain.prefix();
    let root = domain.iceoryx2_config().global.root_path().to_string();
    let mut removed = 0;
    removed += remove_prefixed(std::path::Path::new("/dev/shm"), &prefix, false)?;
    removed += remove_prefixed(std::path::Path::new(&root), &prefix, true)?;
    Ok(removed)
}

fn remove_prefixed(dir: &std::path::Path, prefix: &str, recurse: bool) -> std::io::Result<usize> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(e),
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let path = entry.path();
        let Ok(kind) = entry.file_type() else { continue };
        let name = entry.file_name();
        let matches = name.to_string_lossy().starts_with(prefix);
        if kind.is_dir() {
            if matches {
                std::fs::remove_dir_all(&path)?;
                removed += 1;
            } else if recurse {
                removed += remove_prefixed(&path, prefix, true)?;
            }
        } else if matches {
            match std::fs::remove_file(&path) {
                Ok(()) => removed += 1,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e),
            }
        }
    }
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn domain_names_are_checked() {
        assert_eq!(Domain::new(""), Err(DomainError::Empty));
        assert!(matches!(Domain::new("a_b"), Err(DomainError::BadChar { bad: '_', .. })));
        assert!(matches!(Domain::new("A"), Err(DomainError::BadChar { bad: 'A', .. })));
        assert!(matches!(Domain::new("a/b"), Err(DomainError::BadChar { bad: '/', .. })));
        assert!(matches!(Domain::new(&"x".repeat(33)), Err(DomainError::TooLong { .. })));
        assert_eq!(Domain::new("cam-2").unwrap().name(), "cam-2");
    }

    #[test]
    fn prefixes_of_different_domains_never_prefix_each_other() {
        // remove_domain_files relies on this: "a" must not match files of "a-b".
        let a = Domain::new("a").unwrap().prefix();
        let ab = Domain::new("a-b").unwrap().prefix();
        assert!(!ab.starts_with(&a) && !a.starts_with(&ab));
    }

    #[test]
    fn unique_domains_are_valid_and_distinct() {
        let a = Domain::unique("Some Test_Name that is quite long indeed");
        let b = Domain::unique("Some Test_Name that is quite long indeed");
        assert_ne!(a, b);
        assert!(Domain::new(a.name()).is_ok(), "{a}");
        assert!(a.name().len() <= MAX_DOMAIN_LEN);
    }

    #[test]
    fn config_carries_the_prefix() {
        let d = Domain::new("pfx").unwrap();
        assert_eq!(d.iceoryx2_config().global.prefix.to_string(), "iox2_pfx_");
    }
}
