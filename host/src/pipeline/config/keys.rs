//! Locating keys in the pipeline file's text, so errors name the line.

/// The dotted key written on 1-based `line` of a TOML text (table header + key), if any.
pub(super) fn key_at_line(text: &str, line: usize) -> Option<String> {
    let mut table = String::new();
    let mut counts: std::collections::BTreeMap<String, usize> = Default::default();
    for (i, l) in text.lines().enumerate() {
        let t = strip_comment(l).trim();
        if let Some(h) = header(t) {
            table = h.0.clone();
            if h.1 {
                let c = counts.entry(h.0.clone()).or_insert(0);
                table = format!("{}[{}]", h.0, *c);
                *c += 1;
            }
            if i + 1 == line {
                return Some(table);
            }
            continue;
        }
        if i + 1 == line {
            let key = t.split('=').next()?.trim().trim_matches('"');
            if key.is_empty() {
                return None;
            }
            return Some(if table.is_empty() {
                key.to_string()
            } else {
                format!("{table}.{key}")
            });
        }
    }
    None
}

/// 1-based line of a dotted key (`control.crossover_hz`, `runs[1].file`, or a table
/// `runs[1]`), if written in the text.
pub(super) fn find_key_line(text: &str, key: &str) -> Option<usize> {
    let mut table = String::new();
    let mut counts: std::collections::BTreeMap<String, usize> = Default::default();
    let mut table_line = None;
    for (i, l) in text.lines().enumerate() {
        let t = strip_comment(l).trim();
        if let Some(h) = header(t) {
            table = h.0.clone();
            if h.1 {
                let c = counts.entry(h.0.clone()).or_insert(0);
                table = format!("{}[{}]", h.0, *c);
                *c += 1;
            }
            if table == key {
                return Some(i + 1);
            }
            if key.starts_with(&format!("{table}.")) {
                table_line = Some(i + 1);
            }
            continue;
        }
        if let Some(k) = t.split('=').next() {
            if !t.contains('=') {
                continue;
            }
            let k = k.trim().trim_matches('"');
            let full = if table.is_empty() {
                k.to_string()
            } else {
                format!("{table}.{k}")
            };
            if full == key {
                return Some(i + 1);
            }
        }
    }
    table_line
}

/// (`name`, is_array_of_tables) of a `[name]` / `[[name]]` header line.
fn header(t: &str) -> Option<(String, bool)> {
    if let Some(inner) = t.strip_prefix("[[").and_then(|s| s.strip_suffix("]]")) {
        return Some((inner.trim().to_string(), true));
    }
    if let Some(inner) = t.strip_prefix('[').and_then(|s| s.strip_suffix(']')) {
        return Some((inner.trim().to_string(), false));
    }
    None
}

fn strip_comment(l: &str) -> &str {
    // Good enough for locating keys: a '#' outside a quoted string starts a comment.
    let mut in_str = false;
    for (i, ch) in l.char_indices() {
        match ch {
            '"' => in_str = !in_str,
            '#' if !in_str => return &l[..i],
            _ => {}
        }
    }
    l
}
