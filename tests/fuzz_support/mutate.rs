//! Structured mutations of valid inputs: byte edits (flip, set, cut, insert, delete,
//! duplicate), and edits of one node of a JSON or TOML tree (a value replaced by an
//! interesting one or by raw text, removed, repeated, nested deeply, an unknown key added).

use proptest::prelude::*;

/// One edit of a byte string; positions are taken modulo the length.
#[derive(Debug, Clone)]
pub enum ByteEdit {
    Flip { at: usize, bit: u8 },
    Set { at: usize, value: u8 },
    Truncate { at: usize },
    Insert { at: usize, bytes: Vec<u8> },
    Delete { at: usize, len: usize },
    Duplicate { at: usize, len: usize, to: usize },
}

pub fn byte_edit() -> impl Strategy<Value = ByteEdit> {
    prop_oneof![
        (any::<usize>(), 0u8..8).prop_map(|(at, bit)| ByteEdit::Flip { at, bit }),
        (any::<usize>(), prop::sample::select(vec![0u8, 0xff, 0x7f, 0x80, b'0', b'9', b'-', b'.', b'e', b'"', b'[', b']', b'{', b'}', b'=', b'\n', b',', b'\\']))
            .prop_map(|(at, value)| ByteEdit::Set { at, value }),
        any::<usize>().prop_map(|at| ByteEdit::Truncate { at }),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..16)).prop_map(|(at, bytes)| ByteEdit::Insert { at, bytes }),
        (any::<usize>(), 1usize..64).prop_map(|(at, len)| ByteEdit::Delete { at, len }),
        (any::<usize>(), 1usize..64, any::<usize>()).prop_map(|(at, len, to)| ByteEdit::Duplicate { at, len, to }),
    ]
}

/// Up to `max` edits.
pub fn byte_edits(max: usize) -> impl Strategy<Value = Vec<ByteEdit>> {
    prop::collection::vec(byte_edit(), 0..=max)
}

pub fn apply_bytes(bytes: &mut Vec<u8>, edits: &[ByteEdit]) {
    for e in edits {
        let n = bytes.len();
        let pos = |at: usize| if n == 0 { 0 } else { at % n };
        match e {
            ByteEdit::Flip { at, bit } if n > 0 => bytes[pos(*at)] ^= 1 << bit,
            ByteEdit::Set { at, value } if n > 0 => bytes[pos(*at)] = *value,
            ByteEdit::Truncate { at } => bytes.truncate(pos(*at)),
            ByteEdit::Insert { at, bytes: b } => {
                let p = pos(*at);
                bytes.splice(p..p, b.iter().copied());
            }
            ByteEdit::Delete { at, len } if n > 0 => {
                let p = pos(*at);
                bytes.drain(p..(p + len).min(n));
            }
            ByteEdit::Duplicate { at, len, to } if n > 0 => {
                let p = pos(*at);
                let chunk: Vec<u8> = bytes[p..(p + len).min(n)].to_vec();
                let t = pos(*to);
                bytes.splice(t..t, chunk);
            }
            _ => {}
        }
    }
}

/// `text` with byte edits, as the decoder's `&str` (invalid UTF-8 replaced).
pub fn edit_text(text: &str, edits: &[ByteEdit]) -> String {
    let mut b = text.as_bytes().to_vec();
    apply_bytes(&mut b, edits);
    String::from_utf8_lossy(&b).into_owned()
}

