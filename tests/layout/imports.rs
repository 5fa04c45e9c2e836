//! The import checker: reads Rust source as text, finds every path that
//! names a module of the crate (`use crate::...`, inline `crate::a::b`,
//! `super::`, `self::` and paths through a child module), resolves each
//! to the file of the module it names, and judges the resulting file
//! graph against the layer ranks and for cycles.
//!
//! It works on an in-memory tree (relative path -> text) so that it can be
//! tested on made-up trees as well as run on the real one.
//!
//! Resolution: the longest prefix of the path that is a module names a
//! file (`crate::scene::material::Material` -> `src/scene/material.rs`,
//! `crate::scene::RenderScene` -> `src/scene/mod.rs`); when the next
//! segment is a name that file imports at module level (`pub use` or
//! not), the path is followed through that import, so `crate::Error` is
//! `src/core/error.rs` and `super::Frame` in `systems/wavefront.rs` is
//! `systems/frame.rs`. Comments (doc comments too), string, raw string
//! and character literals are blanked out before anything is read.

use std::collections::{BTreeMap, BTreeSet};

/// One import of one file by another.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Import {
    /// The importing file, relative to the package root.
    pub from: String,
    /// 1-based line of the path's first segment.
    pub line: usize,
    /// The path as written, `::`-joined.
    pub written: String,
    /// The file of the module it names.
    pub to: String,
    /// Inside a `#[cfg(test)]` module.
    pub in_test: bool,
}

/// The files, their modules and every import between them.
pub struct Analysis {
    /// Every file read, with its module path.
    pub modules: BTreeMap<String, Vec<String>>,
    /// Every import of one file by another (never a file by itself),
    /// sorted by file and line.
    pub imports: Vec<Import>,
}

/// A layer rule broken, or a file outside every layer.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct LayerViolation {
    pub from: String,
    pub line: usize,
    pub from_layer: String,
    pub to_layer: String,
    pub to: String,
    pub message: String,
}

/// Files that import each other in a circle (a strongly connected
/// component of the import graph), with the imports that close it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Cycle {
    pub files: Vec<String>,
    pub message: String,
}

/// The module path of a file: `src/lib.rs` is the crate root, `src/a/mod.rs`
/// and `src/a.rs` are `a`, `systems/x.rs` is `systems::x` (lib.rs mounts
/// `systems/` as `crate::systems`). Other files (`src/bin/...`, `src/main.rs`)
/// are not modules of the library.
pub fn module_path(file: &str) -> Option<Vec<String>> {
    let rest = file.strip_suffix(".rs")?;
    let mut segs: Vec<String> = if let Some(r) = rest.strip_prefix("src/") {
        if r == "lib" {
            return Some(Vec::new());
        }
        if r == "main" || r.starts_with("bin/") {
            return None;
        }
        r.split('/').map(String::from).collect()
    } else if rest.starts_with("systems/") {
        rest.split('/').map(String::from).collect()
    } else {
        return None;
    };
    if segs.last().is_some_and(|s| s == "mod") {
        segs.pop();
    }
    Some(segs)
}

/// The layer of a file: the first segment of its module path (`None` for
/// the crate root).
pub fn layer_of(modules: &BTreeMap<String, Vec<String>>, file: &str) -> Option<String> {
    modules.get(file).and_then(|m| m.first().cloned())
}

// ---------------------------------------------------------------------------
// Lexing
// ---------------------------------------------------------------------------

