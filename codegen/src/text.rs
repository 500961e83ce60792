//! Text primitives of the generators: identifier sanitising, float literals, and escaping of
//! free text into comments and string literals of C and Rust.
use crate::error::{Error, Result};

/// What a user-given prefix becomes as a C identifier prefix (upper case).
///
/// Rules, in order:
/// 1. every ASCII letter is upper-cased, every ASCII digit kept, every other character
///    (including non-ASCII) becomes `_`;
/// 2. runs of `_` collapse to one, leading and trailing `_` are dropped;
/// 3. an empty result is an error, and so is one whose file names (`<prefix>.h`, `.rs` in
///    lower case) would shadow a C standard header, a Rust keyword/crate file or a `std`
///    module ([`reserved_file_stem`]);
/// 4. `P_` is prepended when the result starts with a digit (not an identifier) or with a
///    pattern the C standard library reserves for its macros (`E` + digit/upper-case letter:
///    errno; `SIG` + upper-case letter or `_`; `LC_`; `PRI`/`SCN` + `X`; `INT`/`UINT` + digit),
///    so that no generated name `PREFIX_...` can collide with `<errno.h>`, `<signal.h>`,
///    `<locale.h>` or `<inttypes.h>`.
///
/// Every generated C name is `PREFIX_` + an upper-case suffix, so no name can be a keyword or
/// start with `_` or `__`.
///
/// # Errors
/// [`Error::Input`] for `prefix` when nothing alphanumeric is left.
pub fn sanitize_prefix(raw: &str) -> Result<String> {
    let mut out = String::with_capacity(raw.len());
    for ch in raw.chars() {
        let c = if ch.is_ascii_alphanumeric() {
            ch.to_ascii_uppercase()
        } else {
            '_'
        };
        if c == '_' && (out.is_empty() || out.ends_with('_')) {
            continue;
        }
        out.push(c);
    }
    while out.ends_with('_') {
        out.pop();
    }
    if out.is_empty() {
        return Err(Error::input(
            "prefix",
            format!("{raw:?} has no letter or digit to build identifiers from"),
        ));
    }
    if starts_reserved(&out) {
        out.insert_str(0, "P_");
    }
    let stem = out.to_ascii_lowercase();
    if let Some(what) = reserved_file_stem(&stem) {
        return Err(Error::input(
            "prefix",
            format!(
                "{raw:?} would name the files {stem}.h and {stem}.rs, and `{stem}` is {what}: \
                 the file would shadow it in the user's build; choose another prefix (e.g. \
                 `{stem}_ctl`)"
            ),
        ));
    }
    Ok(out)
}

/// The C standard library headers (C89 to C23) and the POSIX headers an embedded build commonly
/// includes, by file stem: a generated `<stem>.h` next to the user's sources would shadow it.
#[rustfmt::skip]
pub const RESERVED_C_HEADERS: &[&str] = &[
    "assert", "complex", "ctype", "errno", "fenv", "float", "inttypes", "iso646", "limits",
    "locale", "math", "setjmp", "signal", "stdalign", "stdarg", "stdatomic", "stdbit",
    "stdbool", "stdckdint", "stddef", "stdint", "stdio", "stdlib", "stdnoreturn", "string",
    "tgmath", "threads", "time", "uchar", "wchar", "wctype", "unistd", "fcntl", "strings",
    "pthread", "sched", "semaphore",
];

/// Rust keywords (strict, reserved and weak), the crate roots and the file names with a
/// meaning to cargo/rustc: a generated `<stem>.rs` with such a stem cannot be a module, or
/// changes what the crate's `mod.rs`/`lib.rs`/`main.rs` is.
#[rustfmt::skip]
pub const RESERVED_RUST_STEMS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum",
    "extern", "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod",
    "move", "mut", "pub", "ref", "return", "self", "static", "struct", "super", "trait",
    "true", "try", "type", "union", "unsafe", "use", "where", "while", "abstract", "become",
    "box", "do", "final", "macro", "override", "priv", "typeof", "unsized", "virtual",
    "yield", "std", "core", "alloc", "lib", "main", "build",
];

