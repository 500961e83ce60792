//! Where each key of the pipeline file is written, from the spans the toml crate reports
//! ([`toml::Spanned`]'s protocol), so errors name the line and the key.
//!
//! [`KeyTree::parse`] reads the file once more as an untyped tree of keys, each with the byte
//! range of its key and of its value as the toml parser located them; the typed
//! [`super::PipelineConfig`] stays free of span wrappers. A table the file only implies
//! (`[a.b]` without `[a]`) has no span of its own: its key's span stands for it.
use serde::de::{self, Deserialize, Deserializer, MapAccess, SeqAccess, Visitor};
use std::fmt;
use std::ops::Range;

/// The name and fields under which the toml deserializer hands out a value's span (the
/// protocol behind [`toml::Spanned`]).
const SPANNED: &str = "$__serde_spanned_private_Spanned";
const START: &str = "$__serde_spanned_private_start";
const END: &str = "$__serde_spanned_private_end";
const VALUE: &str = "$__serde_spanned_private_value";
const FIELDS: &[&str] = &[START, END, VALUE];

/// Every key and array item of a TOML text, by dotted path (`control.crossover_hz`,
/// `runs[1]`, `runs[1].file`), in file order.
#[derive(Debug, Clone, Default)]
pub(super) struct KeyTree {
    places: Vec<Place>,
}

#[derive(Debug, Clone)]
struct Place {
    path: String,
    /// The key as written (None for an array item).
    key: Option<Range<usize>>,
    /// The value (None for an implied table).
    value: Option<Range<usize>>,
}

impl Place {
    fn start(&self) -> Option<usize> {
        self.key.as_ref().or(self.value.as_ref()).map(|r| r.start)
    }
}

impl KeyTree {
    /// The keys of `text` (empty when it is not TOML: the typed parse reports that).
    pub(super) fn parse(text: &str) -> Self {
        let mut places = Vec::new();
        if let Ok(root) = toml::from_str::<Node>(text) {
            root.flatten("", &mut places);
        }
        Self { places }
    }

    /// 1-based line of a dotted key, or of the table that holds it when the key itself is
    /// not written (`control` for an omitted `control.mpc_rate_limit`).
    pub(super) fn line_of(&self, text: &str, key: &str) -> Option<usize> {
        let at = |path: &str| {
            self.places
                .iter()
                .find(|p| p.path == path)
                .and_then(Place::start)
        };
        let parent = key.rfind(['.', '[']).map(|i| &key[..i]);
        let start = at(key).or_else(|| parent.and_then(at))?;
        Some(line_at(text, start))
    }

    /// The dotted key whose key or value holds byte `offset` (the innermost one).
    pub(super) fn key_at(&self, offset: usize) -> Option<&str> {
        self.places
            .iter()
            .flat_map(|p| [&p.key, &p.value].map(|r| r.as_ref().map(|r| (p, r))))
            .flatten()
            .filter(|(_, r)| r.contains(&offset) || (r.is_empty() && r.start == offset))
            .min_by_key(|(_, r)| r.len())
            .map(|(p, _)| p.path.as_str())
    }

    /// The keys written directly in table `table`, in file order.
    pub(super) fn keys_in<'a>(&'a self, table: &'a str) -> impl Iterator<Item = &'a str> + 'a {
        self.places.iter().filter_map(move |p| {
            let rest = p.path.strip_prefix(table)?.strip_prefix('.')?;
            (!rest.contains(['.', '['])).then_some(rest)
        })
    }
}

/// 1-based line of byte `offset` in `text`.
pub(super) fn line_at(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

/// A value with its span when the parser has one.
#[derive(Debug, Default)]
struct Node {
    span: Option<Range<usize>>,
    kind: Kind,
}

#[derive(Debug, Default)]
enum Kind {
    #[default]
    Leaf,
    Table(Vec<(Key, Node)>),
    Array(Vec<Node>),
}

impl Node {
    fn flatten(self, path: &str, out: &mut Vec<Place>) {
        match self.kind {
            Kind::Leaf => {}
            Kind::Table(entries) => {
                for (k, v) in entries {
                    let p = if path.is_empty() {
                        k.name.clone()
                    } else {
                        format!("{path}.{}", k.name)
                    };
                    out.push(Place {
                        path: p.clone(),
                        key: k.span,
                        value: v.span.clone(),
                    });
                    v.flatten(&p, out);
                }
            }
            Kind::Array(items) => {
                for (i, v) in items.into_iter().enumerate() {
                    let p = format!("{path}[{i}]");
                    out.push(Place {
                        path: p.clone(),
                        key: None,
                        value: v.span.clone(),
                    });
                    v.flatten(&p, out);
                }
            }
        }
    }
}

/// A table key with its span when the parser has one.
#[derive(Debug)]
struct Key {
    name: String,
    span: Option<Range<usize>>,
}

impl<'de> Deserialize<'de> for Key {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_struct(SPANNED, FIELDS, KeyVisitor)
    }
}

struct KeyVisitor;

impl<'de> Visitor<'de> for KeyVisitor {
    type Value = Key;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a TOML key")
    }
    fn visit_str<E: de::Error>(self, v: &str) -> Result<Key, E> {
        Ok(Key {
            name: v.to_string(),
            span: None,
        })
    }
    fn visit_map<A: MapAccess<'de>>(self, mut m: A) -> Result<Key, A::Error> {
        let (span, name) = spanned::<A, String>(&mut m)?;
        Ok(Key {
            name,
            span: Some(span),
        })
    }
}