/// What one node of a tree becomes.
#[derive(Debug, Clone)]
pub enum NodeEdit {
    /// Raw text in the file's syntax (a number no type holds, NaN, a broken token, ...).
    Raw(&'static str),
    Float(f64),
    Int(i64),
    Text(String),
    Bool(bool),
    EmptyList,
    EmptyTable,
    Remove,
    /// A list of this many elements: the node's own (cycled) or copies of the node.
    Repeat(usize),
    /// The node wrapped in this many lists.
    Nest(usize),
    /// An unknown key added to the nearest table.
    AddKey(String),
}

const PLACEHOLDER: &str = "HANDEYE_FUZZ_PLACEHOLDER";

pub fn node_edit(raw: &'static [&'static str]) -> impl Strategy<Value = NodeEdit> {
    prop_oneof![
        prop::sample::select(raw.to_vec()).prop_map(NodeEdit::Raw),
        prop::sample::select(vec![0.0, -0.0, -1.0, 1e-300, 1e300, -1e300, f64::MAX, f64::MIN_POSITIVE, 0.5, 1e9, -1e9, 3.0, 7.0, 9.0])
            .prop_map(NodeEdit::Float),
        any::<f64>().prop_map(NodeEdit::Float),
        prop::sample::select(vec![0i64, 1, -1, 2, 3, 8, 9, 255, 65_536, i32::MAX as i64, i64::MAX, i64::MIN, u32::MAX as i64 + 1]).prop_map(NodeEdit::Int),
        prop::collection::vec(any::<char>(), 0..40).prop_map(|c| NodeEdit::Text(c.into_iter().collect())),
        any::<bool>().prop_map(NodeEdit::Bool),
        Just(NodeEdit::EmptyList),
        Just(NodeEdit::EmptyTable),
        Just(NodeEdit::Remove),
        prop_oneof![0usize..12, 12usize..2000].prop_map(NodeEdit::Repeat),
        prop_oneof![1usize..8, 100usize..3000].prop_map(NodeEdit::Nest),
        "[a-z_]{1,12}".prop_map(NodeEdit::AddKey),
    ]
}

/// A JSON text: `base` with node `pick` (depth-first, modulo the count) edited.
pub fn edit_json(base: &serde_json::Value, pick: usize, edit: &NodeEdit) -> String {
    use serde_json::Value;
    let mut v = base.clone();
    let mut paths = Vec::new();
    json_paths(&v, &mut Vec::new(), &mut paths);
    let path = &paths[pick % paths.len()];
    let mut raw = None;
    if let NodeEdit::Remove = edit {
        if let Some((last, parent)) = path.split_last() {
            match json_at(&mut v, parent) {
                Value::Object(m) => {
                    m.remove(&last.0);
                }
                Value::Array(a) => {
                    a.remove(last.1);
                }
                _ => {}
            }
        }
        return v.to_string();
    }
    if let NodeEdit::AddKey(k) = edit {
        let mut p = path.as_slice();
        loop {
            if let Value::Object(m) = json_at(&mut v, p) {
                m.insert(k.clone(), Value::from(1));
                break;
            }
            match p.split_last() {
                Some((_, parent)) => p = parent,
                None => break,
            }
        }
        return v.to_string();
    }
    let node = json_at(&mut v, path);
    let new = match edit {
        NodeEdit::Raw(r) => {
            raw = Some(r.to_string());
            Value::from(PLACEHOLDER)
        }
        NodeEdit::Float(x) => serde_json::Number::from_f64(*x).map(Value::Number).unwrap_or(Value::Null),
        NodeEdit::Int(i) => Value::from(*i),
        NodeEdit::Text(s) => Value::from(s.clone()),
        NodeEdit::Bool(b) => Value::from(*b),
        NodeEdit::EmptyList => Value::Array(vec![]),
        NodeEdit::EmptyTable => Value::Object(Default::default()),
        NodeEdit::Repeat(n) => match &*node {
            Value::Array(a) if !a.is_empty() => Value::Array((0..*n).map(|i| a[i % a.len()].clone()).collect()),
            other => Value::Array(vec![other.clone(); *n]),
        },
        NodeEdit::Nest(n) => {
            raw = Some(format!("{}{}{}", "[".repeat(*n), node, "]".repeat(*n)));
            Value::from(PLACEHOLDER)
        }
        NodeEdit::Remove | NodeEdit::AddKey(_) => unreachable!("handled above"),
    };
    *node = new;
    let text = v.to_string();
    match raw {
        Some(r) => text.replacen(&format!("\"{PLACEHOLDER}\""), &r, 1),
        None => text,
    }
}

/// One step of a path: an object key or an array index (the other field unused).
type Seg = (String, usize);