/// Module names of Rust's standard library (`std::<name>`, and the primitive-type modules): a
/// generated module of that name shadows or confuses `use` paths.
#[rustfmt::skip]
pub const RESERVED_RUST_STD_MODULES: &[&str] = &[
    "any", "arch", "array", "ascii", "backtrace", "borrow", "boxed", "cell", "char", "clone",
    "cmp", "collections", "convert", "default", "env", "error", "f32", "f64", "ffi", "fmt",
    "fs", "future", "hash", "hint", "i8", "i16", "i32", "i64", "i128", "io", "isize", "iter",
    "marker", "mem", "net", "num", "ops", "option", "os", "panic", "path", "pin", "prelude",
    "primitive", "process", "ptr", "rc", "result", "slice", "str", "sync", "task", "thread",
    "u8", "u16", "u32", "u64", "u128", "usize", "vec",
];

/// What `stem` (a lower-case file stem) collides with, if anything.
pub fn reserved_file_stem(stem: &str) -> Option<&'static str> {
    if RESERVED_C_HEADERS.contains(&stem) {
        Some("a C standard or POSIX header")
    } else if RESERVED_RUST_STEMS.contains(&stem) {
        Some("a Rust keyword or a file name with a meaning to cargo/rustc")
    } else if RESERVED_RUST_STD_MODULES.contains(&stem) {
        Some("a module of Rust's standard library")
    } else {
        None
    }
}

fn starts_reserved(s: &str) -> bool {
    let b = s.as_bytes();
    let at = |i: usize| b.get(i).copied().unwrap_or(0);
    let upper_or_digit = |c: u8| c.is_ascii_uppercase() || c.is_ascii_digit();
    at(0).is_ascii_digit()
        || (at(0) == b'E' && upper_or_digit(at(1)))
        || (s.starts_with("SIG") && (at(3).is_ascii_uppercase() || at(3) == b'_'))
        || s.starts_with("LC_")
        || s.starts_with("PRIX")
        || s.starts_with("SCNX")
        || (s.starts_with("INT") && at(3).is_ascii_digit())
        || (s.starts_with("UINT") && at(4).is_ascii_digit())
}

/// `v` rounded to `f32`, printed as the shortest decimal that reads back to the same `f32`
/// (Rust's `{:?}`), always with a `.` or an exponent: `1.0`, `0.1`, `-2.5e-7`, `1e20`.
/// Valid as a Rust float literal as is and as a C `float` constant with an `f` suffix.
/// The caller has checked that `v` is finite and within the `f32` range.
pub fn f32_literal(v: f64) -> String {
    let f = v as f32;
    if !f.is_finite() {
        // Unreachable after the input checks; a literal that still compiles, never a panic.
        return if f.is_nan() {
            "0.0".into()
        } else if f > 0.0 {
            "3.4028235e38".into()
        } else {
            "-3.4028235e38".into()
        };
    }
    format!("{f:?}")
}

/// The C `float` constant of `v`: [`f32_literal`] + `f`.
pub fn c_float(v: f64) -> String {
    let mut s = f32_literal(v);
    s.push('f');
    s
}

/// `v` as shortest round-trip `f64` text (documentation comments).
pub fn f64_text(v: f64) -> String {
    format!("{v:?}")
}

/// ASCII spelling of the non-ASCII symbols that occur in units and receipts.
fn ascii_symbol(c: char) -> Option<&'static str> {
    Some(match c {
        '·' | '⋅' => ".",
        '°' => "deg",
        'µ' | 'μ' => "u",
        'Ω' => "Ohm",
        '²' => "^2",
        '³' => "^3",
        '±' => "+/-",
        '≤' => "<=",
        '≥' => ">=",
        '−' | '–' | '—' => "-",
        '∞' => "inf",
        '‖' => "||",
        _ => return None,
    })
}