/// Reads the three fields of a spanned map (start, end, value).
fn spanned<'de, A: MapAccess<'de>, T: Deserialize<'de>>(
    m: &mut A,
) -> Result<(Range<usize>, T), A::Error> {
    let (mut start, mut end, mut value) = (None, None, None);
    while let Some(k) = m.next_key::<String>()? {
        match k.as_str() {
            START => start = Some(m.next_value::<usize>()?),
            END => end = Some(m.next_value::<usize>()?),
            VALUE => value = Some(m.next_value::<T>()?),
            _ => return Err(de::Error::unknown_field(&k, FIELDS)),
        }
    }
    match (start, end, value) {
        (Some(s), Some(e), Some(v)) => Ok((s..e, v)),
        _ => Err(de::Error::missing_field(VALUE)),
    }
}

impl<'de> Deserialize<'de> for Node {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_struct(SPANNED, FIELDS, NodeVisitor)
    }
}

/// Builds a [`Node`]: a spanned wrapper (its first key is [`START`]), a table, an array or a
/// leaf.
struct NodeVisitor;

macro_rules! leaf {
    ($($f:ident: $t:ty),*) => {$(
        fn $f<E: de::Error>(self, _: $t) -> Result<Node, E> {
            Ok(Node::default())
        }
    )*};
}

impl<'de> Visitor<'de> for NodeVisitor {
    type Value = Node;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a TOML value")
    }
    leaf!(visit_bool: bool, visit_i64: i64, visit_u64: u64, visit_f64: f64, visit_str: &str);
    fn visit_seq<A: SeqAccess<'de>>(self, mut s: A) -> Result<Node, A::Error> {
        let mut items = Vec::new();
        while let Some(v) = s.next_element::<Node>()? {
            items.push(v);
        }
        Ok(Node {
            span: None,
            kind: Kind::Array(items),
        })
    }
    fn visit_map<A: MapAccess<'de>>(self, mut m: A) -> Result<Node, A::Error> {
        let Some(first) = m.next_key::<Key>()? else {
            return Ok(Node::kind(Kind::Table(Vec::new())));
        };
        if first.name != START {
            let mut entries = vec![(first, m.next_value::<Node>()?)];
            while let Some(k) = m.next_key::<Key>()? {
                entries.push((k, m.next_value::<Node>()?));
            }
            return Ok(Node::kind(Kind::Table(entries)));
        }
        let start = m.next_value::<usize>()?;
        let (mut end, mut inner) = (start, Node::default());
        while let Some(k) = m.next_key::<String>()? {
            match k.as_str() {
                END => end = m.next_value::<usize>()?,
                VALUE => inner = m.next_value_seed(Unwrapped)?,
                _ => return Err(de::Error::unknown_field(&k, FIELDS)),
            }
        }
        inner.span = Some(start..end);
        Ok(inner)
    }
}

/// The value inside a spanned wrapper (asking for its span again would wrap it again).
struct Unwrapped;

impl<'de> de::DeserializeSeed<'de> for Unwrapped {
    type Value = Node;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Node, D::Error> {
        d.deserialize_any(NodeVisitor)
    }
}

impl Node {
    fn kind(kind: Kind) -> Self {
        Node { span: None, kind }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = "title = \"t\"\n\n[[runs]]\nname = \"a\"\nfile = \"a.csv\"\n\n[[runs]]\nfile = \"b.csv\" # two\n\n[control]\ncrossover_hz = 10\nlimits = { ms = 1.5, mt = [1, 2] }\n\n[x.y]\nz = 1\n";

    #[test]
    fn keys_items_and_implied_tables_have_lines() {
        let t = KeyTree::parse(TEXT);
        let line = |k: &str| t.line_of(TEXT, k);
        assert_eq!(line("title"), Some(1));
        assert_eq!(line("runs[0]"), Some(3));
        assert_eq!(line("runs[0].file"), Some(5));
        assert_eq!(line("runs[1]"), Some(7));
        assert_eq!(line("runs[1].file"), Some(8));
        // Not written: the table that would hold it.
        assert_eq!(line("runs[1].name"), Some(7));
        assert_eq!(line("control.actuator_limit"), Some(10));
        assert_eq!(line("control.limits.mt"), Some(12));
        assert_eq!(line("x.y.z"), Some(15));
        assert_eq!(line("x.y"), Some(14));
        assert_eq!(line("identification.run"), None);
        let keys: Vec<_> = t.keys_in("control").collect();
        assert_eq!(keys, ["crossover_hz", "limits"]);
    }

    #[test]
    fn offsets_map_to_the_innermost_key() {
        let t = KeyTree::parse(TEXT);
        let at = |s: &str| t.key_at(TEXT.find(s).unwrap());
        assert_eq!(at("10"), Some("control.crossover_hz"));
        assert_eq!(at("1.5"), Some("control.limits.ms"));
        assert_eq!(at("\"b.csv\""), Some("runs[1].file"));
        assert_eq!(at("crossover_hz"), Some("control.crossover_hz"));
    }

    #[test]
    fn not_toml_gives_an_empty_tree() {
        let t = KeyTree::parse("a = = 1");
        assert_eq!(t.line_of("a = = 1", "a"), None);
    }
}
