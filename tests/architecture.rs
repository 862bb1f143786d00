//! The architecture rules the issue asks for, checked on the source text (plain std, no
//! parser crate): no import loop between the source files of any crate, no struct with more
//! than ten public fields in the daemon, and every relative Markdown link resolving inside
//! the repository.
//!
//! The import graph is approximate by design: it reads `use` trees and qualified paths
//! (`crate::x::f`, `super::X`, `child::g`) after stripping comments and literals, walks the
//! module tree as far as a path goes and follows `pub use` re-exports to the module that
//! defines an item. It does not expand macros or resolve method calls, so it can miss an
//! edge but does not invent one; a loop it reports is real.

mod architecture_support;

use std::path::{Path, PathBuf};

use architecture_support::{imports, links, structs};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The crates' source roots, each with its root file.
const CRATES: [(&str, &str); 5] = [
    ("wire/src", "lib.rs"),
    ("vision/src", "lib.rs"),
    ("sim/src", "lib.rs"),
    ("daemon/src", "lib.rs"),
    ("src", "main.rs"),
];

#[test]
fn no_crate_has_an_import_loop() {
    let root = repo();
    let mut report = Vec::new();
    for (src, root_file) in CRATES {
        let graph = imports::CrateGraph::load(&root, Path::new(src), root_file)
            .unwrap_or_else(|e| panic!("{src}: {e}"));
        for cycle in graph.cycles() {
            report.push(format!("{src}: {}", cycle.join(" -> ")));
        }
    }
    assert!(report.is_empty(), "import loops (file -> file it names an item of):\n  {}", report.join("\n  "));
}

#[test]
fn no_daemon_struct_has_more_than_ten_public_fields() {
    let root = repo();
    let mut offenders = Vec::new();
    for file in structs::rust_files(&root.join("daemon/src")) {
        let text = std::fs::read_to_string(&file).unwrap();
        for s in structs::public_field_counts(&text) {
            if s.public_fields > 10 {
                let rel = file.strip_prefix(&root).unwrap_or(&file);
                offenders.push(format!("{}: {} ({} public fields)", rel.display(), s.name, s.public_fields));
            }
        }
    }
    assert!(offenders.is_empty(), "structs with more than 10 public fields:\n  {}", offenders.join("\n  "));
}

#[test]
fn markdown_links_resolve_inside_the_repository() {
    let root = repo();
    let broken = links::broken_links(&root);
    assert!(broken.is_empty(), "Markdown links that do not resolve inside the repository:\n  {}", broken.join("\n  "));
}
