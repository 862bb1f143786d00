//! Relative links in the repository's Markdown files: each must name a file or folder that
//! exists inside the repository, so that a clone on its own has every page it links to.

use std::path::{Path, PathBuf};

/// Folders that hold no documentation of ours.
const SKIP_DIRS: [&str; 3] = ["target", "out", "node_modules"];

/// `file:line: target (why)` for every relative link in a `*.md` under `root` that does not
/// resolve to an existing path inside `root`.
pub fn broken_links(root: &Path) -> Vec<String> {
    let root = root.canonicalize().unwrap_or_else(|e| panic!("{}: {e}", root.display()));
    let mut broken = Vec::new();
    for file in markdown_files(&root) {
        let text = std::fs::read_to_string(&file).unwrap();
        let dir = file.parent().unwrap();
        for (line, target) in link_targets(&text) {
            let Some(rel) = local_path(&target) else { continue };
            let resolved = dir.join(rel);
            let why = match resolved.canonicalize() {
                Err(_) => "does not exist",
                Ok(p) if !p.starts_with(&root) => "outside the repository",
                Ok(_) => continue,
            };
            let shown = file.strip_prefix(&root).unwrap_or(&file);
            broken.push(format!("{}:{line}: {target} ({why})", shown.display()));
        }
    }
    broken
}

fn markdown_files(root: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            if path.is_dir() {
                if !name.starts_with('.') && !SKIP_DIRS.contains(&name.as_str()) {
                    stack.push(path);
                }
            } else if name.ends_with(".md") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// The part of a link target that names a local path: `None` for URLs and in-page anchors;
/// the `#anchor` of a local target dropped.
fn local_path(target: &str) -> Option<&str> {
    if target.is_empty() || target.starts_with('#') || target.contains("://") || target.starts_with("mailto:") {
        return None;
    }
    Some(target.split('#').next().unwrap())
}

/// (line number, target) of every inline link `[text](target "title")` and reference
/// definition `[label]: target`, outside fenced code blocks and code spans.
fn link_targets(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut fenced = false;
    for (n, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("```") || trimmed.starts_with("~~~") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        let line = without_code_spans(line);
        if let Some(rest) = line.trim_start().strip_prefix('[')
            && let Some((_, def)) = rest.split_once("]:")
            && let Some(t) = def.split_whitespace().next()
        {
            out.push((n + 1, t.trim_matches(['<', '>']).to_owned()));
        }
        let mut rest = line.as_str();
        while let Some(k) = rest.find("](") {
            rest = &rest[k + 2..];
            let end = rest.find(')').unwrap_or(rest.len());
            let target = rest[..end].split_whitespace().next().unwrap_or("");
            out.push((n + 1, target.trim_matches(['<', '>']).to_owned()));
            rest = &rest[end..];
        }
    }
    out
}

/// The line with the contents of its `code spans` removed (their backticks kept).
fn without_code_spans(line: &str) -> String {
    let mut out = String::new();
    let mut in_code = false;
    for c in line.chars() {
        if c == '`' {
            in_code = !in_code;
            out.push(c);
        } else if !in_code {
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_inline_links_and_definitions_but_not_code() {
        let md = "See [`a.md`](docs/a.md#x \"t\") and [b](https://x.org/b).\n```\n[c](c.md)\n```\n`[d](d.md)`\n[e]: ../e.md\n[f](#top)";
        let targets: Vec<String> = link_targets(md).into_iter().map(|(_, t)| t).collect();
        assert_eq!(targets, ["docs/a.md#x", "https://x.org/b", "../e.md", "#top"]);
        let local: Vec<&str> = targets.iter().filter_map(|t| local_path(t)).collect();
        assert_eq!(local, ["docs/a.md", "../e.md"]);
    }
}