/// `src` with comments and string, raw string, byte string and character
/// literals replaced by spaces (newlines kept, so lines still count).
pub fn blank_comments_and_literals(src: &str) -> String {
    let b = src.as_bytes();
    let n = b.len();
    let mut out = b.to_vec();
    let wipe = |out: &mut Vec<u8>, from: usize, to: usize| {
        for c in &mut out[from..to.min(n)] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    };
    let at = |i: usize| if i < n { b[i] } else { 0 };
    let mut i = 0;
    while i < n {
        let c = b[i];
        let prev_ident = i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
        if c == b'/' && at(i + 1) == b'/' {
            let end = b[i..].iter().position(|&c| c == b'\n').map_or(n, |p| i + p);
            wipe(&mut out, i, end);
            i = end;
        } else if c == b'/' && at(i + 1) == b'*' {
            let (mut depth, mut j) = (1, i + 2);
            while j < n && depth > 0 {
                if b[j] == b'/' && at(j + 1) == b'*' {
                    depth += 1;
                    j += 2;
                } else if b[j] == b'*' && at(j + 1) == b'/' {
                    depth -= 1;
                    j += 2;
                } else {
                    j += 1;
                }
            }
            wipe(&mut out, i, j);
            i = j;
        } else if !prev_ident
            && (c == b'r' || (c == b'b' && at(i + 1) == b'r'))
            && raw_string_hashes(b, if c == b'r' { i + 1 } else { i + 2 }).is_some()
        {
            let start = if c == b'r' { i + 1 } else { i + 2 };
            let hashes = raw_string_hashes(b, start).unwrap();
            let body = start + hashes + 1;
            let mut j = body;
            let end = loop {
                if j >= n {
                    break n;
                }
                if b[j] == b'"' && (0..hashes).all(|k| at(j + 1 + k) == b'#') {
                    break j + 1 + hashes;
                }
                j += 1;
            };
            wipe(&mut out, i, end);
            i = end;
        } else if c == b'"' || (!prev_ident && (c == b'b' || c == b'c') && at(i + 1) == b'"') {
            let mut j = if c == b'"' { i + 1 } else { i + 2 };
            while j < n && b[j] != b'"' {
                j += if b[j] == b'\\' { 2 } else { 1 };
            }
            wipe(&mut out, i, j + 1);
            i = j + 1;
        } else if c == b'\'' {
            // A character literal ('x', '\n', '\u{..}', 'é') or a lifetime.
            if at(i + 1) == b'\\' {
                let mut j = i + 2;
                while j < n && b[j] != b'\'' && b[j] != b'\n' {
                    j += 1;
                }
                wipe(&mut out, i, j + 1);
                i = j + 1;
            } else if let Some(ch) = src.get(i + 1..).and_then(|s| s.chars().next())
                && at(i + 1 + ch.len_utf8()) == b'\''
            {
                let end = i + 2 + ch.len_utf8();
                wipe(&mut out, i, end);
                i = end;
            } else {
                wipe(&mut out, i, i + 1);
                i += 1;
            }
        } else {
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// With `b[start..]` = `#*"`, the number of `#`.
fn raw_string_hashes(b: &[u8], start: usize) -> Option<usize> {
    let hashes = b.get(start..)?.iter().take_while(|&&c| c == b'#').count();
    (b.get(start + hashes) == Some(&b'"')).then_some(hashes)
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Tok<'a> {
    Ident(&'a str),
    /// `::`
    Sep,
    Punct(u8),
}

#[derive(Clone, Copy, Debug)]
struct Token<'a> {
    tok: Tok<'a>,
    line: usize,
}

fn tokens(clean: &str) -> Vec<Token<'_>> {
    let b = clean.as_bytes();
    let mut out = Vec::new();
    let (mut i, mut line) = (0, 1);
    while i < b.len() {
        let c = b[i];
        if c == b'\n' {
            line += 1;
            i += 1;
        } else if c.is_ascii_whitespace() || !c.is_ascii() {
            i += 1;
        } else if c.is_ascii_alphabetic() || c == b'_' {
            let start = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
            // A raw identifier: r#name.
            let mut word = &clean[start..i];
            if word == "r" && b.get(i) == Some(&b'#') {
                let s = i + 1;
                i = s;
                while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                    i += 1;
                }
                word = &clean[s..i];
            }
            out.push(Token {
                tok: Tok::Ident(word),
                line,
            });
        } else if c.is_ascii_digit() {
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
        } else if c == b':' && b.get(i + 1) == Some(&b':') {
            out.push(Token {
                tok: Tok::Sep,
                line,
            });
            i += 2;
        } else {
            out.push(Token {
                tok: Tok::Punct(c),
                line,
            });
            i += 1;
        }
    }
    out
}

// ---------------------------------------------------------------------------
// Paths in one file
// ---------------------------------------------------------------------------

/// A path as found in a file, before resolution.
#[derive(Clone, Debug)]
struct RawPath {
    segs: Vec<String>,
    line: usize,
    /// Inline modules (`mod tests { ... }`) around it.
    scope: Vec<String>,
    in_test: bool,
    /// A `use` at the top level of the file (not in a function, block or
    /// inline module): its name is visible to `super::` paths of children.
    module_level_use: bool,
    alias: Option<String>,
    glob: bool,
}

/// Every `use` leaf and every inline path that starts a path (`a::b`,
/// not `x::a::b`) in one file's text.
fn raw_paths(text: &str) -> Vec<RawPath> {
    let clean = blank_comments_and_literals(text);
    let toks = tokens(&clean);
    let tok = |i: usize| toks.get(i).map(|t| t.tok);
    let mut out = Vec::new();
    let mut depth = 0usize;
    // (name, depth inside its braces, in test code)
    let mut scopes: Vec<(String, usize, bool)> = Vec::new();
    let mut pending_test = false;
    let mut i = 0;
    while i < toks.len() {
        let in_test = scopes.last().is_some_and(|s| s.2);
        match toks[i].tok {
            Tok::Punct(b'#') => {
                let mut j = i + 1;
                if tok(j) == Some(Tok::Punct(b'!')) {
                    j += 1;
                }
                if tok(j) == Some(Tok::Punct(b'[')) {
                    let (mut d, mut k) = (0, j);
                    let mut words = Vec::new();
                    while k < toks.len() {
                        match toks[k].tok {
                            Tok::Punct(b'[') => d += 1,
                            Tok::Punct(b']') => {
                                d -= 1;
                                if d == 0 {
                                    break;
                                }
                            }
                            Tok::Ident(w) => words.push(w),
                            _ => {}
                        }
                        k += 1;
                    }
                    if words.first() == Some(&"cfg")
                        && words.contains(&"test")
                        && !words.contains(&"not")
                    {
                        pending_test = true;
                    }
                    i = k + 1;
                    continue;
                }
            }
            Tok::Ident("mod") => {
                if let (Some(Tok::Ident(name)), Some(Tok::Punct(b'{'))) = (tok(i + 1), tok(i + 2)) {
                    depth += 1;
                    scopes.push((name.to_string(), depth, pending_test || in_test));
                    pending_test = false;
                    i += 3;
                    continue;
                }
            }
            Tok::Ident("use") if tok(i.wrapping_sub(1)) != Some(Tok::Sep) => {
                let line = toks[i].line;
                let mut j = i + 1;
                let mut leaves = Vec::new();
                parse_use_tree(&toks, &mut j, Vec::new(), &mut leaves, 0);
                for (segs, alias, glob) in leaves {
                    out.push(RawPath {
                        segs,
                        line,
                        scope: scopes.iter().map(|s| s.0.clone()).collect(),
                        in_test,
                        module_level_use: depth == 0,
                        alias,
                        glob,
                    });
                }
                while j < toks.len() && toks[j].tok != Tok::Punct(b';') {
                    j += 1;
                }
                pending_test = false;
                i = j + 1;
                continue;
            }
            Tok::Punct(b'{') => {
                depth += 1;
                pending_test = false;
            }
            Tok::Punct(b'}') => {
                while scopes.last().is_some_and(|s| s.1 == depth) {
                    scopes.pop();
                }
                depth = depth.saturating_sub(1);
                pending_test = false;
            }
            Tok::Punct(b';') => pending_test = false,
            Tok::Ident(first)
                if tok(i + 1) == Some(Tok::Sep)
                    && !matches!(
                        tok(i.wrapping_sub(1)),
                        Some(Tok::Sep | Tok::Punct(b'$' | b'.'))
                    ) =>
            {
                let line = toks[i].line;
                let mut segs = vec![first.to_string()];
                let mut j = i + 1;
                while tok(j) == Some(Tok::Sep) {
                    match tok(j + 1) {
                        Some(Tok::Ident(s)) => {
                            segs.push(s.to_string());
                            j += 2;
                        }
                        _ => break,
                    }
                }
                out.push(RawPath {
                    segs,
                    line,
                    scope: scopes.iter().map(|s| s.0.clone()).collect(),
                    in_test,
                    module_level_use: false,
                    alias: None,
                    glob: false,
                });
                i = j;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    out
}

/// Parses one use tree at `toks[*i..]` into its leaves: (path, alias, glob).
/// A leading `::` (an external crate) becomes the segment `::`.
fn parse_use_tree(
    toks: &[Token],
    i: &mut usize,
    mut segs: Vec<String>,
    out: &mut Vec<(Vec<String>, Option<String>, bool)>,
    nesting: usize,
) {
    let tok = |i: usize| toks.get(i).map(|t| t.tok);
    if nesting > 32 {
        return;
    }
    if tok(*i) == Some(Tok::Sep) {
        *i += 1;
        if segs.is_empty() {
            segs.push("::".into());
        }
    }
    loop {
        match tok(*i) {
            Some(Tok::Ident(s)) => {
                segs.push(s.to_string());
                *i += 1;
                if tok(*i) == Some(Tok::Sep) {
                    *i += 1;
                    continue;
                }
                let mut alias = None;
                if tok(*i) == Some(Tok::Ident("as"))
                    && let Some(Tok::Ident(a)) = tok(*i + 1)
                {
                    alias = Some(a.to_string());
                    *i += 2;
                }
                if segs.last().is_some_and(|s| s == "self") {
                    segs.pop();
                }
                out.push((segs, alias, false));
                return;
            }
            Some(Tok::Punct(b'*')) => {
                *i += 1;
                out.push((segs, None, true));
                return;
            }
            Some(Tok::Punct(b'{')) => {
                *i += 1;
                loop {
                    match tok(*i) {
                        Some(Tok::Punct(b'}')) => {
                            *i += 1;
                            return;
                        }
                        Some(Tok::Punct(b',')) => *i += 1,
                        None | Some(Tok::Punct(b';')) => return,
                        _ => {
                            let before = *i;
                            parse_use_tree(toks, i, segs.clone(), out, nesting + 1);
                            if *i == before {
                                *i += 1;
                            }
                        }
                    }
                }
            }
            _ => return,
        }
    }
}

// ---------------------------------------------------------------------------
// Resolution
// ---------------------------------------------------------------------------

struct Resolver<'a> {
    /// module path -> file
    files: BTreeMap<Vec<String>, &'a str>,
    /// file -> (name -> absolute path it imports at module level)
    aliases: BTreeMap<&'a str, BTreeMap<String, Vec<String>>>,
}

impl Resolver<'_> {
    /// The absolute module path a path written in a file names, or `None`
    /// for paths outside the crate (`std::`, other crates, `Self::`, local
    /// items).
    fn absolute(&self, module: &[String], p: &RawPath) -> Option<Vec<String>> {
        let segs = &p.segs;
        let mut scope: Vec<String> = module.to_vec();
        scope.extend(p.scope.iter().cloned());
        match segs.first()?.as_str() {
            "crate" => Some(segs[1..].to_vec()),
            "super" => {
                let mut k = 0;
                while segs.get(k).is_some_and(|s| s == "super") {
                    scope.pop()?;
                    k += 1;
                }
                scope.extend(segs[k..].iter().cloned());
                Some(scope)
            }
            "self" => {
                scope.extend(segs[1..].iter().cloned());
                Some(scope)
            }
            first if p.scope.is_empty() => {
                // A path through a child module of the file (`frame::Frame`
                // in systems/mod.rs).
                let mut child = module.to_vec();
                child.push(first.to_string());
                self.files.contains_key(&child).then(|| {
                    child.extend(segs[1..].iter().cloned());
                    child
                })
            }
            _ => None,
        }
    }

    /// The file of the module `abs` names: its longest prefix that is a
    /// module, followed through that module's imports for the next segment.
    fn resolve(&self, abs: &[String], hops: usize) -> Option<&str> {
        for k in (0..=abs.len()).rev() {
            if let Some(&file) = self.files.get(&abs[..k]) {
                if k < abs.len()
                    && hops < 8
                    && let Some(target) = self.aliases.get(file).and_then(|a| a.get(&abs[k]))
                {
                    let mut t = target.clone();
                    t.extend(abs[k + 1..].iter().cloned());
                    if let Some(g) = self.resolve(&t, hops + 1) {
                        return Some(g);
                    }
                }
                return Some(file);
            }
        }
        None
    }
}

/// Reads every file of `tree` (relative path -> text) that is a module of
/// the library and resolves its imports.
pub fn analyse(tree: &BTreeMap<String, String>) -> Analysis {
    let modules: BTreeMap<String, Vec<String>> = tree
        .keys()
        .filter_map(|f| module_path(f).map(|m| (f.clone(), m)))
        .collect();
    let parsed: BTreeMap<&str, Vec<RawPath>> = modules
        .keys()
        .map(|f| (f.as_str(), raw_paths(&tree[f])))
        .collect();
    let mut resolver = Resolver {
        files: modules
            .iter()
            .map(|(f, m)| (m.clone(), f.as_str()))
            .collect(),
        aliases: BTreeMap::new(),
    };
    let mut aliases = BTreeMap::new();
    for (&file, paths) in &parsed {
        let mut names = BTreeMap::new();
        for p in paths.iter().filter(|p| p.module_level_use && !p.glob) {
            if let Some(abs) = resolver.absolute(&modules[file], p) {
                let name = p.alias.clone().or_else(|| p.segs.last().cloned());
                if let Some(name) = name.filter(|n| n != "_") {
                    names.insert(name, abs);
                }
            }
        }
        aliases.insert(file, names);
    }
    resolver.aliases = aliases;
    let mut imports = BTreeSet::new();
    for (&file, paths) in &parsed {
        for p in paths {
            let Some(abs) = resolver.absolute(&modules[file], p) else {
                continue;
            };
            let Some(to) = resolver.resolve(&abs, 0) else {
                continue;
            };
            if to != file {
                imports.insert(Import {
                    from: file.to_string(),
                    line: p.line,
                    written: p.segs.join("::") + if p.glob { "::*" } else { "" },
                    to: to.to_string(),
                    in_test: p.in_test,
                });
            }
        }
    }
    // One import per (file, line, target): a use group names many items.
    let mut seen = BTreeSet::new();
    let imports = imports
        .into_iter()
        .filter(|i| seen.insert((i.from.clone(), i.line, i.to.clone())))
        .collect();
    Analysis { modules, imports }
}

impl Analysis {
    /// Every import that goes to a higher layer, or to another layer of
    /// the same rank, and every file in a layer without a rank.
    pub fn layer_violations(&self, ranks: &[(&str, u32)]) -> Vec<LayerViolation> {
        let rank = |l: &str| ranks.iter().find(|r| r.0 == l).map(|r| r.1);
        let mut out = Vec::new();
        for (file, m) in &self.modules {
            if let Some(l) = m.first()
                && rank(l).is_none()
            {
                out.push(LayerViolation {
                    from: file.clone(),
                    line: 1,
                    from_layer: l.clone(),
                    to_layer: String::new(),
                    to: String::new(),
                    message: format!("{file}: layer `{l}` has no rank (add it to the layer table)"),
                });
            }
        }
        for i in &self.imports {
            let (Some(from), Some(to)) = (
                layer_of(&self.modules, &i.from),
                layer_of(&self.modules, &i.to),
            ) else {
                continue;
            };
            let (Some(rf), Some(rt)) = (rank(&from), rank(&to)) else {
                continue;
            };
            if from == to || rt < rf {
                continue;
            }
            let why = if rt == rf {
                "a layer of the same rank"
            } else {
                "a higher layer"
            };
            let test = if i.in_test {
                " (in #[cfg(test)] code)"
            } else {
                ""
            };
            out.push(LayerViolation {
                from: i.from.clone(),
                line: i.line,
                from_layer: from.clone(),
                to_layer: to.clone(),
                to: i.to.clone(),
                message: format!(
                    "{}:{}: {from} (rank {rf}) -> {to} (rank {rt}), {why}: `{}` names {}{test}",
                    i.from, i.line, i.written, i.to
                ),
            });
        }
        out
    }

    /// True when `to` is a module that encloses `from` (its parent or
    /// further up): a submodule naming its own parent's items is inside
    /// that module's namespace, not a dependency between modules.
    fn is_enclosing(&self, from: &str, to: &str) -> bool {
        match (self.modules.get(from), self.modules.get(to)) {
            (Some(f), Some(t)) => t.len() < f.len() && f.starts_with(t),
            _ => false,
        }
    }

    /// Every set of files that import each other in a circle. A file's
    /// imports of the modules that enclose it (a folder's `mod.rs` and
    /// its ancestors) are not edges: a module folder's files share its
    /// private items by Rust's design, and the parent naming its children
    /// is how it exposes them. Cycles among siblings, cousins or unrelated
    /// files are reported.
    pub fn cycles(&self) -> Vec<Cycle> {
        let nodes: Vec<&str> = self.modules.keys().map(String::as_str).collect();
        let index = |f: &str| nodes.iter().position(|&n| n == f).unwrap();
        let mut adj = vec![BTreeSet::new(); nodes.len()];
        for i in &self.imports {
            if !self.is_enclosing(&i.from, &i.to) {
                adj[index(&i.from)].insert(index(&i.to));
            }
        }
        let mut out = Vec::new();
        for scc in strongly_connected(&adj) {
            if scc.len() < 2 {
                continue;
            }
            let files: Vec<String> = scc.iter().map(|&k| nodes[k].to_string()).collect();
            let inside: Vec<String> = self
                .imports
                .iter()
                .filter(|i| {
                    files.contains(&i.from)
                        && files.contains(&i.to)
                        && !self.is_enclosing(&i.from, &i.to)
                })
                .map(|i| format!("    {}:{} `{}` -> {}", i.from, i.line, i.written, i.to))
                .collect();
            out.push(Cycle {
                message: format!(
                    "import cycle among {}:\n{}",
                    files.join(", "),
                    inside.join("\n")
                ),
                files,
            });
        }
        out
    }
}

/// Tarjan's algorithm; components in no particular order, each sorted.
fn strongly_connected(adj: &[BTreeSet<usize>]) -> Vec<Vec<usize>> {
    struct State<'a> {
        adj: &'a [BTreeSet<usize>],
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
        for &w in s.adj[v].iter() {
            match s.index[w] {
                None => {
                    visit(s, w);
                    s.low[v] = s.low[v].min(s.low[w]);
                }
                Some(iw) if s.on_stack[w] => s.low[v] = s.low[v].min(iw),
                _ => {}
            }
        }
        if Some(s.low[v]) == s.index[v] {
            let mut c = Vec::new();
            loop {
                let w = s.stack.pop().unwrap();
                s.on_stack[w] = false;
                c.push(w);
                if w == v {
                    break;
                }
            }
            c.sort();
            s.out.push(c);
        }
    }
    let n = adj.len();
    let mut s = State {
        adj,
        index: vec![None; n],
        low: vec![0; n],
        on_stack: vec![false; n],
        stack: Vec::new(),
        next: 0,
        out: Vec::new(),
    };
    for v in 0..n {
        if s.index[v].is_none() {
            visit(&mut s, v);
        }
    }
    s.out
}

// ---------------------------------------------------------------------------
// The checker on made-up trees
// ---------------------------------------------------------------------------

#[cfg(test)]
mod tests {
    use super::*;

    const RANKS: &[(&str, u32)] = &[("core", 0), ("image", 1), ("accel", 1), ("scene", 3)];

    fn tree(files: &[(&str, &str)]) -> BTreeMap<String, String> {
        files
            .iter()
            .map(|(p, t)| (p.to_string(), t.to_string()))
            .collect()
    }

    fn messages(t: &BTreeMap<String, String>) -> Vec<String> {
        analyse(t)
            .layer_violations(RANKS)
            .into_iter()
            .map(|v| v.message)
            .collect()
    }

    #[test]
    fn an_import_of_a_higher_layer_fails_naming_file_line_and_layers() {
        let t = tree(&[
            ("src/lib.rs", "pub mod core;\npub mod scene;\n"),
            ("src/core/mod.rs", "pub mod math;\n"),
            (
                "src/core/math.rs",
                "//! Maths.\n\nuse crate::scene::Camera;\npub struct V;\n",
            ),
            ("src/scene/mod.rs", "pub struct Camera;\n"),
        ]);
        let v = analyse(&t).layer_violations(RANKS);
        assert_eq!(v.len(), 1, "{v:?}");
        assert_eq!(
            (v[0].from.as_str(), v[0].line, v[0].from_layer.as_str()),
            ("src/core/math.rs", 3, "core")
        );
        assert_eq!(
            (v[0].to_layer.as_str(), v[0].to.as_str()),
            ("scene", "src/scene/mod.rs")
        );
        assert_eq!(
            v[0].message,
            "src/core/math.rs:3: core (rank 0) -> scene (rank 3), a higher layer: \
             `crate::scene::Camera` names src/scene/mod.rs"
        );
    }

    #[test]
    fn same_rank_layers_may_not_import_each_other_but_lower_ones_and_their_own_are_fine() {
        let t = tree(&[
            ("src/lib.rs", ""),
            ("src/core/mod.rs", "pub struct C;"),
            (
                "src/image/film.rs",
                "use crate::core::C;\nuse super::output::W;\nfn f() { crate::accel::tlas::build(); }\n",
            ),
            ("src/image/mod.rs", ""),
            ("src/image/output.rs", "pub struct W;"),
            ("src/accel/mod.rs", ""),
            ("src/accel/tlas.rs", "pub fn build() {}"),
            (
                "src/scene/mod.rs",
                "use crate::{core::C, image::film, accel::tlas::build};",
            ),
        ]);
        assert_eq!(
            messages(&t),
            [
                "src/image/film.rs:3: image (rank 1) -> accel (rank 1), a layer of the same rank: \
              `crate::accel::tlas::build` names src/accel/tlas.rs"
            ]
        );
    }

    #[test]
    fn comments_doc_comments_and_strings_are_not_imports() {
        let t = tree(&[
            ("src/lib.rs", ""),
            ("src/scene/mod.rs", "pub struct S;"),
            (
                "src/core/mod.rs",
                r####"//! See [`crate::scene::S`].
/// Uses crate::scene::S, once.
// use crate::scene::S;
/* use crate::scene::S; /* nested */ crate::scene::S */
const A: &str = "crate::scene::S";
const B: &str = r#"use crate::scene::S; "quoted""#;
const C: char = '"';
const D: &[u8] = b"crate::scene::S";
fn f<'a>(x: &'a str) -> &'a str { x }
"####,
            ),
        ]);
        let a = analyse(&t);
        assert!(a.imports.is_empty(), "{:?}", a.imports);
        // The same path in code is found, on its own line.
        let mut t = t;
        t.get_mut("src/core/mod.rs")
            .unwrap()
            .push_str("fn g() { let _ = crate::scene::S; }\n");
        assert_eq!(
            messages(&t),
            [
                "src/core/mod.rs:10: core (rank 0) -> scene (rank 3), a higher layer: \
              `crate::scene::S` names src/scene/mod.rs"
            ]
        );
    }

    #[test]
    fn super_self_children_and_reexports_resolve_to_the_defining_file() {
        let t = tree(&[
            (
                "src/lib.rs",
                "pub use crate::core::error::{Error, Result};\n",
            ),
            ("src/core/mod.rs", "pub mod error;\n"),
            ("src/core/error.rs", "pub enum Error {}"),
            (
                "systems/mod.rs",
                "pub mod frame;\npub mod wavefront;\npub use frame::{Frame, Config as RenderConfig};\n",
            ),
            ("systems/frame.rs", "pub struct Frame; pub struct Config;"),
            (
                "systems/wavefront.rs",
                "use super::{Frame, RenderConfig};\nfn f() -> crate::Result<()> { self::g() }\n\
                 #[cfg(test)]\nmod tests {\n    use super::*;\n    use super::super::frame::Frame;\n}\n",
            ),
        ]);
        let a = analyse(&t);
        let got: Vec<(&str, usize, &str, &str, bool)> = a
            .imports
            .iter()
            .map(|i| {
                (
                    i.from.as_str(),
                    i.line,
                    i.written.as_str(),
                    i.to.as_str(),
                    i.in_test,
                )
            })
            .collect();
        assert_eq!(
            got,
            [
                (
                    "src/lib.rs",
                    1,
                    "crate::core::error::Error",
                    "src/core/error.rs",
                    false
                ),
                (
                    "systems/mod.rs",
                    3,
                    "frame::Config",
                    "systems/frame.rs",
                    false
                ),
                (
                    "systems/wavefront.rs",
                    1,
                    "super::Frame",
                    "systems/frame.rs",
                    false
                ),
                (
                    "systems/wavefront.rs",
                    2,
                    "crate::Result",
                    "src/core/error.rs",
                    false
                ),
                (
                    "systems/wavefront.rs",
                    6,
                    "super::super::frame::Frame",
                    "systems/frame.rs",
                    true
                ),
            ]
        );
        assert!(a.cycles().is_empty());
    }

    #[test]
    fn a_folder_and_its_own_files_may_name_each_other_but_siblings_may_not() {
        let t = tree(&[
            ("src/lib.rs", ""),
            ("src/geometry/mod.rs", "pub mod shapes;\n"),
            (
                "src/geometry/shapes/mod.rs",
                "mod planar;\nmod roots;\nuse planar::disk;\npub struct Hit;\n",
            ),
            (
                "src/geometry/shapes/planar.rs",
                "use super::Hit;\nuse super::roots::solve;\npub fn disk() {}\n",
            ),
            ("src/geometry/shapes/roots.rs", "pub fn solve() {}\n"),
        ]);
        assert!(analyse(&t).cycles().is_empty());
        // roots naming planar back closes a cycle between siblings.
        let mut t = t;
        t.insert(
            "src/geometry/shapes/roots.rs".into(),
            "pub fn solve() { super::planar::disk() }\n".into(),
        );
        let c = analyse(&t).cycles();
        assert_eq!(c.len(), 1, "{c:?}");
        assert_eq!(
            c[0].files,
            [
                "src/geometry/shapes/planar.rs",
                "src/geometry/shapes/roots.rs"
            ]
        );
    }

    #[test]
    fn a_cycle_fails_naming_its_files() {
        let t = tree(&[
            ("src/lib.rs", ""),
            (
                "src/accel/mod.rs",
                "pub mod packet;\npub mod stream;\npub mod tlas;\n",
            ),
            (
                "src/accel/packet.rs",
                "use super::stream::S;\npub struct P;",
            ),
            ("src/accel/stream.rs", "use super::tlas::T;\npub struct S;"),
            (
                "src/accel/tlas.rs",
                "pub struct T(crate::accel::packet::P);",
            ),
        ]);
        let a = analyse(&t);
        assert!(a.layer_violations(RANKS).is_empty());
        let c = a.cycles();
        assert_eq!(c.len(), 1, "{c:?}");
        assert_eq!(
            c[0].files,
            [
                "src/accel/packet.rs",
                "src/accel/stream.rs",
                "src/accel/tlas.rs"
            ]
        );
        assert!(
            c[0].message
                .contains("src/accel/tlas.rs:1 `crate::accel::packet::P`"),
            "{}",
            c[0].message
        );
        // Broken, it is gone.
        let mut t = t;
        t.insert("src/accel/tlas.rs".into(), "pub struct T;".into());
        assert!(analyse(&t).cycles().is_empty());
    }

    #[test]
    fn a_file_in_an_unranked_layer_is_reported() {
        let t = tree(&[("src/lib.rs", ""), ("src/gpu/mod.rs", "")]);
        assert_eq!(
            messages(&t),
            ["src/gpu/mod.rs: layer `gpu` has no rank (add it to the layer table)"]
        );
    }
}
