//! A Rust lexer just good enough to find items, `use` trees and paths: comments vanish,
//! string and char literals become one token (so a `'{'` cannot unbalance braces), lifetimes
//! are dropped, and `::` is one token.

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Token {
    Ident(String),
    /// `::`
    PathSep,
    Punct(char),
    /// A string literal's contents (raw or not, escapes left as written).
    Str(String),
    /// A char or numeric literal; its value never matters here.
    Literal,
}

impl Token {
    pub fn is_ident(&self, s: &str) -> bool {
        matches!(self, Token::Ident(i) if i == s)
    }

    pub fn is_punct(&self, c: char) -> bool {
        matches!(self, Token::Punct(p) if *p == c)
    }

    pub fn ident(&self) -> Option<&str> {
        match self {
            Token::Ident(i) => Some(i),
            _ => None,
        }
    }
}

pub fn tokenize(src: &str) -> Vec<Token> {
    let s: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < s.len() {
        let c = s[i];
        let next = s.get(i + 1).copied();
        if c.is_whitespace() {
            i += 1;
        } else if c == '/' && next == Some('/') {
            while i < s.len() && s[i] != '\n' {
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            // Block comments nest in Rust.
            let mut depth = 0;
            while i < s.len() {
                if s[i] == '/' && s.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if s[i] == '*' && s.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if let Some(end) = raw_string_end(&s, i) {
            let (start, stop) = end.1;
            out.push(Token::Str(s[start..stop].iter().collect()));
            i = end.0;
        } else if c == '"' || (c == 'b' && next == Some('"')) || (c == 'c' && next == Some('"')) {
            i += if c == '"' { 1 } else { 2 };
            let start = i;
            while i < s.len() && s[i] != '"' {
                i += if s[i] == '\\' { 2 } else { 1 };
            }
            out.push(Token::Str(s[start..i.min(s.len())].iter().collect()));
            i += 1;
        } else if c == '\'' || (c == 'b' && next == Some('\'')) {
            let q = if c == '\'' { i } else { i + 1 };
            if s.get(q + 1) == Some(&'\\') {
                // An escaped char literal: skip to its closing quote.
                i = q + 2;
                while i < s.len() && s[i] != '\'' {
                    i += 1;
                }
                i += 1;
                out.push(Token::Literal);
            } else if s.get(q + 2) == Some(&'\'') {
                i = q + 3;
                out.push(Token::Literal);
            } else {
                // A lifetime or label: `'a`, skipped with its name.
                i = q + 1;
                while i < s.len() && (s[i].is_alphanumeric() || s[i] == '_') {
                    i += 1;
                }
            }
        } else if c.is_alphabetic() || c == '_' {
            let start = i;
            while i < s.len() && (s[i].is_alphanumeric() || s[i] == '_') {
                i += 1;
            }
            let word: String = s[start..i].iter().collect();
            // `r#ident` is a raw identifier.
            if word == "r" && s.get(i) == Some(&'#') && s.get(i + 1).is_some_and(|c| c.is_alphabetic()) {
                i += 1;
                continue;
            }
            out.push(Token::Ident(word));
        } else if c.is_ascii_digit() {
            while i < s.len() && (s[i].is_alphanumeric() || s[i] == '_' || (s[i] == '.' && s.get(i + 1).is_some_and(|d| d.is_ascii_digit()))) {
                i += 1;
            }
            out.push(Token::Literal);
        } else if c == ':' && next == Some(':') {
            out.push(Token::PathSep);
            i += 2;
        } else {
            out.push(Token::Punct(c));
            i += 1;
        }
    }
    out
}

/// A raw string literal starting at `i` (`r"…"`, `r#"…"#`, `br#"…"#`): the index after it and
/// the range of its contents.
fn raw_string_end(s: &[char], i: usize) -> Option<(usize, (usize, usize))> {
    let mut j = i;
    if s.get(j) == Some(&'b') || s.get(j) == Some(&'c') {
        j += 1;
    }
    if s.get(j) != Some(&'r') {
        return None;
    }
    if i > 0 && (s[i - 1].is_alphanumeric() || s[i - 1] == '_') {
        return None;
    }
    j += 1;
    let mut hashes = 0;
    while s.get(j) == Some(&'#') {
        hashes += 1;
        j += 1;
    }
    if s.get(j) != Some(&'"') {
        return None;
    }
    let start = j + 1;
    let mut k = start;
    while k < s.len() {
        if s[k] == '"' && (1..=hashes).all(|h| s.get(k + h) == Some(&'#')) {
            return Some((k + 1 + hashes, (start, k)));
        }
        k += 1;
    }
    Some((s.len(), (start, s.len())))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn idents(src: &str) -> Vec<String> {
        tokenize(src).into_iter().filter_map(|t| t.ident().map(str::to_owned)).collect()
    }

    #[test]
    fn comments_literals_and_lifetimes_vanish() {
        let src = "/* a /* nested */ b */ fn f<'a>(x: &'a str) -> char { let _ = \"{ crate::x }\"; let _ = r#\"}\"#; '{' } // c";
        assert_eq!(idents(src), ["fn", "f", "x", "str", "char", "let", "_", "let", "_"]);
        let braces = tokenize(src).iter().filter(|t| t.is_punct('{') || t.is_punct('}')).count();
        assert_eq!(braces, 2);
    }

    #[test]
    fn path_separators_are_one_token() {
        assert_eq!(tokenize("a::b"), [Token::Ident("a".into()), Token::PathSep, Token::Ident("b".into())]);
    }
}
