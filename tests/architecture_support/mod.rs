//! The source-text readers behind `tests/architecture.rs`: a small Rust lexer, the import
//! graph of a crate's files, public-field counts of structs, and Markdown links.

pub mod imports;
pub mod lexer;
pub mod links;
pub mod structs;
