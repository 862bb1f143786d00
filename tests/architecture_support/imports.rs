//! The import graph of one crate: nodes are its source files, an edge A -> B when A names an
//! item defined in B (through a `use` tree or a qualified path in code), and the loops in it.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::{Path, PathBuf};

use super::lexer::{tokenize, Token};

/// A module of the crate: a file, or an inline `mod name { ... }` block inside one.
#[derive(Debug, Default)]
struct Module {
    parent: Option<usize>,
    /// The file it lives in (index into `CrateGraph::files`).
    file: usize,
    /// Where the files of its `mod x;` children are looked for.
    child_dir: PathBuf,
    children: BTreeMap<String, usize>,
    /// Names of items it defines itself.
    defined: BTreeSet<String>,
    /// `pub use path::X` / `pub use path::Y as X`: exported name and the path it names.
    reexports: Vec<(String, Vec<String>)>,
    /// `pub use path::*`.
    globs: Vec<Vec<String>>,
    /// Paths it names: `use` trees (not re-exports) and qualified paths in code.
    refs: Vec<Vec<String>>,
}

#[derive(Debug)]
pub struct CrateGraph {
    /// File paths as given to the loader (`prefix/relative.rs`).
    files: Vec<String>,
    modules: Vec<Module>,
}

/// One `use` tree leaf: the full path, the name it binds, and whether it is a glob.
#[derive(Debug, PartialEq)]
struct UseLeaf {
    path: Vec<String>,
    alias: Option<String>,
    glob: bool,
}

impl CrateGraph {
    /// Reads the crate whose sources are under `repo/src_dir`, starting at `root_file`.
    pub fn load(repo: &Path, src_dir: &Path, root_file: &str) -> Result<Self, String> {
        let base = repo.join(src_dir);
        Self::load_with(&src_dir.join(root_file), |p| {
            let rel = p.strip_prefix(src_dir).unwrap_or(p);
            std::fs::read_to_string(base.join(rel)).ok()
        })
    }

    /// Reads a crate through `read` (a path relative to the working directory, `None` when
    /// absent): the real file system, or strings in a unit test.
    pub fn load_with(root_file: &Path, read: impl Fn(&Path) -> Option<String>) -> Result<Self, String> {
        let mut g = CrateGraph { files: Vec::new(), modules: Vec::new() };
        let root_dir = root_file.parent().unwrap_or(Path::new("")).to_path_buf();
        let mut queue = VecDeque::from([(root_file.to_path_buf(), None::<(usize, String)>, root_dir)]);
        while let Some((path, parent, child_dir)) = queue.pop_front() {
            let text = read(&path).ok_or_else(|| format!("cannot read {}", path.display()))?;
            let file = g.files.len();
            g.files.push(path.to_string_lossy().replace('\\', "/"));
            let id = g.modules.len();
            g.modules.push(Module { parent: parent.as_ref().map(|p| p.0), file, child_dir, ..Module::default() });
            if let Some((p, name)) = parent {
                g.modules[p].children.insert(name, id);
            }
            for (owner, name, explicit) in g.parse_file(id, &text) {
                let owner_dir = g.modules[owner].child_dir.clone();
                let file_dir = path.parent().unwrap_or(Path::new("")).to_path_buf();
                let candidates = match &explicit {
                    Some(p) => vec![file_dir.join(p)],
                    None => vec![owner_dir.join(format!("{name}.rs")), owner_dir.join(&name).join("mod.rs")],
                };
                let found = candidates.iter().find(|c| read(c).is_some()).ok_or_else(|| {
                    format!("{}: `mod {name};` found none of {candidates:?}", path.display())
                })?;
                // A `mod.rs` owns its directory; so does a file named by `#[path]`.
                let is_mod_rs = found.file_name().is_some_and(|f| f == "mod.rs") || explicit.is_some();
                let dir = if is_mod_rs {
                    found.parent().unwrap_or(Path::new("")).to_path_buf()
                } else {
                    owner_dir.join(&name)
                };
                queue.push_back((found.clone(), Some((owner, name)), dir));
            }
        }
        Ok(g)
    }

