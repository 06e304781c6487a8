//! LoopLab's stage SDK: what a stage of your own links (a controller, an estimator, sensors or a
//! plant model in Rust, and the Python and C bindings), in layers that depend only downwards:
//! contract → config → model → runtime. The rest of LoopLab (`looplab-shared`: the scenarios,
//! the monitor, the launcher, the tools) builds on it. ARCHITECTURE.md has the picture.

// A line for the user on stderr that never panics (a closed terminal, a reader gone away): the
// exit status must still say why a process ended; its control characters escaped
// ([`printable`]). Defined before the modules, so every module has it.
#[macro_export]
macro_rules! tell {
    ($($text:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr().lock(), "{}", $crate::printable(&format!($($text)*)));
    }};
}

/// `text` with every control character but a newline or a tab written as its escape (`\u{1b}`):
/// what a user's file, argument or process puts in a message is shown, and never drives the
/// terminal.
pub fn printable(text: &str) -> std::borrow::Cow<'_, str> {
    let escaped = |c: char| c.is_control() && c != '\n' && c != '\t';
    if !text.chars().any(escaped) {
        return std::borrow::Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len() + 16);
    for c in text.chars() {
        if escaped(c) {
            out.extend(c.escape_unicode());
        } else {
            out.push(c);
        }
    }
    std::borrow::Cow::Owned(out)
}

pub mod config;
pub mod contract;
pub mod model;
pub mod runtime;

#[cfg(test)]
mod tests {
    #[test]
    fn control_characters_are_escaped_and_newlines_tabs_and_unicode_kept() {
        assert_eq!(super::printable("key `x\u{1b}[31my`\r\u{7}"), "key `x\\u{1b}[31my`\\u{d}\\u{7}");
        assert_eq!(super::printable("two\n\tlines · µs"), "two\n\tlines · µs");
        assert!(matches!(super::printable("plain"), std::borrow::Cow::Borrowed(_)));
    }
}
