//! Where in a scenario file something is: field paths and the line/column of a byte offset,
//! from toml's spanned document.

use std::ops::Range;
use std::path::Path;

use toml::Spanned;
use toml::de::{DeTable, DeValue};

use super::error::ScenarioError;

/// One step of a field path: a table key or an array index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Seg {
    K(&'static str),
    I(usize),
}

pub(super) fn path_string(path: &[Seg]) -> String {
    let mut s = String::new();
    for seg in path {
        match seg {
            Seg::K(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            Seg::I(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

/// Span of the value at `path` (or of the deepest part of it that exists).
pub(super) fn span_of(doc: &Spanned<DeTable<'_>>, path: &[Seg]) -> Option<Range<usize>> {
    let mut span = doc.span();
    let mut table: Option<&DeTable<'_>> = Some(doc.get_ref());
    let mut value: Option<&Spanned<DeValue<'_>>> = None;
    for seg in path {
        let next = match (*seg, table, value) {
            (Seg::K(k), Some(t), _) => t.iter().find(|(key, _)| key.get_ref() == k).map(|(key, v)| {
                // Point at the key itself: the line a user looks for.
                span = key.span();
                v
            }),
            (Seg::I(i), _, Some(v)) => v.get_ref().as_array().and_then(|a| a.get(i)).inspect(|v| span = v.span()),
            _ => None,
        };
        let Some(v) = next else { break };
        value = Some(v);
        table = v.get_ref().as_table();
    }
    Some(span)
}

/// Dotted path of the field at byte offset `pos`: the key, value or table header that starts
/// last at or before `pos` (toml spans of tables cover only their header line).
pub(super) fn path_at(doc: &Spanned<DeTable<'_>>, pos: usize) -> String {
    fn collect_table(t: &DeTable<'_>, prefix: &str, out: &mut Vec<(usize, String)>) {
        for (k, v) in t.iter() {
            let path = if prefix.is_empty() { k.get_ref().to_string() } else { format!("{prefix}.{}", k.get_ref()) };
            out.push((k.span().start, path.clone()));
            collect_value(v, &path, out);
        }
    }
    fn collect_value(v: &Spanned<DeValue<'_>>, path: &str, out: &mut Vec<(usize, String)>) {
        out.push((v.span().start, path.to_string()));
        if let Some(t) = v.get_ref().as_table() {
            collect_table(t, path, out);
        } else if let Some(a) = v.get_ref().as_array() {
            for (i, item) in a.iter().enumerate() {
                collect_value(item, &format!("{path}[{i}]"), out);
            }
        }
    }
    let mut entries = Vec::new();
    collect_table(doc.get_ref(), "", &mut entries);
    entries
        .into_iter()
        .filter(|(start, _)| *start <= pos)
        .max_by(|a, b| a.0.cmp(&b.0).then(a.1.len().cmp(&b.1.len())))
        .map_or_else(|| "(top level)".to_string(), |(_, p)| p)
}

pub(super) fn error_at(file: &Path, text: &str, field: Option<String>, span: Option<Range<usize>>, message: &str) -> ScenarioError {
    let (line, column) = match span {
        Some(s) => line_col(text, s.start),
        None => (0, 0),
    };
    ScenarioError {
        file: file.to_path_buf(),
        line,
        column,
        field: field.unwrap_or_else(|| "(syntax)".into()),
        message: message.trim().replace('\n', "; "),
    }
}

/// 1-based line and column (in characters) of byte offset `pos`.
pub(super) fn line_col(text: &str, pos: usize) -> (usize, usize) {
    let mut pos = pos.min(text.len());
    while !text.is_char_boundary(pos) {
        pos -= 1;
    }
    let before = &text[..pos];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}