    /// Walks the tokens of one file whose module is `id`: registers its inline modules,
    /// items, re-exports and references; returns the `mod x;` declarations to load as
    /// (owning module, name, `#[path]` if any).
    fn parse_file(&mut self, id: usize, text: &str) -> Vec<(usize, String, Option<String>)> {
        let toks = tokenize(text);
        let mut decls = Vec::new();
        // Open braces: Some(module) for an inline module's, None for any other.
        let mut scopes: Vec<Option<usize>> = Vec::new();
        let mut path_attr: Option<String> = None;
        let mut i = 0;
        while i < toks.len() {
            let cur = scopes.iter().rev().find_map(|s| *s).unwrap_or(id);
            let t = &toks[i];
            let prev = i.checked_sub(1).map(|k| &toks[k]);
            if t.is_punct('#') {
                let open = if toks.get(i + 1).is_some_and(|t| t.is_punct('!')) { i + 2 } else { i + 1 };
                if toks.get(open).is_some_and(|t| t.is_punct('[')) {
                    let close = matching(&toks, open, '[', ']');
                    if let [Token::Ident(a), Token::Punct('='), Token::Str(p)] = &toks[open + 1..close]
                        && a == "path"
                    {
                        path_attr = Some(p.clone());
                    }
                    i = close + 1;
                    continue;
                }
            }
            match t {
                Token::Ident(kw) if kw == "mod" => {
                    if let Some(Token::Ident(name)) = toks.get(i + 1) {
                        if toks.get(i + 2).is_some_and(|t| t.is_punct(';')) {
                            decls.push((cur, name.clone(), path_attr.take()));
                            self.modules[cur].defined.insert(name.clone());
                            i += 3;
                            continue;
                        }
                        if toks.get(i + 2).is_some_and(|t| t.is_punct('{')) {
                            let inline = self.modules.len();
                            let child_dir = self.modules[cur].child_dir.join(name);
                            let file = self.modules[cur].file;
                            self.modules.push(Module { parent: Some(cur), file, child_dir, ..Module::default() });
                            self.modules[cur].children.insert(name.clone(), inline);
                            self.modules[cur].defined.insert(name.clone());
                            scopes.push(Some(inline));
                            path_attr = None;
                            i += 3;
                            continue;
                        }
                    }
                }
                Token::Ident(kw) if kw == "use" => {
                    let public = is_public(&toks, i);
                    let mut leaves = Vec::new();
                    let mut j = i + 1;
                    parse_use_tree(&toks, &mut j, Vec::new(), &mut leaves);
                    while j < toks.len() && !toks[j].is_punct(';') {
                        j += 1;
                    }
                    let m = &mut self.modules[cur];
                    for leaf in leaves {
                        match (public, leaf.glob) {
                            (true, true) => m.globs.push(leaf.path),
                            (true, false) => {
                                let name = leaf.alias.clone().or_else(|| leaf.path.last().cloned()).unwrap_or_default();
                                m.reexports.push((name, leaf.path));
                            }
                            (false, _) => m.refs.push(leaf.path),
                        }
                    }
                    i = j + 1;
                    continue;
                }
                Token::Ident(kw) if ["fn", "struct", "enum", "trait", "type", "const", "static", "union"].contains(&kw.as_str()) => {
                    if let Some(Token::Ident(name)) = toks.get(i + 1) {
                        self.modules[cur].defined.insert(name.clone());
                    }
                }
                Token::Ident(kw) if kw == "macro_rules" => {
                    if let Some(Token::Ident(name)) = toks.get(i + 2) {
                        self.modules[cur].defined.insert(name.clone());
                    }
                }
                Token::Ident(first)
                    if toks.get(i + 1) == Some(&Token::PathSep)
                        && prev != Some(&Token::PathSep)
                        && !prev.is_some_and(|p| p.is_ident("in")) =>
                {
                    // A qualified path in code: `crate::a::f`, `super::X`, `child::g`, ...
                    let mut segs = vec![first.clone()];
                    let mut j = i + 1;
                    while toks.get(j) == Some(&Token::PathSep) {
                        match toks.get(j + 1) {
                            Some(Token::Ident(s)) => {
                                segs.push(s.clone());
                                j += 2;
                            }
                            _ => break,
                        }
                    }
                    self.modules[cur].refs.push(segs);
                    i = j;
                    continue;
                }
                Token::Punct('{') => scopes.push(None),
                Token::Punct('}') => {
                    scopes.pop();
                }
                _ => {}
            }
            i += 1;
        }
        decls
    }