fn json_paths(v: &serde_json::Value, here: &mut Vec<Seg>, out: &mut Vec<Vec<Seg>>) {
    out.push(here.clone());
    match v {
        serde_json::Value::Object(m) => {
            for (k, c) in m {
                here.push((k.clone(), 0));
                json_paths(c, here, out);
                here.pop();
            }
        }
        serde_json::Value::Array(a) => {
            for (i, c) in a.iter().enumerate() {
                here.push((String::new(), i));
                json_paths(c, here, out);
                here.pop();
            }
        }
        _ => {}
    }
}

fn json_at<'a>(v: &'a mut serde_json::Value, path: &[Seg]) -> &'a mut serde_json::Value {
    path.iter().fold(v, |v, (k, i)| match v {
        serde_json::Value::Object(_) => &mut v[k.as_str()],
        _ => &mut v[*i],
    })
}

/// A TOML text: `base` with node `pick` (depth-first, modulo the count) edited.
pub fn edit_toml(base: &toml::Table, pick: usize, edit: &NodeEdit) -> String {
    use toml::Value;
    let mut root = Value::Table(base.clone());
    let mut paths = Vec::new();
    toml_paths(&root, &mut Vec::new(), &mut paths);
    let path = paths[pick % paths.len()].clone();
    let mut raw = None;
    match edit {
        NodeEdit::Remove => {
            if let Some((last, parent)) = path.split_last() {
                match toml_at(&mut root, parent) {
                    Value::Table(t) => {
                        t.remove(&last.0);
                    }
                    Value::Array(a) => {
                        a.remove(last.1);
                    }
                    _ => {}
                }
            }
        }
        NodeEdit::AddKey(k) => {
            let mut p = path.as_slice();
            loop {
                if let Value::Table(t) = toml_at(&mut root, p) {
                    t.insert(k.clone(), Value::Integer(1));
                    break;
                }
                match p.split_last() {
                    Some((_, parent)) => p = parent,
                    None => break,
                }
            }
        }
        _ if path.is_empty() => {}
        _ => {
            let node = toml_at(&mut root, &path);
            let new = match edit {
                NodeEdit::Raw(r) => {
                    raw = Some(r.to_string());
                    Value::String(PLACEHOLDER.into())
                }
                NodeEdit::Float(x) => Value::Float(*x),
                NodeEdit::Int(i) => Value::Integer(*i),
                NodeEdit::Text(s) => Value::String(s.clone()),
                NodeEdit::Bool(b) => Value::Boolean(*b),
                NodeEdit::EmptyList => Value::Array(vec![]),
                NodeEdit::EmptyTable => Value::Table(Default::default()),
                NodeEdit::Repeat(n) => match &*node {
                    Value::Array(a) if !a.is_empty() => Value::Array((0..*n).map(|i| a[i % a.len()].clone()).collect()),
                    other => Value::Array(vec![other.clone(); *n]),
                },
                NodeEdit::Nest(n) => (0..*n.min(&64)).fold(node.clone(), |v, _| Value::Array(vec![v])),
                NodeEdit::Remove | NodeEdit::AddKey(_) => unreachable!("handled above"),
            };
            *node = new;
        }
    }
    let Value::Table(t) = root else { unreachable!("the root is a table") };
    let text = toml::to_string(&t).unwrap_or_default();
    match raw {
        Some(r) => text.replacen(&format!("\"{PLACEHOLDER}\""), &r, 1),
        None => text,
    }
}

fn toml_paths(v: &toml::Value, here: &mut Vec<Seg>, out: &mut Vec<Vec<Seg>>) {
    out.push(here.clone());
    match v {
        toml::Value::Table(t) => {
            for (k, c) in t {
                here.push((k.clone(), 0));
                toml_paths(c, here, out);
                here.pop();
            }
        }
        toml::Value::Array(a) => {
            for (i, c) in a.iter().enumerate() {
                here.push((String::new(), i));
                toml_paths(c, here, out);
                here.pop();
            }
        }
        _ => {}
    }
}

fn toml_at<'a>(v: &'a mut toml::Value, path: &[Seg]) -> &'a mut toml::Value {
    path.iter().fold(v, |v, (k, i)| match v {
        toml::Value::Table(t) => t.get_mut(k.as_str()).expect("path from toml_paths"),
        toml::Value::Array(a) => &mut a[*i],
        _ => unreachable!("paths only go through tables and arrays"),
    })
}
