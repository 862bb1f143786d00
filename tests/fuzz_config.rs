//! Fuzzing the TOML decoders (issue 21): scenario files (`Scenario::parse`) and
//! `daemon.toml` (`DaemonConfig::parse`). Inputs are random text and the shipped files
//! with one node of their tree edited (a value replaced by an interesting one or by raw
//! TOML, removed, repeated up to 2000 times, nested, an unknown key added) and/or bytes
//! edited. No input may panic or allocate without bound; each rejection is counted under
//! the field it names (its top-level key or table), `syntax` / `parse` for text that is not
//! TOML or has a value of the wrong type, `unknown_field` / `unknown_key` for a misspelling.
//!
//! `make test` runs the short tests; `make fuzz` the `#[ignore]`d `*_long` ones.

// Decoders take `&S::Value` of their proptest strategy (`&String`, `&Vec<u8>`).
#![allow(clippy::ptr_arg)]

mod fuzz_support;

use std::path::Path;

use fuzz_support::mutate::{byte_edits, edit_text, edit_toml, node_edit};
use fuzz_support::{assert_coverage, Fuzz, Outcome};
use handeye_daemon::config::{ConfigError, DaemonConfig};
use handeye_sim::Scenario;
use proptest::prelude::*;

/// TOML text where a value breaks: numbers no type holds, special floats, bad tokens.
const TOML_RAW: &[&str] = &[
    "nan", "-inf", "inf", "1e999", "9223372036854775808", "-9223372036854775809", "0x7fffffffffffffff", "1979-05-27T07:32:00Z", "{}", "[[]]", "[1, \"a\"]", "'''", "\"\\u0000\"", "=",
];

/// Random text, or one of `bases` with a tree edit and/or byte edits.
fn toml_inputs(bases: Vec<String>) -> impl Strategy<Value = String> {
    let tables: Vec<toml::Table> = bases.iter().map(|t| t.parse().expect("base files are TOML")).collect();
    let n = tables.len();
    let tables2 = tables.clone();
    let tree = (0..n, any::<usize>(), node_edit(TOML_RAW)).prop_map(move |(i, pick, edit)| edit_toml(&tables[i], pick, &edit));
    let tree_and_bytes = (0..n, any::<usize>(), node_edit(TOML_RAW), byte_edits(2)).prop_map(move |(i, pick, edit, b)| edit_text(&edit_toml(&tables2[i], pick, &edit), &b));
    let bytes = (0..n, byte_edits(4)).prop_map(move |(i, b)| edit_text(&bases[i], &b));
    prop_oneof![
        1 => prop::collection::vec(any::<u8>(), 0..400).prop_map(|b| String::from_utf8_lossy(&b).into_owned()),
        4 => tree,
        2 => tree_and_bytes,
        2 => bytes,
    ]
}

/// The parser builds the document: a bounded multiple of the text's length.
fn toml_alloc_bound(text: &String) -> usize {
    (1 << 20) + 64 * text.len()
}

fn shipped_scenarios() -> Vec<String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios");
    let mut files: Vec<_> = std::fs::read_dir(&dir).expect("scenarios/").filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.extension().is_some_and(|x| x == "toml")).collect();
    files.sort();
    files.iter().map(|p| std::fs::read_to_string(p).expect("scenario")).collect()
}

fn decode_scenario(text: &String) -> Outcome {
    match Scenario::parse(text, Path::new("fuzz.toml")) {
        Ok(_) => Ok(()),
        Err(e) if e.message.is_empty() => Err(String::new()),
        Err(e) if e.message.starts_with("unknown field") => Err("unknown_field".into()),
        Err(e) => {
            let root = e.field.trim_start_matches('(').split(['.', '[', ')']).next().unwrap_or_default();
            Err(if root.is_empty() { "(top level)".into() } else { root.to_string() })
        }
    }
}

#[test]
fn scenario_toml() {
    let counts = Fuzz::short("scenario_toml", 3000).run(toml_inputs(shipped_scenarios()), toml_alloc_bound, decode_scenario);
    assert_coverage("scenario_toml", &counts, &["syntax", "unknown_field", "blocks", "cameras"]);
}

#[test]
#[ignore = "long fuzz run: make fuzz"]
fn scenario_toml_long() {
    Fuzz::long("scenario_toml").run(toml_inputs(shipped_scenarios()), toml_alloc_bound, decode_scenario);
}

fn decode_daemon_toml(text: &String) -> Outcome {
    match DaemonConfig::parse(text, Path::new("daemon.toml")) {
        Ok(cfg) => {
            // What `handeye run` does with an accepted configuration: write it back out.
            let _ = cfg.to_toml();
            Ok(())
        }
        Err(ConfigError::Parse { message, .. }) if message.is_empty() => Err(String::new()),
        Err(ConfigError::Parse { message, .. }) if message.starts_with("unknown key") => Err("unknown_key".into()),
        Err(ConfigError::Parse { .. }) => Err("parse".into()),
        // Counted by table (`plan`, `tracker`, ...; top-level keys by name).
        Err(ConfigError::Invalid { field, .. }) => Err(field.split('.').next().unwrap_or(field).into()),
        Err(ConfigError::Read { .. }) => Err("read".into()),
    }
}

fn daemon_bases() -> Vec<String> {
    vec![DaemonConfig::default().to_toml()]
}

#[test]
fn daemon_toml() {
    let counts = Fuzz::short("daemon_toml", 3000).run(toml_inputs(daemon_bases()), toml_alloc_bound, decode_daemon_toml);
    assert_coverage("daemon_toml", &counts, &["parse", "unknown_key", "plan", "tracker"]);
}

#[test]
#[ignore = "long fuzz run: make fuzz"]
fn daemon_toml_long() {
    Fuzz::long("daemon_toml").run(toml_inputs(daemon_bases()), toml_alloc_bound, decode_daemon_toml);
}