    /// The module a path names from `ctx`: walks the module tree as far as the path goes,
    /// then follows re-exports of the item it ends at to the module that defines it. `None`
    /// for paths outside the crate (other crates, std, local names).
    fn resolve(&self, ctx: usize, segs: &[String], depth: usize) -> Option<usize> {
        let first = segs.first()?;
        let (mut cur, rest) = match first.as_str() {
            "crate" => (0, &segs[1..]),
            "self" => (ctx, &segs[1..]),
            "super" => (self.modules[ctx].parent?, &segs[1..]),
            name if self.modules[ctx].children.contains_key(name) => (ctx, segs),
            _ => return None,
        };
        for seg in rest {
            match seg.as_str() {
                "super" => cur = self.modules[cur].parent?,
                "self" => {}
                name => match self.modules[cur].children.get(name) {
                    Some(&child) => cur = child,
                    None => return Some(self.defining_module(cur, name, depth)),
                },
            }
        }
        Some(cur)
    }

    /// Where the item `name`, named through module `m`, is defined: `m` itself unless `m`
    /// re-exports it from elsewhere.
    fn defining_module(&self, m: usize, name: &str, depth: usize) -> usize {
        let module = &self.modules[m];
        if depth > 16 || module.defined.contains(name) {
            return m;
        }
        if let Some((_, path)) = module.reexports.iter().find(|(n, _)| n == name) {
            return self.resolve(m, path, depth + 1).unwrap_or(m);
        }
        for glob in &module.globs {
            if let Some(g) = self.resolve(m, glob, depth + 1) {
                let gm = &self.modules[g];
                if g != m && (gm.defined.contains(name) || gm.reexports.iter().any(|(n, _)| n == name) || !gm.globs.is_empty()) {
                    let target = self.defining_module(g, name, depth + 1);
                    if self.modules[target].defined.contains(name) {
                        return target;
                    }
                }
            }
        }
        m
    }

    /// File -> files it names items of (self-edges left out).
    pub fn edges(&self) -> BTreeMap<usize, BTreeSet<usize>> {
        let mut edges: BTreeMap<usize, BTreeSet<usize>> = BTreeMap::new();
        for (id, m) in self.modules.iter().enumerate() {
            for path in &m.refs {
                if let Some(target) = self.resolve(id, path, 0) {
                    let to = self.modules[target].file;
                    if to != m.file {
                        edges.entry(m.file).or_default().insert(to);
                    }
                }
            }
        }
        edges
    }

    /// Every file's edges, by name: for reading the graph in a failing test.
    pub fn named_edges(&self) -> Vec<(String, String)> {
        let mut out = Vec::new();
        for (from, tos) in self.edges() {
            for to in tos {
                out.push((self.files[from].clone(), self.files[to].clone()));
            }
        }
        out
    }

    /// The loops: for every file in a strongly connected component of more than one file,
    /// the shortest loop through it, as file names (first == last), each loop once.
    pub fn cycles(&self) -> Vec<Vec<String>> {
        let edges = self.edges();
        let mut found: BTreeSet<Vec<usize>> = BTreeSet::new();
        for scc in strongly_connected(self.files.len(), &edges) {
            if scc.len() < 2 {
                continue;
            }
            for &start in &scc {
                if let Some(mut cycle) = shortest_cycle(start, &edges, &scc) {
                    // Rotate so that equal loops compare equal.
                    let k = (0..cycle.len()).min_by_key(|&k| cycle[k]).unwrap_or(0);
                    cycle.rotate_left(k);
                    found.insert(cycle);
                }
            }
        }
        found
            .into_iter()
            .map(|c| c.iter().chain(c.first()).map(|&f| self.files[f].clone()).collect())
            .collect()
    }
}

/// Whether the `use` at `i` is a re-export: `pub use`, `pub(crate) use`, `pub(super) use`.
fn is_public(toks: &[Token], i: usize) -> bool {
    match i.checked_sub(1).map(|k| &toks[k]) {
        Some(t) if t.is_ident("pub") => true,
        Some(t) if t.is_punct(')') => {
            let mut k = i - 1;
            while k > 0 && !toks[k].is_punct('(') {
                k -= 1;
            }
            k > 0 && toks[k - 1].is_ident("pub")
        }
        _ => false,
    }
}

/// Index of the bracket that closes the one at `open`.
fn matching(toks: &[Token], open: usize, o: char, c: char) -> usize {
    let mut depth = 0;
    for (k, t) in toks.iter().enumerate().skip(open) {
        if t.is_punct(o) {
            depth += 1;
        } else if t.is_punct(c) {
            depth -= 1;
            if depth == 0 {
                return k;
            }
        }
    }
    toks.len() - 1
}

