//! Public fields of structs, counted on the source text: a struct with many public fields is
//! state that every reader may reach into, which the daemon's owned parts are meant to end.

use std::path::{Path, PathBuf};

use super::lexer::{tokenize, Token};

#[derive(Debug, PartialEq)]
pub struct StructFields {
    pub name: String,
    /// Named fields declared `pub` or `pub(crate)`.
    pub public_fields: usize,
}

/// Every braced struct in `src` with its count of `pub` / `pub(crate)` fields (tuple and
/// unit structs have no named fields and are left out).
pub fn public_field_counts(src: &str) -> Vec<StructFields> {
    let toks = tokenize(src);
    let mut out = Vec::new();
    for (i, t) in toks.iter().enumerate() {
        let (true, Some(Token::Ident(name))) = (t.is_ident("struct"), toks.get(i + 1)) else {
            continue;
        };
        // Past the generics and any where clause to the body, if braced.
        let mut angle = 0i32;
        let mut j = i + 2;
        while j < toks.len() {
            match &toks[j] {
                Token::Punct('<') => angle += 1,
                Token::Punct('>') if !toks[j - 1].is_punct('-') => angle -= 1,
                Token::Punct('{' | '(' | ';') if angle == 0 => break,
                _ => {}
            }
            j += 1;
        }
        if !toks.get(j).is_some_and(|t| t.is_punct('{')) {
            continue;
        }
        let mut depth = 0;
        let mut public_fields = 0;
        for k in j..toks.len() {
            match &toks[k] {
                Token::Punct('{' | '(' | '[') => depth += 1,
                Token::Punct('}' | ')' | ']') => {
                    depth -= 1;
                    if depth == 0 {
                        break;
                    }
                }
                t if depth == 1 && t.is_ident("pub") => {
                    let restricted = toks.get(k + 1).is_some_and(|t| t.is_punct('('));
                    if !restricted || toks.get(k + 2).is_some_and(|t| t.is_ident("crate")) {
                        public_fields += 1;
                    }
                }
                _ => {}
            }
        }
        out.push(StructFields { name: name.clone(), public_fields });
    }
    out
}

/// The `.rs` files under `dir`, sorted.
pub fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_pub_and_pub_crate_named_fields_only() {
        let src = "pub struct A<T: Into<f64>> where T: Copy { pub a: Vec<(u8, u8)>, pub(crate) b: [u8; 3], pub(super) c: u8, d: u8, pub e: fn(u8) -> u8 }\n\
                   pub struct Tuple(pub u8, pub u8);\n\
                   struct Unit;\n\
                   struct B { inner: Option<Box<dyn Fn() -> u8>>, pub x: u8 }";
        assert_eq!(
            public_field_counts(src),
            [
                StructFields { name: "A".into(), public_fields: 3 },
                StructFields { name: "B".into(), public_fields: 1 },
            ]
        );
    }
}