/// Free text made safe inside a C block comment or a Rust/C line comment on one line:
/// printable ASCII only (common unit symbols spelled out, e.g. `N·m` → `N.m`, `°` → `deg`;
/// anything else becomes `?`), no `*/` or `/*`, no trigraph `??x`, no trailing backslash
/// (line splice).
pub fn comment_text(s: &str) -> String {
    let mut t = String::with_capacity(s.len());
    for c in s.chars() {
        if (' '..='~').contains(&c) {
            t.push(c);
        } else if let Some(a) = ascii_symbol(c) {
            t.push_str(a);
        } else {
            t.push('?');
        }
    }
    loop {
        let before = t.len();
        t = t
            .replace("*/", "* /")
            .replace("/*", "/ *")
            .replace("??", "? ?");
        if t.len() == before {
            break;
        }
    }
    while t.ends_with('\\') || t.ends_with(' ') {
        t.pop();
    }
    t
}

/// A C string literal (with quotes) holding `s`: printable ASCII except `"`, `\` and `?` as is
/// (`?` escaped against trigraphs), everything else as three-digit octal escapes of its UTF-8
/// bytes.
pub fn c_string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for &b in s.as_bytes() {
        match b {
            b'"' => out.push_str("\\\""),
            b'\\' => out.push_str("\\\\"),
            b'?' => out.push_str("\\?"),
            0x20..=0x7e => out.push(b as char),
            _ => out.push_str(&format!("\\{b:03o}")),
        }
    }
    out.push('"');
    out
}

/// A Rust string literal (with quotes) holding `s` (`str::escape_debug`).
pub fn rust_string(s: &str) -> String {
    format!("{s:?}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefix_rules() {
        assert_eq!(sanitize_prefix("motor").unwrap(), "MOTOR");
        assert_eq!(sanitize_prefix("  axis-2.pitch  ").unwrap(), "AXIS_2_PITCH");
        assert_eq!(sanitize_prefix("__a__b__").unwrap(), "A_B");
        assert_eq!(sanitize_prefix("3axis").unwrap(), "P_3AXIS");
        assert_eq!(sanitize_prefix("Émotor").unwrap(), "MOTOR");
        assert_eq!(sanitize_prefix("edge").unwrap(), "P_EDGE");
        assert_eq!(sanitize_prefix("e_stop").unwrap(), "E_STOP");
        assert_eq!(sanitize_prefix("signal").unwrap(), "P_SIGNAL");
        assert_eq!(sanitize_prefix("int8").unwrap(), "P_INT8");
        assert_eq!(sanitize_prefix("interp").unwrap(), "INTERP");
        assert!(matches!(
            sanitize_prefix("-- ."),
            Err(Error::Input { ref field, .. }) if field == "prefix"
        ));
        assert!(sanitize_prefix("").is_err());
    }

    #[test]
    fn float_literals_round_trip_and_parse() {
        for v in [
            0.0,
            -0.0,
            1.0,
            0.1,
            -2.5e-7,
            1e20,
            3.4e38,
            1.17549435e-38,
            123456.789,
            std::f64::consts::PI,
        ] {
            let s = f32_literal(v);
            assert!(s.contains('.') || s.contains('e'), "{s}");
            let back: f32 = s.parse().unwrap();
            assert_eq!(back.to_bits(), (v as f32).to_bits(), "{v} -> {s}");
            assert!(c_float(v).ends_with('f'));
        }
        assert_eq!(f32_literal(1.0), "1.0");
        assert_eq!(c_float(0.1), "0.1f");
    }

    #[test]
    fn comment_and_string_escaping() {
        assert_eq!(comment_text("a */ b /* c ??/ d\\"), "a * / b / * c ? ?/ d");
        assert_eq!(comment_text("x\ny°"), "x?ydeg");
        assert_eq!(
            comment_text("0.3 N·m, 5 µs, ‖W_m T‖∞ ≤ 1"),
            "0.3 N.m, 5 us, ||W_m T||inf <= 1"
        );
        assert_eq!(comment_text("é"), "?");
        assert_eq!(comment_text("???"), "? ??".replace("??", "? ?"));
        assert!(!comment_text("????").contains("??"));
        assert_eq!(c_string("a\"b\\c?d"), r#""a\"b\\c\?d""#);
        assert_eq!(c_string("é"), r#""\303\251""#);
        assert_eq!(rust_string("a\"b\n"), r#""a\"b\n""#);
    }
}