/// Parses one use tree at `*i` (after `use` or inside braces) into its leaves.
fn parse_use_tree(toks: &[Token], i: &mut usize, prefix: Vec<String>, out: &mut Vec<UseLeaf>) {
    let mut path = prefix;
    if toks.get(*i) == Some(&Token::PathSep) {
        *i += 1;
    }
    loop {
        match toks.get(*i) {
            Some(Token::Ident(name)) => {
                path.push(name.clone());
                *i += 1;
                if toks.get(*i) == Some(&Token::PathSep) {
                    *i += 1;
                    continue;
                }
                let mut alias = None;
                if toks.get(*i).is_some_and(|t| t.is_ident("as")) {
                    alias = toks.get(*i + 1).and_then(|t| t.ident()).map(str::to_owned);
                    *i += 2;
                }
                // `a::{self}` names the module `a`.
                if path.len() > 1 && path.last().is_some_and(|s| s == "self") {
                    path.pop();
                }
                out.push(UseLeaf { path, alias, glob: false });
                return;
            }
            Some(Token::Punct('*')) => {
                *i += 1;
                out.push(UseLeaf { path, alias: None, glob: true });
                return;
            }
            Some(Token::Punct('{')) => {
                *i += 1;
                while let Some(t) = toks.get(*i) {
                    if t.is_punct('}') {
                        *i += 1;
                        break;
                    }
                    if t.is_punct(',') {
                        *i += 1;
                        continue;
                    }
                    let before = *i;
                    parse_use_tree(toks, i, path.clone(), out);
                    if *i == before {
                        *i += 1;
                    }
                }
                return;
            }
            _ => return,
        }
    }
}

/// Tarjan's strongly connected components.
fn strongly_connected(n: usize, edges: &BTreeMap<usize, BTreeSet<usize>>) -> Vec<Vec<usize>> {
    struct State<'a> {
        edges: &'a BTreeMap<usize, BTreeSet<usize>>,
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        on_stack: Vec<bool>,
        stack: Vec<usize>,
        next: usize,
        out: Vec<Vec<usize>>,
    }
    fn visit(s: &mut State, v: usize) {
        s.index[v] = Some(s.next);
        s.low[v] = s.next;
        s.next += 1;
        s.stack.push(v);
        s.on_stack[v] = true;
        let succ: Vec<usize> = s.edges.get(&v).map(|e| e.iter().copied().collect()).unwrap_or_default();
        for w in succ {
            match s.index[w] {
                None => {
                    visit(s, w);
                    s.low[v] = s.low[v].min(s.low[w]);
                }
                Some(iw) if s.on_stack[w] => s.low[v] = s.low[v].min(iw),
                Some(_) => {}
            }
        }
        if Some(s.low[v]) == s.index[v] {
            let mut scc = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack[w] = false;
                scc.push(w);
                if w == v {
                    break;
                }
            }
            scc.sort();
            s.out.push(scc);
        }
    }
    let mut s = State { edges, index: vec![None; n], low: vec![0; n], on_stack: vec![false; n], stack: Vec::new(), next: 0, out: Vec::new() };
    for v in 0..n {
        if s.index[v].is_none() {
            visit(&mut s, v);
        }
    }
    s.out
}

