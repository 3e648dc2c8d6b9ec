//! Messages are in words: no format string in the host crates' library and command code (their
//! `#[cfg(test)]` modules, test files and examples aside) formats a value with Rust's debug
//! formatting (`{:?}`, `{x:?}`, `{:#?}`, `{:02x?}`), which shows users type names, `Some(..)`,
//! quoted strings and brackets instead of what the value means.
//!
//! The files listed in [`PENDING`] are known to hold such messages still (their owners are
//! changing them); the test fails if one of them no longer does, so the list stays honest.

use std::path::{Path, PathBuf};

/// Files that still format with debug formatting, with the reason they are not fixed here.
const PENDING: &[(&str, &str)] = &[];

/// Lines where debug formatting is not shown to anyone: a cache fingerprint's key.
const NOT_SHOWN: &[&str] = &[".value(\"model\", &format!(\"{:?}\", ctx.cfg.fit.model))"];

/// Every `.rs` file under `dir`.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The debug-formatting placeholders on a line: `{` + optional name + `:` + spec ending in `?`
/// + `}` (the spec holds no space, quote or brace).
fn debug_placeholders(line: &str) -> Vec<String> {
    let mut found = Vec::new();
    let bytes = line.as_bytes();
    for (end, _) in line.match_indices("?}") {
        let Some(open) = line[..end].rfind('{') else {
            continue;
        };
        let inner = &line[open + 1..end];
        let escaped = open > 0 && bytes[open - 1] == b'{';
        let plain = inner
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "_.:#<>^+-".contains(c));
        if !escaped && plain && inner.contains(':') {
            found.push(line[open..end + 2].to_string());
        }
    }
    found
}

/// The library part of a source file: up to its test module.
fn library_part(text: &str) -> &str {
    let mut offset = 0;
    let mut lines = text.split_inclusive('\n').peekable();
    while let Some(line) = lines.next() {
        if line.trim() == "#[cfg(test)]"
            && lines
                .peek()
                .is_some_and(|next| next.split_whitespace().any(|w| w == "mod"))
        {
            return &text[..offset];
        }
        offset += line.len();
    }
    text
}

#[test]
fn no_message_of_the_host_crates_is_debug_formatted() {
    let host = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("host directory")
        .to_path_buf();
    let mut files = Vec::new();
    for krate in std::fs::read_dir(&host).expect("host").flatten() {
        rust_files(&krate.path().join("src"), &mut files);
    }
    assert!(files.len() > 50, "found {} source files", files.len());
    let mut offences = Vec::new();
    let mut pending_clean = Vec::new();
    for f in &files {
        let rel = f
            .strip_prefix(&host)
            .unwrap_or(f)
            .to_string_lossy()
            .replace('\\', "/");
        // Test-only files (a test module kept in its own file).
        let name = f.file_name().map(|n| n.to_string_lossy().into_owned());
        if name.is_some_and(|n| n.contains("tests")) {
            continue;
        }
        let text = std::fs::read_to_string(f).expect("read");
        let mut here = Vec::new();
        for (i, line) in library_part(&text).lines().enumerate() {
            let code = line.trim_start();
            if code.starts_with("//")
                || code.contains("debug!(")
                || code.contains("trace!(")
                || NOT_SHOWN.iter().any(|s| code.contains(s))
            {
                continue;
            }
            for p in debug_placeholders(line) {
                here.push(format!("{rel}:{}: `{p}` in {}", i + 1, code));
            }
        }
        match PENDING.iter().find(|(p, _)| *p == rel) {
            Some(_) if here.is_empty() => pending_clean.push(rel.clone()),
            Some(_) => {}
            None => offences.extend(here),
        }
    }
    assert!(
        offences.is_empty(),
        "debug formatting in messages (write the value in words):\n{}",
        offences.join("\n")
    );
    assert!(
        pending_clean.is_empty(),
        "no longer debug-formatted: remove from PENDING: {pending_clean:?}"
    );
}

#[test]
fn the_scan_finds_debug_placeholders_and_nothing_else() {
    assert_eq!(
        debug_placeholders(r#"format!("{a:?} and {:#?} and {b:02x?}", x)"#),
        ["{a:?}", "{:#?}", "{b:02x?}"]
    );
    assert!(debug_placeholders(r#"format!("{a} {{b:?}} {:.3}", 1)"#).is_empty());
    assert!(debug_placeholders(r#"let q = x.map(|v| v?);"#).is_empty());
    let text = "fn a() {}\n#[cfg(test)]\nmod tests {\n    x!(\"{:?}\")\n}\n";
    assert_eq!(library_part(text), "fn a() {}\n");
    let text = "fn a() {}\n#[cfg(test)]\npub(crate) mod tests {\n}\n";
    assert_eq!(library_part(text), "fn a() {}\n");
}