/// The shortest path from `start` back to itself inside `scc` (breadth first), without the
/// repeated end.
fn shortest_cycle(start: usize, edges: &BTreeMap<usize, BTreeSet<usize>>, scc: &[usize]) -> Option<Vec<usize>> {
    let mut came_from: BTreeMap<usize, usize> = BTreeMap::new();
    let mut queue = VecDeque::from([start]);
    while let Some(v) = queue.pop_front() {
        for &w in edges.get(&v).into_iter().flatten() {
            if !scc.contains(&w) {
                continue;
            }
            if w == start {
                let mut path = vec![v];
                let mut at = v;
                while at != start {
                    at = came_from[&at];
                    path.push(at);
                }
                path.reverse();
                return Some(path);
            }
            if w != start && !came_from.contains_key(&w) {
                came_from.insert(w, v);
                queue.push_back(w);
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph(files: &[(&str, &str)]) -> CrateGraph {
        let files: BTreeMap<PathBuf, String> = files.iter().map(|(p, t)| (PathBuf::from(p), t.to_string())).collect();
        CrateGraph::load_with(Path::new("src/lib.rs"), |p| files.get(p).cloned()).unwrap()
    }

    fn has(g: &CrateGraph, from: &str, to: &str) -> bool {
        g.named_edges().contains(&(format!("src/{from}"), format!("src/{to}")))
    }

    #[test]
    fn nested_use_braces_give_an_edge_per_module() {
        let g = graph(&[
            ("src/lib.rs", "mod a; mod b; mod c; mod d;"),
            ("src/a.rs", "use crate::{b::{B, C}, c::{self}, d::E};"),
            ("src/b.rs", "pub struct B; pub struct C;"),
            ("src/c.rs", ""),
            ("src/d.rs", "pub enum E {}"),
        ]);
        assert!(has(&g, "a.rs", "b.rs") && has(&g, "a.rs", "c.rs") && has(&g, "a.rs", "d.rs"), "{:?}", g.named_edges());
        assert!(g.cycles().is_empty());
    }

    #[test]
    fn super_super_and_qualified_paths_in_code() {
        let g = graph(&[
            ("src/lib.rs", "mod top; pub fn f() {}"),
            ("src/top/mod.rs", "mod mid; pub struct T;"),
            ("src/top/mid/mod.rs", "mod leaf;"),
            ("src/top/mid/leaf.rs", "fn g() { super::super::super::f(); let _ = super::super::T; }"),
        ]);
        assert!(has(&g, "top/mid/leaf.rs", "lib.rs"), "{:?}", g.named_edges());
        assert!(has(&g, "top/mid/leaf.rs", "top/mod.rs"), "{:?}", g.named_edges());
        assert!(!has(&g, "top/mid/leaf.rs", "top/mid/mod.rs"));
    }

    #[test]
    fn re_exports_lead_to_the_defining_module_and_are_no_edges_themselves() {
        let g = graph(&[
            ("src/lib.rs", "pub mod api; mod user; mod globbed;"),
            ("src/api/mod.rs", "mod inner; mod more; pub use inner::{Thing, Other as Renamed}; pub use self::more::*;"),
            ("src/api/inner.rs", "pub struct Thing; pub struct Other;"),
            ("src/api/more.rs", "pub fn helper() {}"),
            ("src/user.rs", "use crate::api::{Thing, Renamed}; fn f() { crate::api::helper(); }"),
            ("src/globbed.rs", "pub use crate::api::*;"),
        ]);
        assert!(has(&g, "user.rs", "api/inner.rs"), "{:?}", g.named_edges());
        assert!(has(&g, "user.rs", "api/more.rs"), "{:?}", g.named_edges());
        assert!(!has(&g, "user.rs", "api/mod.rs"), "{:?}", g.named_edges());
        assert!(!has(&g, "api/mod.rs", "api/inner.rs"), "a re-export is no edge: {:?}", g.named_edges());
        assert!(!has(&g, "globbed.rs", "api/mod.rs"));
    }

    #[test]
    fn inline_modules_belong_to_their_file() {
        let g = graph(&[
            ("src/lib.rs", "mod a; mod b;"),
            ("src/a.rs", "pub fn f() {} #[cfg(test)] mod tests { use super::*; fn t() { super::f(); crate::b::g(); } }"),
            ("src/b.rs", "pub fn g() {} mod inner { pub mod deep { fn h() { super::super::g(); } } }"),
        ]);
        assert_eq!(g.named_edges(), [("src/a.rs".to_string(), "src/b.rs".to_string())]);
    }

    #[test]
    fn child_files_of_a_non_mod_rs_file_and_path_attributes() {
        let g = graph(&[
            ("src/lib.rs", "mod a;"),
            ("src/a.rs", "mod b; #[path = \"a_tests.rs\"] mod tests; pub fn f() { b::g(); }"),
            ("src/a/b.rs", "pub fn g() {}"),
            ("src/a_tests.rs", "use super::*;"),
        ]);
        assert!(has(&g, "a.rs", "a/b.rs"), "{:?}", g.named_edges());
        assert!(has(&g, "a_tests.rs", "a.rs"), "{:?}", g.named_edges());
    }

    #[test]
    fn a_two_module_loop_is_found_and_named() {
        let g = graph(&[
            ("src/lib.rs", "pub mod phase;"),
            ("src/phase/mod.rs", "pub mod servo; pub struct Mission; fn run() { servo::step(); }"),
            ("src/phase/servo.rs", "use super::Mission; pub fn step() {}"),
        ]);
        assert_eq!(g.cycles(), [vec!["src/phase/mod.rs", "src/phase/servo.rs", "src/phase/mod.rs"]]);
    }

    #[test]
    fn a_parent_that_only_declares_and_re_exports_is_no_loop() {
        let g = graph(&[
            ("src/lib.rs", "mod m; pub use m::X;"),
            ("src/m.rs", "use crate::helper; pub struct X; fn f() { helper(); }"),
        ]);
        assert!(g.cycles().is_empty(), "{:?}", g.cycles());
    }
}
